"""Pieces of the search that carry the guarantee: the distance lattice and the cell sets."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.geometry.octree import PositionGrid
from fixwizard.geometry.se3 import make_transform
from fixwizard.solver.cells import root_cells
from fixwizard.solver.distance_grid import DistanceGrid
from shapes import SHAPES, as_fixture


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_distance_lattice_interval_holds_the_exact_signed_distance(name):
    fixture = as_fixture(name)
    grid = DistanceGrid(fixture.oracle)
    rng = np.random.default_rng(0)
    points = rng.uniform(-2.0, 2.0, (100_000, 3)) * fixture.radius_m
    exact = fixture.oracle.signed_distance_m(points)
    error = fixture.oracle.error_bound_m(points)
    low, high = grid.interval_m(points)
    assert np.all(exact + error >= low) and np.all(exact - error <= high)


def test_cell_set_split_and_subset_keep_each_pose_in_exactly_one_cell():
    cells = root_cells(PositionGrid(corner_m=np.zeros(3), side_m=0.1))
    cells = cells.split_rotations().split_positions().split_rotations()
    rng = np.random.default_rng(1)
    for _ in range(20):
        pose = make_transform(Rotation.random(random_state=rng.integers(1 << 30)), rng.random(3) * 0.1)
        assert cells.contains(pose)
        rotation = cells.rotation_grid.cell_of(cells.rotation_level, Rotation.from_matrix(pose[:3, :3]))[0]
        assert not cells.subset(cells.rotation_cells != rotation).contains(pose)
    assert len(np.unique(np.column_stack([cells.rotation_cells, cells.position_cells]), axis=0)) == len(cells)
