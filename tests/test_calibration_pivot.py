"""Coarse pivot calibration: tip and pivot point from flange poses about one fixed point."""

import numpy as np
import pytest

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.pivot import fit_pivot
from fixwizard.geometry.se3 import read_pose_file
from fixwizard.workflow.tip_calibration import read_pose_series
from test_calibration_helpers import TCP_P_TIP_M, pivot_poses, real_calib_dir

TILT_RAD = np.radians(25)
DIRECTIONS = np.array([[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0.7, 0.7, 0]])


def test_tip_and_pivot_are_recovered_within_the_noise_level():
    noise_m = 0.05e-3
    fit = fit_pivot(pivot_poses(TILT_RAD * DIRECTIONS, noise_m))
    # 25 degree tilts amplify position noise by about 1 / (2 sin 12.5 deg) = 2.3
    assert np.abs(fit.tcp_p_tip_m - TCP_P_TIP_M).max() < 3 * noise_m
    assert np.abs(fit.base_p_pivot_m - [0.4, -0.1, 0.03]).max() < 3 * noise_m
    assert fit.stats.max_m < 2 * np.sqrt(3) * noise_m
    assert fit.stats.rms_m <= fit.stats.max_m


def test_exact_poses_give_the_exact_tip_with_zero_residual():
    fit = fit_pivot(pivot_poses(TILT_RAD * DIRECTIONS[[0, 1, 3]]))
    np.testing.assert_allclose(fit.tcp_p_tip_m, TCP_P_TIP_M, atol=1e-12)
    assert fit.stats.max_m < 1e-12


@pytest.mark.parametrize("rotvecs_rad", [
    np.radians(2) * DIRECTIONS,  # rotations too small
    np.radians([[0, 0, 0], [20, 0, 0], [-20, 0, 0], [40, 0, 0]]),  # all about one axis
], ids=["tiny rotations", "one axis"])
def test_poses_that_cannot_determine_the_tip_are_refused_with_advice(rotvecs_rad):
    with pytest.raises(CalibrationError, match="tilt the tool in at least two different directions by 20 degrees"):
        fit_pivot(pivot_poses(rotvecs_rad))


def test_fewer_than_three_poses_are_refused():
    with pytest.raises(CalibrationError, match="at least 3 flange poses"):
        fit_pivot(pivot_poses(TILT_RAD * DIRECTIONS[:2]))


def test_real_pivot_poses_reproduce_the_published_coarse_tip():
    calib = real_calib_dir()
    fit = fit_pivot(read_pose_series(calib / "tip_manual").base_T_tcp)
    published = read_pose_file(calib / "tcp_t_tip_manual.pose")[:3, 3]
    assert np.abs(fit.tcp_p_tip_m - published).max() < 0.01e-3
    assert fit.stats.max_m < 1.5e-3
