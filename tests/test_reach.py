"""The reach: certified poses pushed outward. Every one explains every tap for sure, so it must lie inside the
guaranteed set and bounds: a cross-check of the guarantee from the other side."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import real_taps
from fixwizard.fixture import load_fixture
from fixwizard.geometry.se3 import invert, transform_points
from fixwizard.solver.estimates import BoundCentre
from fixwizard.solver.reach import certified, pose_figures, reach
from fixwizard.solver.solve import solve

pytestmark = pytest.mark.slow  # real-data solves pushed outward, 15-40 s each


@pytest.mark.parametrize("run", ["student_3", "expert"])
def test_certified_poses_pushed_outward_stay_inside_the_guaranteed_bounds(real_data, run):
    fixture = load_fixture(real_data / "meshes" / "matlab_logo.ply")
    solution = solve(fixture, real_taps(real_data, run), 0.003, 0.001, max_cells=3e6)
    bounds = solution.bounds
    centre = BoundCentre(Rotation.from_matrix(bounds.base_T_cad_center[:3, :3]), bounds.base_T_cad_center[:3, 3])
    start = solution.base_T_cad @ invert(fixture.fix_T_cad)
    found = reach(solution.problem, [start], centre, -fixture.cad_p_center, fixture.oracle.hull_cover,
                  bounds.max_point_displacement_m)
    assert found is not None and len(found.poses) > 20
    for pose in found.poses:
        assert certified(solution.problem, pose)
        assert solution.contains(pose @ fixture.fix_T_cad)
        assert np.all(pose_figures(pose, centre, -fixture.cad_p_center, fixture.oracle.hull_cover)
                      <= [bounds.position_m, bounds.rotation_rad, bounds.max_point_displacement_m])
    # pushed outward, the reach goes well beyond the start: the bounds are at most this much too wide
    assert np.all(found.figures > 0.6 * np.array([bounds.position_m, bounds.rotation_rad,
                                                  bounds.max_point_displacement_m]))


def test_a_pose_that_misses_a_tap_does_not_certify(real_data):
    fixture = load_fixture(real_data / "meshes" / "matlab_logo.ply")
    taps = real_taps(real_data, "expert")
    solution = solve(fixture, taps, 0.003, 0.001, max_cells=1e6)
    pose = solution.base_T_cad @ invert(fixture.fix_T_cad)
    assert certified(solution.problem, pose)
    moved = pose.copy()
    moved[:3, 3] += [0.0, 0.0, 0.003]
    assert not certified(solution.problem, moved)
    assert transform_points(moved, np.zeros((1, 3))).shape == (1, 3)
