"""The paper's real robot data: four operators' taps on the MATLAB-logo fixture (1.0 mm bound, 3 mm ball)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import REFERENCE_BOUNDS, RUNS, real_taps
from fixwizard.fixture import load_fixture
from fixwizard.solver.solve import solve

TOLERANCE = 1.25  # within 25 % of the published bounds, or tighter


@pytest.fixture(scope="module")
def solutions(real_data):
    fixture = load_fixture(real_data / "meshes" / "matlab_logo.ply")
    return {run: solve(fixture, real_taps(real_data, run), 0.003, 0.001, max_cells=1e7) for run in RUNS}


@pytest.mark.parametrize("run", RUNS)
def test_each_run_is_unique_with_bounds_near_the_published_ones(solutions, run):
    solution = solutions[run]
    position_mm, rotation_deg = REFERENCE_BOUNDS[run]
    assert solution.status == "unique"
    assert solution.bounds.position_m * 1e3 <= position_mm * TOLERANCE
    assert np.degrees(solution.bounds.rotation_rad) <= rotation_deg * TOLERANCE


@pytest.mark.xfail(strict=True, reason=(
    "the paper reports agreement within 0.87 mm / 0.74 deg; here student_3's expected pose lies 1.9 mm from "
    "student_1's and 1.8 mm from student_2's (rotations within 1.5 deg). The same holds with the Minkowski mesh "
    "and unsigned distance, with sigma = 1 mm, and with the 100-199 series tip. Every run fits some pose within "
    "0.53-0.79 mm (minimax), so the runs are consistent; their likelihood-weighted means differ. Open question, "
    "see the issue notes."))
def test_the_four_expected_poses_agree(solutions):
    poses = [solutions[run].base_T_cad for run in RUNS]
    for index, first in enumerate(poses):
        for second in poses[index + 1:]:
            assert np.linalg.norm(first[:3, 3] - second[:3, 3]) < 0.001
            assert np.degrees(Rotation.from_matrix(first[:3, :3].T @ second[:3, :3]).magnitude()) < 1.0
