"""Modes: groups of surviving cells in rotation space that are distinct poses for the operator.

Cells that touch (centres within ``gamma_i + gamma_j``) are connected. Connected groups whose
closest cells are less than ``MODE_GAP_RAD`` apart are one mode: such islands come from the
shape of the consistent set at the scale of the bounds, not from a symmetry, and no choice
of taps would tell them apart better than the bounds already do.
"""

import numpy as np
from scipy.cluster.hierarchy import DisjointSet
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

MODE_GAP_RAD = np.radians(5.0)
# Neighbour search runs on quaternion chords; 1 % slack absorbs the chord conversion's rounding.
TOUCH_SLACK = 1.01


def _chord(angle_rad: float) -> float:
    """Quaternion chord length of a rotation angle: ``|q1 - q2| = 2 sin(angle / 4)`` for aligned signs."""
    return 2.0 * np.sin(min(angle_rad, np.pi) / 4.0)


def _touching_groups(quaternions: np.ndarray, gammas_rad: np.ndarray) -> np.ndarray:
    count = len(quaternions)
    pairs = cKDTree(np.vstack([quaternions, -quaternions])).query_pairs(
        _chord(2.0 * float(np.max(gammas_rad)) * TOUCH_SLACK), output_type="ndarray") % count
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    if len(pairs):
        angles = (Rotation.from_quat(quaternions[pairs[:, 0]]).inv()
                  * Rotation.from_quat(quaternions[pairs[:, 1]])).magnitude()
        pairs = pairs[angles <= (gammas_rad[pairs[:, 0]] + gammas_rad[pairs[:, 1]]) * TOUCH_SLACK]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    return connected_components(graph, directed=False)[1]


def _merge_close_groups(quaternions: np.ndarray, groups: np.ndarray) -> np.ndarray:
    labels = np.unique(groups)
    trees = {label: cKDTree(np.vstack([quaternions[groups == label], -quaternions[groups == label]]))
             for label in labels}
    merged = DisjointSet(labels)
    for index, first in enumerate(labels):
        for second in labels[index + 1:]:
            if not merged.connected(first, second):
                gap = trees[first].query(quaternions[groups == second], k=1)[0].min()
                if gap <= _chord(MODE_GAP_RAD):
                    merged.merge(first, second)
    roots = np.array([merged[label] for label in labels])
    return np.unique(roots, return_inverse=True)[1][np.searchsorted(labels, groups)]


def rotation_modes(rotations: Rotation, gammas_rad: np.ndarray, cell_index: np.ndarray) -> np.ndarray:
    """Mode label (0..K-1) of each cell, given the distinct rotation cells (``rotations``, ``gammas_rad``)
    and each cell's index into them; the quaternion sign is handled by indexing both ``q`` and ``-q``."""
    if len(gammas_rad) == 0:
        return np.zeros(len(cell_index), np.int64)
    quaternions = rotations.as_quat().reshape(-1, 4)
    groups = _touching_groups(quaternions, gammas_rad)
    return _merge_close_groups(quaternions, groups)[cell_index]
