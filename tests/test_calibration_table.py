"""Table plane (fine, by SVD) and table frame (coarse, from taps A, B, C)."""

import numpy as np
import pytest

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.plans import grid_hover_poses
from fixwizard.calibration.table import coarse_table_frame, fit_table_plane
from fixwizard.geometry.se3 import make_transform, read_pose_file
from fixwizard.workflow.tip_calibration import read_pose_series
from test_calibration_helpers import BASE_T_TABLE, TCP_P_TIP_M, abc_taps, real_calib_dir, tap

NOISE_M = 0.05e-3
COARSE_TIP_M = TCP_P_TIP_M + [0.002, -0.001, 0.001]


def grid_taps(noise_m: float = NOISE_M) -> np.ndarray:
    return tap(grid_hover_poses(BASE_T_TABLE, TCP_P_TIP_M, 6, 6, 0.01, 0.02), noise_m)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def test_plane_normal_is_recovered_within_the_noise_and_points_towards_the_flange():
    plane = fit_table_plane(grid_taps(), COARSE_TIP_M)
    # +-0.05 mm over a 50 mm grid tilts a plane by at most about 0.1 mm / 50 mm = 0.11 degrees
    assert angle_deg(plane.base_n_table, BASE_T_TABLE[:3, 2]) < 0.11
    assert plane.stats.max_m < 2 * NOISE_M
    assert plane.excluded == ()


def test_a_wrong_coarse_tip_shifts_the_plane_but_not_its_normal():
    exact = fit_table_plane(grid_taps(0.0), TCP_P_TIP_M)
    coarse = fit_table_plane(grid_taps(0.0), COARSE_TIP_M)
    assert angle_deg(exact.base_n_table, coarse.base_n_table) < 1e-6
    assert exact.stats.max_m < 1e-9


def test_a_tap_off_the_table_is_excluded_and_named():
    taps = grid_taps()
    taps[7, :3, 3] += 3e-3 * BASE_T_TABLE[:3, 2]
    files = tuple(f"table_{index}.pose" for index in range(len(taps)))
    plane = fit_table_plane(taps, COARSE_TIP_M, files)
    assert [(tap.index, tap.file) for tap in plane.excluded] == [(7, "table_7.pose")]
    assert plane.excluded[0].residual_m == pytest.approx(3e-3, abs=0.2e-3)
    assert angle_deg(plane.base_n_table, BASE_T_TABLE[:3, 2]) < 0.11


def test_table_taps_that_turn_the_tool_are_refused():
    taps = grid_taps()
    taps[3] = taps[3] @ make_transform(np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]), [0, 0, 0])
    with pytest.raises(CalibrationError, match="tap 3 is turned by 90.0 degrees"):
        fit_table_plane(taps, COARSE_TIP_M)


def test_table_taps_along_a_line_are_refused():
    taps = tap(grid_hover_poses(BASE_T_TABLE, TCP_P_TIP_M, 1, 8, 0.01, 0.02))
    with pytest.raises(CalibrationError, match="lie almost on a line"):
        fit_table_plane(taps, COARSE_TIP_M)


def test_coarse_frame_has_origin_at_b_x_towards_a_and_c_on_the_positive_y_side():
    np.testing.assert_allclose(coarse_table_frame(abc_taps(), TCP_P_TIP_M), BASE_T_TABLE, atol=1e-12)


def test_a_fine_normal_replaces_the_coarse_z_axis():
    base_n_table = BASE_T_TABLE[:3, :3] @ [np.sin(0.01), 0, np.cos(0.01)]
    frame = coarse_table_frame(abc_taps(), TCP_P_TIP_M, base_n_table)
    np.testing.assert_allclose(frame[:3, 2], base_n_table, atol=1e-12)
    assert angle_deg(frame[:3, 0], BASE_T_TABLE[:3, 0]) == pytest.approx(np.degrees(0.01), abs=1e-3)


def test_coarse_taps_in_clockwise_order_are_refused():
    with pytest.raises(CalibrationError, match="tap them counter-clockwise"):
        coarse_table_frame(abc_taps()[::-1], TCP_P_TIP_M)


def test_coarse_taps_on_one_line_are_refused():
    taps = abc_taps()
    taps[2, :3, 3] = taps[1, :3, 3] - 0.5 * (taps[0, :3, 3] - taps[1, :3, 3])
    with pytest.raises(CalibrationError, match="nearly on one line"):
        coarse_table_frame(taps, TCP_P_TIP_M)


def test_real_table_taps_give_the_published_table_normal():
    calib = real_calib_dir()
    coarse_tip = read_pose_file(calib / "tcp_t_tip_manual.pose")[:3, 3]
    plane = fit_table_plane(read_pose_series(calib / "square_pts").base_T_tcp, coarse_tip)
    assert angle_deg(plane.base_n_table, read_pose_file(calib / "base_t_square.pose")[:3, 2]) < 0.01
    assert plane.stats.max_m < 0.1e-3


def test_real_coarse_taps_give_the_published_coarse_table_frame():
    calib = real_calib_dir()
    coarse_tip = read_pose_file(calib / "tcp_t_tip_manual.pose")[:3, 3]
    frame = coarse_table_frame(read_pose_series(calib / "square_manual").base_T_tcp, coarse_tip)
    np.testing.assert_allclose(frame, read_pose_file(calib / "base_t_square_manual.pose"), atol=1e-5)
