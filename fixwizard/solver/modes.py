"""Modes: groups of surviving cells that are distinct poses for the operator.

Cells are grouped first in rotation, through their ancestors at ``MODE_LEVEL`` (cells of about 4 degrees): two
ancestors are connected when they touch (centre angle at most ``gamma_i + gamma_j``). So groups closer than
roughly two such cells (under about 10 degrees) are one mode: islands at that scale come from the shape of the
consistent set, not from a symmetry, and the bounds already cover them.

Then each rotation group is split where its positions fall apart: a part with a repeated feature (two identical
bosses, a rail's holes) is explained by poses shifted by the feature's spacing at the same rotation. Position
cells are grouped through their octree ancestors of at least ``POSITION_MODE_FRACTION`` of the fixture radius
across, touching when they share a face, an edge or a corner. The projection of a connected set of cells onto
positions is connected, so a split never cuts a connected set; groups closer than about two such ancestors stay one
mode, and its bounds cover them.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from fixwizard.solver.cells import CellSet

MODE_LEVEL = 4
# Neighbour search runs on quaternion chords; 1 % slack absorbs the chord conversion's rounding.
TOUCH_SLACK = 1.01
# Positions apart by more than about twice this fraction of the fixture radius are distinct modes.
POSITION_MODE_FRACTION = 1 / 16
# The 13 octree neighbour offsets of one half of the 26 (the other half are their negatives).
HALF_NEIGHBOURS = np.array([offset for offset in np.ndindex(3, 3, 3) if offset > (1, 1, 1)], dtype=np.int64) - 1


def _touching_components(rotations: Rotation, gammas_rad: np.ndarray) -> np.ndarray:
    """Connected-component label of each rotation cell, cells touching when ``angle <= gamma_i + gamma_j``."""
    quaternions = rotations.as_quat().reshape(-1, 4)
    count = len(quaternions)
    radius = min(2.0 * float(np.max(gammas_rad)) * TOUCH_SLACK, np.pi)
    pairs = cKDTree(np.vstack([quaternions, -quaternions])).query_pairs(
        2.0 * np.sin(radius / 4.0), output_type="ndarray") % count
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    if len(pairs):  # angle <= gamma_i + gamma_j  <=>  |q_i . q_j| = cos(angle / 2) >= cos((gamma_i + gamma_j) / 2)
        dots = np.abs(np.einsum("ij,ij->i", quaternions[pairs[:, 0]], quaternions[pairs[:, 1]]))
        half_reach = np.minimum((gammas_rad[pairs[:, 0]] + gammas_rad[pairs[:, 1]]) * TOUCH_SLACK / 2, np.pi / 2)
        pairs = pairs[dots >= np.cos(half_reach)]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    return connected_components(graph, directed=False)[1]


def rotation_modes(cells: CellSet) -> np.ndarray:
    """Rotation group (0..K-1) of each cell of a non-empty set."""
    level = min(cells.rotation_level, MODE_LEVEL)
    grid = cells.rotation_grid
    coarse, coarse_index = np.unique(grid.ancestors(cells.rotation_level, cells.rotation_ids, level),
                                     return_inverse=True)
    components = _touching_components(grid.centers(level, coarse), grid.gamma(level, coarse))
    return np.unique(components, return_inverse=True)[1][coarse_index][cells.rotation_index]


def _grouped_position_components(groups: np.ndarray, position_cells: np.ndarray) -> np.ndarray:
    """Connected-component label (0..K-1) of each cell given its group (N,) and integer octree cell (N, 3) of
    one level: cells are connected when they are of one group and their octree cells are 26-neighbours."""
    cells = position_cells.astype(np.int64) - position_cells.min(axis=0) + 1  # neighbours at -1 stay >= 0
    side = int(cells.max()) + 2
    keys = ((groups.astype(np.int64) * side + cells[:, 0]) * side + cells[:, 1]) * side + cells[:, 2]
    occupied, occupied_index = np.unique(keys, return_inverse=True)
    occupied_index = occupied_index.ravel()
    rows, columns = [], []
    for offset in HALF_NEIGHBOURS:
        neighbour = occupied + (offset[0] * side + offset[1]) * side + offset[2]
        at = np.minimum(np.searchsorted(occupied, neighbour), len(occupied) - 1)
        found = np.flatnonzero(occupied[at] == neighbour)
        rows.append(found)
        columns.append(at[found])
    row, column = np.concatenate(rows), np.concatenate(columns)
    graph = coo_matrix((np.ones(len(row)), (row, column)), shape=(len(occupied), len(occupied)))
    return connected_components(graph, directed=False)[1][occupied_index]


def mode_labels(cells: CellSet, fixture_radius_m: float) -> np.ndarray:
    """Mode label (0..K-1) of each cell of a non-empty set: its rotation group, split where the group's positions
    fall apart (see the module doc). ``fixture_radius_m``: the fixture's radius (m)."""
    groups = rotation_modes(cells)
    grid, level = cells.position_grid, cells.position_level
    wanted = POSITION_MODE_FRACTION * fixture_radius_m
    coarse_level = max(0, min(level, int(np.floor(np.log2(grid.side_m / wanted)))))
    coarse = cells.position_cells.astype(np.int64) >> (level - coarse_level)
    if np.all(np.ptp(coarse, axis=0) <= 1):  # every cell within two ancestors a side: all of them touch
        return groups
    labels = _grouped_position_components(groups, coarse)
    return np.unique(labels, return_inverse=True)[1].ravel()
