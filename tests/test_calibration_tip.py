"""Fine tip from tilted table taps: least squares on the taps that belong, with the conditioning reported."""

import numpy as np
import pytest

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.plans import tilted_hover_poses
from fixwizard.calibration.tip import fit_fine_tip
from fixwizard.geometry.se3 import read_pose_file
from fixwizard.workflow.tip_calibration import read_pose_series
from test_calibration_helpers import BASE_T_TABLE, TCP_P_TIP_M, real_calib_dir, tap

NOISE_M = 0.1e-3
BASE_N_TABLE = BASE_T_TABLE[:3, 2]
COARSE_TIP_M = TCP_P_TIP_M + [0.002, 0.0, 0.001]


def tilted_taps(noise_m: float = NOISE_M, tilts_deg: tuple[float, ...] = (10, 15, 20, 25, 30)) -> np.ndarray:
    """40 taps: 8 directions x 5 tilts, planned with a coarse tip 2.2 mm off."""
    return tap(tilted_hover_poses(BASE_T_TABLE, COARSE_TIP_M, 0.005, 0.01, tilts_deg), noise_m)


def test_tip_is_recovered_within_its_standard_error_and_the_noise_level():
    fit = fit_fine_tip(tilted_taps(), BASE_N_TABLE)
    assert np.all(np.abs(fit.tcp_p_tip_m - TCP_P_TIP_M) < 4 * fit.standard_error_m)
    # sideways the tilts (sin 10..30 deg) fix the tip well; along the tool axis only cos(tilt) varies
    assert np.all(fit.standard_error_m[:2] < NOISE_M / 2)
    assert fit.standard_error_m[2] < 3 * NOISE_M
    assert fit.stats.max_m < 1.5 * NOISE_M
    assert fit.condition_number == pytest.approx(fit.spread[0] / fit.spread[2])
    assert fit.excluded == ()


def test_taps_that_do_not_belong_are_excluded_and_named():
    taps = tilted_taps()
    taps[5, :3, 3] -= 15e-3 * BASE_N_TABLE  # missed the table edge and went on down
    taps[17, :3, 3] += 5e-3 * BASE_N_TABLE  # a file of another series
    taps[30, :3, 3] += 2e-3 * BASE_N_TABLE  # stopped early
    files = tuple(f"tilted_{index}.pose" for index in range(len(taps)))
    fit = fit_fine_tip(taps, BASE_N_TABLE, files)
    assert [(tap.index, tap.file) for tap in fit.excluded] == [(5, "tilted_5.pose"), (17, "tilted_17.pose"),
                                                              (30, "tilted_30.pose")]
    assert [round(tap.residual_m * 1e3) for tap in fit.excluded] == [-15, 5, 2]
    assert fit.excluded[0].describe().startswith("tap 5 (tilted_5.pose): -14.9")
    assert np.all(np.abs(fit.tcp_p_tip_m - TCP_P_TIP_M) < 4 * fit.standard_error_m)


def test_honest_scatter_below_one_millimetre_is_never_rejected():
    fit = fit_fine_tip(tilted_taps(noise_m=0.5e-3), BASE_N_TABLE)
    assert fit.excluded == ()


def test_more_than_a_third_of_taps_that_disagree_are_refused_with_their_names():
    taps = tilted_taps()
    wrong = np.arange(0, 40, 3)
    taps[wrong, :3, 3] += np.linspace(3e-3, 20e-3, len(wrong))[:, None] * BASE_N_TABLE
    with pytest.raises(CalibrationError, match=r"14 of the 40 tilted taps disagree .* tap 0, tap 3, tap 6"):
        fit_fine_tip(taps, BASE_N_TABLE)


def test_taps_at_a_single_tilt_are_refused_with_advice():
    with pytest.raises(CalibrationError, match="tap the table at tilts from 10 to 30 degrees"):
        fit_fine_tip(tilted_taps(tilts_deg=(20,) * 5), BASE_N_TABLE)


def test_too_few_taps_are_refused():
    with pytest.raises(CalibrationError, match="at least 8 tilted taps"):
        fit_fine_tip(tilted_taps()[:5], BASE_N_TABLE)


def real_tilted_series():
    calib = real_calib_dir()
    return read_pose_series(calib / "tip_pts"), read_pose_file(calib / "base_t_square.pose")[:3, 2]


def test_real_tilted_series_fits_the_table_to_a_third_of_a_millimetre():
    series, base_n_table = real_tilted_series()
    fit = fit_fine_tip(series.base_T_tcp[100:], base_n_table, series.files[100:])
    assert fit.stats.max_m <= 0.35e-3
    assert fit.stats.rms_m == pytest.approx(0.10e-3, abs=0.01e-3)
    assert fit.excluded == ()


def test_real_taps_off_the_table_are_excluded_and_named_not_averaged_in():
    series, base_n_table = real_tilted_series()
    keep = np.r_[0:11, 100:200]
    fit = fit_fine_tip(series.base_T_tcp[keep], base_n_table, tuple(series.files[index] for index in keep))
    # files 0-10 lie 16 to 61 mm off the table
    assert {tap.file for tap in fit.excluded} == {f"base_t_tcp_pt_{index}.pose" for index in range(11)}
    assert fit.stats.max_m <= 0.35e-3


def test_real_series_with_the_flange_turned_90_degrees_is_refused_not_mixed_in():
    series, base_n_table = real_tilted_series()
    # files 11-99 are a second series with the flange turned 90 degrees about the tool axis: they agree with
    # each other to 0.1 mm RMS and fitted with files 100-199 stay within 1.7 mm, yet alone give a tip 2.6 mm
    # away, which no rigidly mounted tool can do
    with pytest.raises(CalibrationError) as refused:
        fit_fine_tip(series.base_T_tcp, base_n_table, series.files)
    message = str(refused.value)
    assert "depends on how the flange is turned about the tool axis" in message
    assert "the 86 taps base_t_tcp_pt_11.pose to base_t_tcp_pt_96.pose (flange heading" in message
    assert "the 100 taps base_t_tcp_pt_100.pose to base_t_tcp_pt_199.pose (heading" in message
    assert "2.64 mm apart" in message and "calibrate from one series only" in message
    assert message.endswith("Already left out for their residuals: the 14 taps base_t_tcp_pt_0.pose to "
                            "base_t_tcp_pt_10.pose, base_t_tcp_pt_97.pose to base_t_tcp_pt_99.pose.")


def test_real_second_series_alone_fits_as_well_as_the_first():
    series, base_n_table = real_tilted_series()
    fit = fit_fine_tip(series.base_T_tcp[11:100], base_n_table, series.files[11:100])
    assert fit.excluded == () and fit.stats.rms_m < 0.15e-3
