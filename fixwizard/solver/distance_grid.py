"""A precomputed lattice of signed distances: a cheap interval for the coarse search levels.

The signed distance is 1-Lipschitz, so at a point ``x`` it lies within ``|x - v|`` of its
value at any lattice vertex ``v``, give or take the lattice values' own float32 error. The
search first takes the nearest vertex, then, where that does not decide, the tightest bounds of
the eight corners of the voxel holding the point (the nearest voxel outside the lattice box).
Outside the mesh's bounding box the point also lies outside the solid, at least as far from the
surface as from the box.

Building a lattice takes a second of Open3D queries, so lattices are kept on disk between runs
(``cache_folder()``), named by a hash of everything they depend on: the mesh's vertices and
triangles, the lattice's geometry, and the file format. A file that does
not match its name or cannot be read is rebuilt.
"""

import hashlib
import io
import os
import weakref
import zipfile
from pathlib import Path

import numpy as np

from fixwizard.atomic import write_bytes_atomic
from fixwizard.fixture import DistanceOracle
from fixwizard.solver.interval_kernel import Arrays, lattice_intervals_m

MAX_VERTICES = 400_000
MIN_SPACING_M = 0.0015
MARGIN_M = 0.01
# The oracle's intervals are at most ~1e-8 m wide for metre-sized triangles of any shape (mesh_distance); a
# cached error bound above this one did not come from it.
MAX_VALUE_ERROR_M = 1e-6
CACHE_FORMAT = 3  # raise whenever what a lattice holds or how the oracle computes it changes


def cache_folder() -> Path:
    """Where lattices are kept: ``$FIXWIZARD_CACHE``, else ``$XDG_CACHE_HOME/fixwizard``, else
    ``~/.cache/fixwizard``."""
    if os.environ.get("FIXWIZARD_CACHE"):
        return Path(os.environ["FIXWIZARD_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "fixwizard"


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
        key = self._key(oracle)
        path = cache_folder() / f"lattice-{key}.npz"
        if not self._load(path, key, len(vertices), oracle.triangle_count):
            low, high, self._faces = oracle.distance_interval_m(vertices)
            self._values = 0.5 * (low + high)
            self._value_error_m = float(np.max(high - low))  # half the width, doubled for the midpoint's rounding
            self._store(path, key)

    def _key(self, oracle: DistanceOracle) -> str:
        mesh_vertices, triangles = oracle.mesh_arrays
        digest = hashlib.sha256()
        for part in (mesh_vertices, triangles, self._low, np.array([self._spacing]), self._shape):
            digest.update(np.ascontiguousarray(part).tobytes())
        digest.update(repr((oracle.signed, CACHE_FORMAT)).encode())
        return digest.hexdigest()

    def _load(self, path: Path, key: str, count: int, triangle_count: int) -> bool:
        """Take values, their error and faces from a cached lattice; False when there is none fit to use (the
        compiled search reads faces without bounds checks, so an index out of range must never get through, and
        an error bound must be one the oracle can give)."""
        try:
            with np.load(path) as stored:
                values, faces, stored_key = stored["values"], stored["faces"], str(stored["key"])
                value_error_m = float(stored["value_error_m"])
        except (OSError, EOFError, KeyError, ValueError, TypeError, zipfile.BadZipFile):
            return False
        if (stored_key != key or values.shape != (count,) or faces.shape != (count,) or not np.all(np.isfinite(values))
                or faces.min() < 0 or faces.max() >= triangle_count or not 0.0 <= value_error_m <= MAX_VALUE_ERROR_M):
            return False
        self._values, self._faces = values.astype(np.float64), faces.astype(np.int64)
        self._value_error_m = value_error_m
        return True

    def _store(self, path: Path, key: str) -> None:
        """Keep the lattice for the next run; a cache that cannot be written only costs time."""
        buffer = io.BytesIO()
        np.savez(buffer, values=self._values, faces=self._faces.astype(np.int32), key=key,
                 value_error_m=self._value_error_m)
        try:
            write_bytes_atomic(path, buffer.getvalue())
        except OSError:
            pass

    @property
    def kernel_arguments(self) -> Arrays:
        """The lattice as ``interval_kernel`` takes it: low corner (m), spacing (m), shape, flat values (m), their
        error (m), the mesh's bounding box (m), and the face closest to each vertex."""
        return (self._low, self._spacing, self._shape, self._values, self._value_error_m, self._mesh_low,
                self._mesh_high, self._faces)

    def interval_m(self, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interval (m) holding the signed distance at each (N, 3) point."""
        return lattice_intervals_m(np.ascontiguousarray(points_m, np.float64), self.kernel_arguments)


_GRIDS: "weakref.WeakKeyDictionary[DistanceOracle, DistanceGrid]" = weakref.WeakKeyDictionary()


def distance_grid_for(oracle: DistanceOracle) -> DistanceGrid:
    """The lattice of an oracle, built on first use and kept while the oracle lives."""
    if oracle not in _GRIDS:
        _GRIDS[oracle] = DistanceGrid(oracle)
    return _GRIDS[oracle]
