"""A precomputed lattice of signed distances: a cheap interval for the coarse search levels.

The signed distance is 1-Lipschitz, so at a point ``x`` it lies within ``|x - v|`` of its
value at any lattice vertex ``v``; the lookup takes the nearest vertex (clamped to the
lattice box) and adds the lattice values' own float32 error. Outside the lattice box the
point also lies outside the solid, at least as far from the surface as from the mesh's
bounding box.
"""

import weakref

import numpy as np

from fixwizard.fixture import DistanceOracle
from fixwizard.solver.interval_kernel import lattice_intervals_m

MAX_VERTICES = 400_000
MIN_SPACING_M = 0.0015
MARGIN_M = 0.01


class DistanceGrid:
    """Signed distances (m) on a lattice around a mesh, in the mesh's frame."""

    def __init__(self, oracle: DistanceOracle) -> None:
        self._mesh_low, self._mesh_high = oracle.bounds_m
        low, high = self._mesh_low - MARGIN_M, self._mesh_high + MARGIN_M
        extent = high - low
        spacing = max(MIN_SPACING_M, float(np.cbrt(np.prod(extent) / MAX_VERTICES)))
        self._shape = np.ceil(extent / spacing).astype(np.int64) + 1
        self._low, self._spacing = low, spacing
        axes = [low[axis] + spacing * np.arange(self._shape[axis]) for axis in range(3)]
        vertices = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        self._values = oracle.signed_distance_m(vertices)
        self._value_error_m = float(np.max(oracle.error_bound_m(vertices)))

    @property
    def kernel_arguments(self) -> tuple:
        """The lattice as ``interval_kernel`` takes it: low corner (m), spacing (m), shape, flat values (m), their
        error (m), and the mesh's bounding box (m)."""
        return (self._low, self._spacing, self._shape, self._values, self._value_error_m, self._mesh_low,
                self._mesh_high)

    def interval_m(self, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interval (m) holding the signed distance at each (N, 3) point."""
        return lattice_intervals_m(np.ascontiguousarray(points_m, np.float64), *self.kernel_arguments)


_GRIDS: "weakref.WeakKeyDictionary[DistanceOracle, DistanceGrid]" = weakref.WeakKeyDictionary()


def distance_grid_for(oracle: DistanceOracle) -> DistanceGrid:
    """The lattice of an oracle, built on first use and kept while the oracle lives."""
    if oracle not in _GRIDS:
        _GRIDS[oracle] = DistanceGrid(oracle)
    return _GRIDS[oracle]
