"""A report's age as `verify` states it: a report dated in the future is said to be so, with the clocks to check,
never a negative age."""

import dataclasses
from pathlib import Path

from fixwizard import report
from fixwizard.workflow.verify import report_lines

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "report.yaml"


def test_a_report_dated_in_the_future_is_said_so_with_the_clocks_to_check():
    loaded = report.load(EXAMPLE)
    (line,) = report_lines(loaded, -3 * 86400.0)
    assert "dated 3.0 days in the future (check the clocks of the PCs)" in line and "-3.0" not in line


def test_a_report_a_little_ahead_of_this_clock_is_no_age_below_zero():
    """Clocks of two PCs may differ by up to report.FUTURE_TOLERANCE_S: such a report is 0 s old."""
    (line,) = report_lines(report.load(EXAMPLE), -report.FUTURE_TOLERANCE_S / 2)
    assert ", 0 s old," in line


def test_an_old_report_is_said_old():
    (line,) = report_lines(report.load(EXAMPLE), 2.5 * 3600.0)
    assert ", 2.5 h old," in line


def test_the_bounds_are_said_to_be_about_their_centre_not_the_pose():
    """verify's 'guaranteed within 4.82 mm and 4.29 deg' read as the guarantee of the pose to use, which is 5.35 mm
    and 5.36 deg (pose.guaranteed)."""
    loaded = report.load(EXAMPLE)
    (line,) = report_lines(loaded, 60.0)
    assert (loaded.position_bound_m, loaded.rotation_bound_deg) == (0.0048154, 4.29023)  # bounds:, rounded up
    assert "guaranteed set within 4.82 mm and 4.30 deg of its centre (bounds.center)" in line


def test_the_guaranteed_figures_are_said_rounded_up():
    """A report's 1.2341 mm and 1.2341 deg were said as 'within 1.23 mm and 1.23 deg', less than it guarantees."""
    loaded = dataclasses.replace(report.load(EXAMPLE), position_bound_m=0.0012341, rotation_bound_deg=1.2341)
    (line,) = report_lines(loaded, 60.0)
    assert "guaranteed set within 1.24 mm and 1.24 deg of its centre (bounds.center)" in line
