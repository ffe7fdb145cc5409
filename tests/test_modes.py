"""Modes: a set's cells fall into distinct poses where they fall apart in rotation or in position, and a connected
set of cells is never cut."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.transform import Rotation

from fixwizard.geometry.octree import PositionGrid
from fixwizard.geometry.se3 import quaternion_angle_rad
from fixwizard.geometry.so3_grid import RotationGrid
from fixwizard.solver.cells import CellSet
from fixwizard.solver.modes import POSITION_MODE_FRACTION, mode_labels, rotation_modes

GRID = RotationGrid()
CUBE = PositionGrid(np.zeros(3), 0.512)  # level 9 cells are 1 mm across
ROTATION_LEVEL, POSITION_LEVEL = 5, 9
RADIUS_M = 0.15  # position groups of at least 9.4 mm: level 5 ancestors, 16 mm across


def cell_set(rotations: Rotation, positions_m: np.ndarray) -> CellSet:
    """The cells holding the given poses (one per row; repeats kept)."""
    ids = GRID.cell_of(ROTATION_LEVEL, rotations)
    cells = np.floor(positions_m / CUBE.cell_side_m(POSITION_LEVEL)).astype(np.int32)
    return CellSet(GRID, CUBE, ROTATION_LEVEL, POSITION_LEVEL, ids, np.arange(len(ids)), cells)


def connected_cells(cells: CellSet) -> np.ndarray:
    """Component of each cell of the set's cells as they touch in SE(3): rotation cells within the sum of their
    ``gamma`` and octree cells sharing a face, an edge or a corner (every pair checked)."""
    rotations, gammas, index = cells.distinct_rotations()
    quaternions = rotations.as_quat()[index]
    first, second = np.triu_indices(len(cells), 1)
    angle = quaternion_angle_rad(quaternions[first], quaternions[second])
    rotation_touch = angle <= gammas[index][first] + gammas[index][second]
    position_touch = np.max(np.abs(cells.position_cells[first] - cells.position_cells[second]), axis=1) <= 1
    touching = rotation_touch & position_touch
    graph = coo_matrix((np.ones(touching.sum()), (first[touching], second[touching])), shape=(len(cells),) * 2)
    return connected_components(graph, directed=False)[1]


def test_poses_shifted_by_a_repeated_feature_at_one_rotation_are_two_modes():
    rotation = Rotation.from_rotvec([0.3, -0.2, 0.5])
    clump = np.random.default_rng(0).uniform(-0.002, 0.002, (200, 3))
    shift_m = np.array([0.05, 0.0, 0.0])  # bosses 50 mm apart on a fixture of 150 mm radius
    cells = cell_set(Rotation.concatenate([rotation] * 400), np.vstack([0.2 + clump, 0.2 + clump + shift_m]))
    labels = mode_labels(cells, RADIUS_M)
    assert len(np.unique(labels)) == 2
    assert len(np.unique(labels[:200])) == 1 and len(np.unique(labels[200:])) == 1


def test_a_long_connected_set_is_one_mode():
    """A fixture sliding along a face: a line of touching cells far longer than a position group, turning as
    it goes."""
    steps = np.linspace(0.0, 0.2, 400)
    rotations = Rotation.from_rotvec(np.outer(steps, [0.0, 0.0, 0.2]))
    cells = cell_set(rotations, 0.1 + np.outer(steps, [1.0, 0.3, 0.0]))
    assert len(np.unique(mode_labels(cells, RADIUS_M))) == 1


def test_cells_that_touch_at_a_corner_only_are_one_mode():
    """Octree cells along the cube's diagonal touch at corners only, also where they cross into the next position
    group."""
    rotation = Rotation.from_rotvec([0.1, 0.2, 0.3])
    steps = (0.2 + np.arange(100) * CUBE.cell_side_m(POSITION_LEVEL)) + 0.5e-3
    cells = cell_set(Rotation.concatenate([rotation] * 100), np.repeat(steps[:, None], 3, axis=1))
    assert len(np.unique(mode_labels(cells, RADIUS_M))) == 1


def test_positions_closer_than_a_position_group_stay_one_mode():
    rotation = Rotation.from_rotvec([0.1, 0.2, 0.3])
    gap_m = POSITION_MODE_FRACTION * RADIUS_M / 2
    cells = cell_set(Rotation.concatenate([rotation] * 2), np.array([[0.2, 0.2, 0.2], [0.2 + gap_m, 0.2, 0.2]]))
    assert len(np.unique(mode_labels(cells, RADIUS_M))) == 1


@pytest.mark.parametrize("seed", range(8))
def test_a_connected_set_of_cells_is_never_cut_and_each_mode_is_one_rotation_group(seed):
    """Random clumps of cells in rotation and position, some touching, some apart: every cell of a connected
    group shares its mode."""
    rng = np.random.default_rng(seed)
    clumps = rng.integers(2, 6)
    centres = Rotation.random(clumps, random_state=seed)
    rotations = Rotation.concatenate([centres[int(k)] * Rotation.from_rotvec(rng.normal(0, 0.03, 3))
                                      for k in rng.integers(0, clumps, 300)])
    positions_m = 0.25 + rng.uniform(-1, 1, (clumps, 3))[rng.integers(0, clumps, 300)] * 0.03
    positions_m += rng.normal(0, 0.004, (300, 3))
    cells = cell_set(rotations, positions_m)
    labels = mode_labels(cells, RADIUS_M)
    components = connected_cells(cells)
    for component in np.unique(components):
        assert len(np.unique(labels[components == component])) == 1
    groups = rotation_modes(cells)
    for label in np.unique(labels):
        assert len(np.unique(groups[labels == label])) == 1
    assert np.array_equal(np.unique(labels), np.arange(labels.max() + 1))
