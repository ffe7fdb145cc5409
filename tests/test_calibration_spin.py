"""The fine tip must not depend on how the flange is spun about the tool axis."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.plans import tilted_hover_poses
from fixwizard.calibration.spin import spin_groups, spin_headings_rad
from fixwizard.calibration.tip import fit_fine_tip
from fixwizard.geometry.se3 import make_transform
from test_calibration_helpers import BASE_T_TABLE, TCP_P_TIP_M, tap

BASE_N_TABLE = BASE_T_TABLE[:3, 2]
HOVER = tilted_hover_poses(BASE_T_TABLE, TCP_P_TIP_M, 0.005, 0.01)


def spun(spins_deg: np.ndarray) -> np.ndarray:
    """The 40 hover poses of the tilted plan, the i-th turned by ``spins_deg[i]`` about its own tool axis."""
    return np.array([pose @ make_transform(Rotation.from_euler("z", spin, degrees=True), np.zeros(3))
                     for pose, spin in zip(HOVER, spins_deg, strict=True)])


def test_tilting_keeps_the_heading_and_spinning_turns_it_by_the_spin():
    headings = np.degrees(spin_headings_rad(spun(np.zeros(40)), BASE_N_TABLE))
    np.testing.assert_allclose(headings, headings[0], atol=1e-9)
    turned = np.degrees(spin_headings_rad(spun(np.full(40, 90.0)), BASE_N_TABLE))
    np.testing.assert_allclose((turned - headings + 180) % 360 - 180, 90, atol=1e-9)


def test_groups_are_split_at_gaps_and_joined_across_plus_minus_180_degrees():
    headings = np.radians([-175.0, 0.0, 175.0, 5.0, 100.0, 120.0])
    assert sorted(group.tolist() for group in spin_groups(headings)) == [[0, 2], [1, 3], [4, 5]]
    assert [group.tolist() for group in spin_groups(np.radians(np.arange(0, 360, 20.0)))] == [list(range(18))]


@pytest.mark.parametrize("spins_deg", [np.repeat([0.0, 90.0, 180.0, 270.0], 10),
                                       np.random.default_rng(3).uniform(-180, 180, 40)], ids=["four", "random"])
def test_honest_series_with_varied_spins_and_bounded_noise_pass(spins_deg):
    for seed in range(5):
        taps = np.concatenate([tap(spun(spins_deg), 0.3e-3, seed), tap(spun(spins_deg + 45), 0.3e-3, seed + 10)])
        fit = fit_fine_tip(taps, BASE_N_TABLE)
        assert fit.excluded == ()
        assert np.all(np.abs(fit.tcp_p_tip_m - TCP_P_TIP_M) < 4 * fit.standard_error_m)


def test_two_series_with_the_tool_remounted_between_them_are_refused_with_their_taps():
    remounted_m = TCP_P_TIP_M + [1.0e-3, -0.8e-3, 0.0]
    taps = np.concatenate([tap(HOVER, 0.1e-3), tap(spun(np.full(40, 90.0)), 0.1e-3, 1, remounted_m)])
    files = tuple(f"pt_{index}.pose" for index in range(80))
    with pytest.raises(CalibrationError, match=r"depends on how the flange is turned about the tool axis.*"
                       r"the 40 taps pt_(0|40)\.pose to pt_(39|79)\.pose .* 1\.\d\d mm apart .*"
                       r"calibrate from one series only"):
        fit_fine_tip(taps, BASE_N_TABLE, files)


def test_groups_too_small_to_determine_the_tip_are_not_compared():
    # five taps at another spin with a tip 3 mm away: too few to fit alone, so the residual test handles them
    taps = np.concatenate([tap(HOVER, 0.1e-3), tap(spun(np.full(40, 90.0))[:5], 0.1e-3, 1, TCP_P_TIP_M + 3e-3)])
    fit = fit_fine_tip(taps, BASE_N_TABLE)
    assert fit.inliers[:40].all()
