"""Position octree: a cube split into 8 per level; cells are integer coordinates on a level's lattice."""

from dataclasses import dataclass

import numpy as np

# Cells are int32 coordinates: below 2^31 per axis. Level 30 cells of a 1 m cube are 1 nm across.
MAX_LEVEL = 30
CHILD_OFFSETS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.int32)


@dataclass(frozen=True)
class PositionGrid:
    """Cube of side ``side_m`` with its minimum corner at ``corner_m`` (base frame, m), split per level."""

    corner_m: np.ndarray
    side_m: float

    def cell_side_m(self, level: int) -> float:
        """Edge length (m) of a cell at ``level``."""
        return self.side_m / 2**level

    def half_diagonal_m(self, level: int) -> float:
        """Largest distance (m) from a cell's centre to any point of the cell: the bound ``b_p``."""
        return 0.5 * np.sqrt(3.0) * self.cell_side_m(level)

    def centers_m(self, level: int, cells: np.ndarray) -> np.ndarray:
        """Centres (N, 3) in m of (N, 3) integer cells at ``level``."""
        return self.corner_m + (cells + 0.5) * self.cell_side_m(level)

    def children(self, cells: np.ndarray) -> np.ndarray:
        """The 8 children of each cell, (8N, 3), grouped per parent."""
        return (2 * cells[:, None, :] + CHILD_OFFSETS[None, :, :]).reshape(-1, 3)

    def cell_of(self, level: int, position_m: np.ndarray) -> np.ndarray:
        """Integer cell (3,) holding a position (m); it may lie outside the root cube."""
        return np.floor((np.asarray(position_m) - self.corner_m) / self.cell_side_m(level)).astype(np.int64)
