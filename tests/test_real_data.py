"""The paper's real robot data: four operators' taps on the MATLAB-logo fixture (1.0 mm bound, 3 mm ball)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import REFERENCE_BOUNDS, RUNS, real_taps
from fixwizard.fixture import load_fixture
from fixwizard.geometry.meb import minimum_enclosing_ball
from fixwizard.geometry.se3 import transform_points
from fixwizard.solver.estimates import rotation_center
from fixwizard.solver.solve import solve

pytestmark = pytest.mark.slow  # solves of the paper's real runs at full budget (minutes in all)

TOLERANCE = 1.25  # within 25 % of the published bounds, or tighter


@pytest.fixture(scope="module")
def logo(real_data):
    return load_fixture(real_data / "meshes" / "matlab_logo.ply")


@pytest.fixture(scope="module")
def solutions(real_data, logo):
    return {run: solve(logo, real_taps(real_data, run), 0.003, 0.001, max_cells=1e7) for run in RUNS}


@pytest.mark.parametrize("run", RUNS)
def test_each_run_is_unique_with_bounds_near_the_published_ones(solutions, run):
    solution = solutions[run]
    position_mm, rotation_deg = REFERENCE_BOUNDS[run]
    assert solution.status == "unique"
    assert solution.bounds.position_m * 1e3 <= position_mm * TOLERANCE
    assert np.degrees(solution.bounds.rotation_rad) <= rotation_deg * TOLERANCE


def test_the_four_expected_poses_agree_as_the_paper_measures_it(solutions, logo):
    """The paper's 0.87 mm / 0.74 deg are radii of the smallest balls enclosing the runs' expected positions of
    the fixture's centre (its mesh is centred on its minimum enclosing ball) and their rotations (in the
    quaternion chart); the reference implementation's experiments/analyze_real_exp.py computes them so.
    Pairwise, expected positions differ by up to twice that radius."""
    base_p_centres = np.array([transform_points(solutions[run].base_T_cad, logo.cad_p_center[None])[0]
                               for run in RUNS])
    rotations = Rotation.from_matrix(np.array([solutions[run].base_T_cad[:3, :3] for run in RUNS]))
    rotation_radius_rad = (rotation_center(rotations).inv() * rotations).magnitude().max()
    assert minimum_enclosing_ball(base_p_centres).radius < 0.001
    assert np.degrees(rotation_radius_rad) < 1.0
