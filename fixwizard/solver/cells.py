"""Sets of SE(3) cells: rotation cells of the HealPix grid times position cells of the octree.

Many cells share a rotation, so a set stores its distinct rotation cells once
(``rotation_ids``) and each cell's index into them (``rotation_index``).
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.geometry.octree import PositionGrid
from fixwizard.geometry.so3_grid import RotationGrid


@dataclass
class CellSet:
    """Cells of ``base_T_fix`` at one rotation level and one position level.

    ``rotation_ids`` (U,): distinct rotation cells; ``rotation_index`` (N,): each cell's row
    in them; ``position_cells`` (N, 3): octree cells. Children of a cell are stored
    consecutively, eight per parent, so cell ``k``'s parent is ``k // 8``.
    """

    rotation_grid: RotationGrid
    position_grid: PositionGrid
    rotation_level: int
    position_level: int
    rotation_ids: np.ndarray
    rotation_index: np.ndarray
    position_cells: np.ndarray

    def __len__(self) -> int:
        return len(self.rotation_index)

    @property
    def rotation_cells(self) -> np.ndarray:
        """Rotation cell of each cell (N,)."""
        return self.rotation_ids[self.rotation_index]

    @property
    def position_bound_m(self) -> float:
        """``b_p``: largest distance (m) from a position cell's centre to any point of it."""
        return self.position_grid.half_diagonal_m(self.position_level)

    def distinct_rotations(self) -> tuple[Rotation, np.ndarray, np.ndarray]:
        """Centres and ``gamma`` (rad) of the distinct rotation cells, and each cell's index into them."""
        return (self.rotation_grid.centers(self.rotation_level, self.rotation_ids),
                self.rotation_grid.gamma(self.rotation_level, self.rotation_ids), self.rotation_index)

    def distinct_rotation_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """``distinct_rotations`` as matrices (U, 3, 3), and ``gamma`` (rad)."""
        return (self.rotation_grid.center_matrices(self.rotation_level, self.rotation_ids),
                self.rotation_grid.gamma(self.rotation_level, self.rotation_ids))

    def positions_m(self, indices: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Centres (m, base frame) of the position cells of the given cells."""
        return self.position_grid.centers_m(self.position_level, self.position_cells[indices])

    def contains(self, base_T_fix: np.ndarray) -> bool:
        """Whether a pose of the internal fixture frame lies in one of the cells."""
        return bool(self.locate(Rotation.from_matrix(base_T_fix[:3, :3]), base_T_fix[:3, 3])[0] >= 0)

    def _position_key(self, position_cells: np.ndarray) -> np.ndarray:
        """One integer per octree cell (N, 3) of this set's level: at most 2^20 per axis, a key fits in 62 bits."""
        side = 2**self.position_level
        cells = position_cells.astype(np.int64)
        return (cells[:, 0] * side + cells[:, 1]) * side + cells[:, 2]

    def __getstate__(self) -> dict[str, object]:
        """Pickled (to and from solver processes) without ``_lookup``, which is rebuilt where it is needed."""
        state = dict(self.__dict__)
        state.pop("_lookup", None)
        return state

    @cached_property
    def _lookup(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For ``locate``: the set's distinct rotation cells and position keys (sorted), and the composite key
        ``rotation rank * positions + position rank`` of every cell, sorted, with the cell of each (computed once
        per set: its arrays are never changed)."""
        rotations, rotation_rank = np.unique(self.rotation_cells, return_inverse=True)
        positions, position_rank = np.unique(self._position_key(self.position_cells), return_inverse=True)
        composite = rotation_rank.reshape(-1) * len(positions) + position_rank.reshape(-1)
        order = np.argsort(composite, kind="stable")
        return rotations, positions, composite[order], order

    def locate(self, base_R_fix: Rotation, base_p_fix: np.ndarray) -> np.ndarray:
        """The cell (row) holding each pose (rotations and positions (N, 3), m), -1 where no cell does."""
        rotation = self.rotation_grid.cell_of(self.rotation_level, base_R_fix)
        position = np.floor((np.asarray(base_p_fix).reshape(-1, 3) - self.position_grid.corner_m)
                            / self.position_grid.cell_side_m(self.position_level)).astype(np.int64)
        inside = np.all((position >= 0) & (position < 2**self.position_level), axis=1)
        position = np.where(inside[:, None], position, 0)
        rotations, positions, sorted_composite, order = self._lookup
        wanted_rotation = np.minimum(np.searchsorted(rotations, rotation), len(rotations) - 1)
        wanted_key = self._position_key(position)
        wanted_position = np.minimum(np.searchsorted(positions, wanted_key), len(positions) - 1)
        known = inside & (rotations[wanted_rotation] == rotation) & (positions[wanted_position] == wanted_key)
        wanted = wanted_rotation * len(positions) + wanted_position
        slots = np.minimum(np.searchsorted(sorted_composite, wanted), len(sorted_composite) - 1)
        found = known & (sorted_composite[slots] == wanted)
        return np.where(found, order[slots], -1)

    def subset(self, mask: np.ndarray) -> "CellSet":
        """The cells where ``mask`` is true, keeping only the rotation cells still used."""
        index = self.rotation_index[mask]
        used = np.zeros(len(self.rotation_ids), bool)
        used[index] = True
        remap = np.cumsum(used) - 1
        return CellSet(self.rotation_grid, self.position_grid, self.rotation_level, self.position_level,
                       self.rotation_ids[used], remap[index], self.position_cells[mask])

    @staticmethod
    def concatenate(parts: list["CellSet"]) -> "CellSet":
        """One set holding the cells of sets at the same levels of the same grids (a rotation cell used by several
        parts is listed once per part)."""
        first = parts[0]
        offsets = np.cumsum([0] + [len(part.rotation_ids) for part in parts[:-1]])
        return CellSet(first.rotation_grid, first.position_grid, first.rotation_level, first.position_level,
                       np.concatenate([part.rotation_ids for part in parts]),
                       np.concatenate([part.rotation_index + offset
                                       for part, offset in zip(parts, offsets, strict=True)]),
                       np.concatenate([part.position_cells for part in parts]))

    def split_rotations(self) -> "CellSet":
        """Every cell's 8 children in rotation (next rotation level), grouped per parent."""
        children = self.rotation_grid.children(self.rotation_level, self.rotation_ids)
        index = (8 * self.rotation_index[:, None] + np.arange(8)).reshape(-1)
        return CellSet(self.rotation_grid, self.position_grid, self.rotation_level + 1, self.position_level,
                       children, index, np.repeat(self.position_cells, 8, axis=0))

    def split_positions(self) -> "CellSet":
        """Every cell's 8 children in position (next position level), grouped per parent."""
        return CellSet(self.rotation_grid, self.position_grid, self.rotation_level, self.position_level + 1,
                       self.rotation_ids, np.repeat(self.rotation_index, 8),
                       self.position_grid.children(self.position_cells))


def root_cells(position_grid: PositionGrid) -> CellSet:
    """The 72 rotation cells of level 0 times the root position cube."""
    grid = RotationGrid()
    ids = np.arange(grid.n_cells(0), dtype=np.int64)
    return CellSet(grid, position_grid, 0, 0, ids, np.arange(len(ids)), np.zeros((len(ids), 3), np.int32))
