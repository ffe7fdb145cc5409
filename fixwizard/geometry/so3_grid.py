"""Hierarchical rotation grid: HealPix (nested) directions times tilt angles, 72 cells at level 0.

A rotation ``R`` is located by its direction ``d = R e_z`` (a HealPix pixel) and a tilt
``psi``: ``R = S(d) Rz(psi)``. The section ``S`` is fixed per level-0 (base) pixel ``b``:
``S(d) = W(c_b -> d) S0_b`` with ``W`` the shortest rotation taking the base pixel centre
``c_b`` to ``d`` and ``S0_b`` the shortest rotation taking ``e_z`` to ``c_b``. Base pixels
span under 50 degrees, so ``S`` is smooth on each and has no pole singularity; nested
children stay in their base pixel, so every child cell lies inside its parent and the
cells of a level partition SO(3).

Cell bound ``gamma`` (largest angle between the cell centre and any rotation in it). With
``M = S(d_c)^T S(d)`` written as swing times twist about the body z axis, the swing angle is
``alpha`` (the angle between ``d_c`` and ``d``) and the twist is ``E``, the area of the
spherical triangle ``(c_b, d_c, d)`` (the holonomy of ``W``). A tilt offset adds to the
twist, so ``angle(S(d_c) Rz(psi_c), S(d) Rz(psi)) = 2 acos(cos(alpha/2) cos((E + psi - psi_c)/2))
<= g(d) = 2 acos(cos(alpha/2) cos((|E| + step/2)/2))``. ``alpha`` and ``|E|`` grow
monotonically along every great-circle ray from ``d_c``, so on a pixel that is star-shaped
about its centre the maximum of ``g`` lies on the boundary; it is taken over dense boundary
samples plus a margin of ``LIPSCHITZ_G * 0.6 * spacing`` between samples (``g`` changes at
most by ``alpha + E`` between two directions, and ``E <= h tan(beta / 2) < 0.5 h`` for a
step ``h`` at ``beta < 50 deg`` from ``c_b``, so 2 is a safe Lipschitz constant; 0.6 rather
than 0.5 of the chord covers the edge's curvature between samples). Tests check the bound
against random rotations at several levels.
"""

from typing import overload

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.geometry.healpix import pixel_boundaries, pixel_centers, pixels_of

BASE_TILTS = 6
BASE_PIXELS = 12
CELLS_PER_LEVEL0 = BASE_PIXELS * BASE_TILTS
# Cell ids ``pixel * n_tilts + tilt`` are int64: 72 * 8^18 < 2^63 < 72 * 8^19. Level 18 cells are 2e-6 rad across.
MAX_LEVEL = 18
BOUNDARY_STEPS = 32
LIPSCHITZ_G = 2.0
_EZ = np.array([0.0, 0.0, 1.0])


@overload
def chord(angle_rad: float) -> float: ...
@overload
def chord(angle_rad: np.ndarray) -> np.ndarray: ...
def chord(angle_rad: np.ndarray | float) -> np.ndarray | float:
    """Largest displacement of a unit-lever point rotated by ``angle``: ``2 sin(angle / 2)``, angle capped at pi
    (the cancellation-free form of ``sqrt(2 - 2 cos(angle))``)."""
    return 2.0 * np.sin(np.minimum(angle_rad, np.pi) / 2.0)


def _shortest_rotations(from_dirs: np.ndarray, to_dirs: np.ndarray) -> np.ndarray:
    """Matrices (N, 3, 3) of the shortest rotations taking unit vectors ``from_dirs`` to ``to_dirs`` (both (N, 3),
    none antipodal): ``c I + [v]x + v v^T / (1 + c)`` with ``v = a x b``, ``c = a . b``."""
    v = np.cross(from_dirs, to_dirs)
    c = np.sum(from_dirs * to_dirs, axis=-1)
    matrices = v[:, :, None] * (v / (1.0 + c)[:, None])[:, None, :]
    matrices[:, 0, 0] += c
    matrices[:, 1, 1] += c
    matrices[:, 2, 2] += c
    matrices[:, 0, 1] -= v[:, 2]
    matrices[:, 1, 0] += v[:, 2]
    matrices[:, 0, 2] += v[:, 1]
    matrices[:, 2, 0] -= v[:, 1]
    matrices[:, 1, 2] -= v[:, 0]
    matrices[:, 2, 1] += v[:, 0]
    return matrices


def _tilted(sections: np.ndarray, psi_rad: np.ndarray) -> np.ndarray:
    """``sections @ Rz(psi)`` for matrices (N, 3, 3) and angles (N,): the first two columns turned by ``psi``."""
    cos, sin = np.cos(psi_rad)[:, None], np.sin(psi_rad)[:, None]
    tilted = sections.copy()
    tilted[:, :, 0] = sections[:, :, 0] * cos + sections[:, :, 1] * sin
    tilted[:, :, 1] = sections[:, :, 1] * cos - sections[:, :, 0] * sin
    return tilted


def _angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) between unit vectors along the last axis, accurate at small angles."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def _triangle_area(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Area (sr) of spherical triangles with unit-vector corners (Van Oosterom-Strackee)."""
    numerator = np.abs(np.sum(a * np.cross(b, c), axis=-1))
    denominator = 1.0 + np.sum(a * b, axis=-1) + np.sum(b * c, axis=-1) + np.sum(c * a, axis=-1)
    return 2.0 * np.arctan2(numerator, denominator)


def swing_twist_angle(swing: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) of a swing by ``swing`` composed with a twist by ``twist`` about the swung axis."""
    sin2 = np.sin(swing / 2) ** 2 + np.sin(twist / 2) ** 2 - (np.sin(swing / 2) * np.sin(twist / 2)) ** 2
    return 2.0 * np.arcsin(np.sqrt(np.clip(sin2, 0.0, 1.0)))


class RotationGrid:
    """The hierarchical SO(3) grid. A cell at ``level`` is ``pixel * n_tilts(level) + tilt``."""

    def __init__(self) -> None:
        self._base_centers = pixel_centers(1, np.arange(BASE_PIXELS))
        self._base_sections = _shortest_rotations(np.tile(_EZ, (BASE_PIXELS, 1)), self._base_centers)
        self._pixel_gamma: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @staticmethod
    def n_tilts(level: int) -> int:
        return BASE_TILTS * 2**level

    @staticmethod
    def n_cells(level: int) -> int:
        return CELLS_PER_LEVEL0 * 8**level

    @staticmethod
    def tilt_step_rad(level: int) -> float:
        return 2.0 * np.pi / RotationGrid.n_tilts(level)

    def children(self, level: int, cells: np.ndarray) -> np.ndarray:
        """The 8 children at ``level + 1`` of each cell, (8N,), grouped per parent (``level < MAX_LEVEL``)."""
        if level >= MAX_LEVEL:
            raise ValueError(f"rotation cells go no finer than level {MAX_LEVEL}")
        pixels, tilts = np.divmod(cells, self.n_tilts(level))
        child_pixels = 4 * pixels[:, None, None] + np.arange(4)[None, :, None]
        child_tilts = 2 * tilts[:, None, None] + np.arange(2)[None, None, :]
        return (child_pixels * self.n_tilts(level + 1) + child_tilts).reshape(-1)

    def ancestors(self, level: int, cells: np.ndarray, coarse_level: int) -> np.ndarray:
        """The cells at ``coarse_level <= level`` that hold the given cells."""
        pixels, tilts = np.divmod(np.asarray(cells, np.int64), self.n_tilts(level))
        steps = level - coarse_level
        return (pixels >> (2 * steps)) * self.n_tilts(coarse_level) + (tilts >> steps)

    def _sections(self, level: int, pixels: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """``S(d)`` (N, 3, 3) for directions ``d`` lying in the given pixels."""
        base = pixels >> (2 * level)
        return _shortest_rotations(self._base_centers[base], directions) @ self._base_sections[base]

    def center_matrices(self, level: int, cells: np.ndarray) -> np.ndarray:
        """Centre rotations (N, 3, 3) of cells (the rotation part of ``base_T_fix``)."""
        pixels, tilts = np.divmod(np.asarray(cells, np.int64), self.n_tilts(level))
        directions = pixel_centers(2**level, pixels)
        psi = (tilts + 0.5) * self.tilt_step_rad(level)
        return _tilted(self._sections(level, pixels, directions), psi)

    def centers(self, level: int, cells: np.ndarray) -> Rotation:
        """``center_matrices`` as rotations."""
        return Rotation.from_matrix(self.center_matrices(level, cells))

    def sample(self, level: int, cells: np.ndarray, rng: np.random.Generator) -> Rotation:
        """One random rotation inside each cell (direction from a random pixel 10 levels finer)."""
        pixels, tilts = np.divmod(np.asarray(cells, np.int64), self.n_tilts(level))
        depth = 10
        fine = (pixels << (2 * depth)) + rng.integers(0, 4**depth, size=len(pixels))
        directions = pixel_centers(2 ** (level + depth), fine)
        psi = (tilts + rng.random(len(tilts))) * self.tilt_step_rad(level)
        return Rotation.from_matrix(_tilted(self._sections(level, pixels, directions), psi))

    def cell_of(self, level: int, rotations: Rotation) -> np.ndarray:
        """Cells holding the given rotations."""
        matrices = rotations.as_matrix().reshape(-1, 3, 3)
        directions = matrices[:, :, 2]
        pixels = pixels_of(2**level, directions)
        twist = np.swapaxes(self._sections(level, pixels, directions), 1, 2) @ matrices
        psi = np.mod(np.arctan2(twist[:, 1, 0], twist[:, 0, 0]), 2.0 * np.pi)
        tilts = np.minimum((psi / self.tilt_step_rad(level)).astype(np.int64), self.n_tilts(level) - 1)
        return pixels * self.n_tilts(level) + tilts

    def gamma(self, level: int, cells: np.ndarray) -> np.ndarray:
        """Largest angle (rad) between each cell's centre and any rotation in the cell; cached per pixel
        (sorted pixels and their values: a deep level has far more pixels than a search ever touches)."""
        pixels = np.asarray(cells, np.int64) // self.n_tilts(level)
        known, values = self._pixel_gamma.get(level, (np.zeros(0, np.int64), np.zeros(0)))
        wanted = np.unique(pixels)
        missing = wanted[~np.isin(wanted, known, assume_unique=True)]
        if len(missing):
            computed = np.concatenate([self._compute_gamma(level, chunk)
                                       for chunk in np.array_split(missing, max(1, len(missing) // 20000))])
            known, values = np.concatenate([known, missing]), np.concatenate([values, computed])
            order = np.argsort(known, kind="stable")
            known, values = known[order], values[order]
            self._pixel_gamma[level] = known, values
        return values[np.searchsorted(known, pixels)]

    def _compute_gamma(self, level: int, pixels: np.ndarray) -> np.ndarray:
        nside = 2**level
        boundary = pixel_boundaries(nside, pixels, BOUNDARY_STEPS)
        centers = pixel_centers(nside, pixels)[:, None, :]
        base = self._base_centers[pixels >> (2 * level)][:, None, :]
        alpha = _angle_between(centers, boundary)
        twist = _triangle_area(base, centers, boundary) + 0.5 * self.tilt_step_rad(level)
        spacing = _angle_between(boundary, np.roll(boundary, -1, axis=1)).max(axis=1)
        return swing_twist_angle(alpha, twist).max(axis=1) + LIPSCHITZ_G * 0.6 * spacing
