"""The tip calibration's verdict: good when the tip's uncertainty fits in the sample bound's margin and the two
tips agree, usable or redo (with the reason in plain words) when they do not, or when taps were left out."""

import dataclasses

import numpy as np
import pytest

from fixwizard.calibration.residuals import ExcludedTap, ResidualStats
from fixwizard.calibration.store import TipCalibration
from fixwizard.calibration.taps import PoseSeries
from fixwizard.calibration.verdict import tip_verdict

TIP_M = np.array([0.0, 0.0, 0.15])


def calibration(standard_error_mm=(0.04, 0.04, 0.17), pivot_offset_mm=0.3, pivot_max_mm=0.19, tip_max_mm=0.18,
                bound_mm=0.5, excluded=0) -> TipCalibration:
    """A calibration like the simulated cell's (sample bound 0.5 mm) with the figures the verdict reads changed."""
    tilted = PoseSeries(np.tile(np.eye(4), (40, 1, 1)), (),
                        tuple(ExcludedTap(index, None, 0.002, 0.001) for index in range(excluded)))
    return TipCalibration(
        name="tip", created="2024-05-01T10:00:00+00:00", robot="sim", tcp_p_tip_m=TIP_M, ball_diameter_m=0.003,
        sample_bound_m=bound_mm / 1e3, sample_bound_reason="", base_T_table=np.eye(4),
        pivot_tcp_p_tip_m=TIP_M + [pivot_offset_mm / 1e3, 0.0, 0.0],
        pivot_residuals=ResidualStats(pivot_max_mm / 2e3, pivot_max_mm / 1e3),
        table_residuals=ResidualStats(1e-4, 2e-4), tip_residuals=ResidualStats(tip_max_mm / 2e3, tip_max_mm / 1e3),
        tip_condition_number=4.3, tip_standard_error_m=np.array(standard_error_mm) / 1e3, steps={"tilted": tilted})


def test_a_calibration_like_the_simulated_cells_is_good_and_says_how_well_the_tip_is_known():
    verdict = tip_verdict(calibration())
    assert verdict.level == "good"
    assert verdict.reasons == ("the ball centre is known to about 0.18 mm and each tap is trusted to 0.5 mm; the "
                               "pivot and the table taps agree",)
    assert verdict.headline() == "GOOD: use this calibration."


@pytest.mark.parametrize(("standard_error_mm", "level"), [((0.0, 0.0, 0.32), "good"), ((0.0, 0.0, 0.33), "usable"),
                                                          ((0.0, 0.0, 0.5), "usable"), ((0.0, 0.0, 0.51), "redo")])
def test_the_tips_uncertainty_must_fit_in_the_margin_the_bound_leaves_above_the_largest_residual(standard_error_mm,
                                                                                                  level):
    # margin 0.5 - 0.18 = 0.32 mm: good up to it, usable up to the bound, redo beyond; the pivot agrees throughout
    verdict = tip_verdict(calibration(standard_error_mm=standard_error_mm, pivot_offset_mm=0.0))
    assert verdict.level == level
    if level != "good":
        assert verdict.reasons[0].startswith(f"the ball centre is {'only ' if level == 'redo' else ''}known to about "
                                             f"{standard_error_mm[2]:.2f} mm")


def test_tips_that_disagree_beyond_their_own_errors_ask_for_a_check_of_the_ball():
    # normal disagreement: 3 x 0.19 + 2 x 0.18 = 0.93 mm
    assert tip_verdict(calibration(pivot_offset_mm=0.9)).level == "good"
    usable = tip_verdict(calibration(pivot_offset_mm=1.5))
    assert usable.level == "usable" and "the ball may have slipped in the pivot" in usable.reasons[0]
    redo = tip_verdict(calibration(pivot_offset_mm=2.0))
    assert redo.level == "redo" and redo.reasons[0] == ("the pivot and the table taps put the ball 2.00 mm apart (up "
                                                        "to 0.93 mm is normal): check that the ball is tight")
    assert redo.headline() == "REDO: calibrate again (Redo from the pivot)."


@pytest.mark.parametrize(("pivot_offset_mm", "level"), [(0.05, "good"), (0.09, "good"), (0.15, "usable"),
                                                        (0.19, "usable"), (0.25, "redo")])
def test_an_exact_arm_tells_its_tips_apart_no_finer_than_a_robots_repeatability(pivot_offset_mm, level):
    # residuals and scatter near zero (the loopback controller, an arm without kinematic error) would make any
    # difference a loose ball; below 0.1 mm two tips of one robot agree, up to 0.2 mm usable, beyond that redo
    exact = calibration(standard_error_mm=(0.001, 0.001, 0.002), pivot_offset_mm=pivot_offset_mm, pivot_max_mm=0.001,
                        tip_max_mm=0.001)
    verdict = tip_verdict(exact)
    assert verdict.level == level, verdict.reasons
    if level != "good":
        assert verdict.reasons[0].startswith(f"the pivot and the table taps put the ball {pivot_offset_mm:.2f} mm "
                                             "apart (up to 0.10 mm is normal)")


def test_many_taps_left_out_mean_something_moved_and_a_large_bound_means_loose_bounds():
    assert tip_verdict(calibration(excluded=8)).level == "good"  # 8 of 40: the robust fit's business
    moved = tip_verdict(calibration(excluded=9))
    assert moved.level == "redo" and moved.reasons[0].startswith("9 of 40 tilted taps did not fit the others")
    loose = tip_verdict(dataclasses.replace(calibration(), sample_bound_m=1.5e-3))
    assert loose.level == "usable"
    assert loose.reasons == ("each tap is only trusted to 1.5 mm, so the fixture will be known to about 2-4 mm",)
