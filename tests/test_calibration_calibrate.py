"""A whole calibration from the recorded poses of every step."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.calibration.calibrate import calibrate_tip
from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.taps import PoseSeries, ball_centres_m
from fixwizard.geometry.se3 import make_transform
from test_calibration_helpers import BASE_T_TABLE, TCP_P_TIP_M, synthetic_steps


def test_all_steps_give_the_tip_the_table_frame_and_a_bound_above_the_residuals():
    calibration = calibrate_tip(**synthetic_steps(), ball_diameter_m=0.003)
    assert np.all(np.abs(calibration.tcp_p_tip_m - TCP_P_TIP_M) < 4 * calibration.tip_standard_error_m)
    assert np.linalg.norm(calibration.pivot_tcp_p_tip_m - TCP_P_TIP_M) < 0.2e-3
    assert np.linalg.norm(calibration.base_T_table[:3, 3] - BASE_T_TABLE[:3, 3]) < 0.5e-3
    assert Rotation.from_matrix(calibration.base_T_table[:3, :3].T @ BASE_T_TABLE[:3, :3]).magnitude() < 1e-3
    assert calibration.tip_residuals.max_m < calibration.sample_bound_m
    assert calibration.sample_bound_reason.startswith(f"{calibration.sample_bound_m * 1e3:.1f} mm: ")


def test_without_taps_a_b_c_the_table_frame_follows_the_plane_and_the_base_x_axis():
    steps = synthetic_steps()
    del steps["table_coarse"]
    calibration = calibrate_tip(**steps, ball_diameter_m=0.003)
    base_T_table = calibration.base_T_table
    assert base_T_table[:3, 2] @ BASE_T_TABLE[:3, 2] > np.cos(1e-3)
    # x is the base x axis projected onto the table, so the table y axis is square to the base x axis
    assert base_T_table[0, 0] > 0.99 and base_T_table[0, 1] == pytest.approx(0.0, abs=1e-12)
    centroid = ball_centres_m(steps["table"].base_T_tcp, calibration.tcp_p_tip_m).mean(axis=0)
    np.testing.assert_allclose(base_T_table[:3, 3], centroid, atol=1e-12)
    assert "table_coarse" not in calibration.steps


def test_taps_a_b_c_on_another_plane_are_refused():
    steps = synthetic_steps()
    tilted_abc = make_transform(Rotation.from_rotvec([0.2, 0, 0]), [0, 0, 0]) @ steps["table_coarse"].base_T_tcp
    steps["table_coarse"] = PoseSeries(tilted_abc)
    with pytest.raises(CalibrationError, match="describe different planes"):
        calibrate_tip(**steps, ball_diameter_m=0.003)
