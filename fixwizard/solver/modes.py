"""Modes: groups of surviving cells in rotation space that are distinct poses for the operator.

Cells are grouped through their ancestors at ``MODE_LEVEL`` (cells of about 4 degrees): two
ancestors are connected when they touch (centre angle at most ``gamma_i + gamma_j``). So
groups closer than roughly two such cells (under about 10 degrees) are one mode: islands at
that scale come from the shape of the consistent set, not from a symmetry, and the bounds
already cover them.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import quaternion_angle_rad
from fixwizard.solver.cells import CellSet

MODE_LEVEL = 4
# Neighbour search runs on quaternion chords; 1 % slack absorbs the chord conversion's rounding.
TOUCH_SLACK = 1.01


def _touching_components(rotations: Rotation, gammas_rad: np.ndarray) -> np.ndarray:
    """Connected-component label of each rotation cell, cells touching when ``angle <= gamma_i + gamma_j``."""
    quaternions = rotations.as_quat().reshape(-1, 4)
    count = len(quaternions)
    radius = min(2.0 * float(np.max(gammas_rad)) * TOUCH_SLACK, np.pi)
    pairs = cKDTree(np.vstack([quaternions, -quaternions])).query_pairs(
        2.0 * np.sin(radius / 4.0), output_type="ndarray") % count
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    if len(pairs):
        angles = quaternion_angle_rad(quaternions[pairs[:, 0]], quaternions[pairs[:, 1]])
        pairs = pairs[angles <= (gammas_rad[pairs[:, 0]] + gammas_rad[pairs[:, 1]]) * TOUCH_SLACK]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    return connected_components(graph, directed=False)[1]


def rotation_modes(cells: CellSet) -> np.ndarray:
    """Mode label (0..K-1) of each cell of a non-empty set."""
    level = min(cells.rotation_level, MODE_LEVEL)
    grid = cells.rotation_grid
    coarse, coarse_index = np.unique(grid.ancestors(cells.rotation_level, cells.rotation_ids, level),
                                     return_inverse=True)
    components = _touching_components(grid.centers(level, coarse), grid.gamma(level, coarse))
    return np.unique(components, return_inverse=True)[1][coarse_index][cells.rotation_index]
