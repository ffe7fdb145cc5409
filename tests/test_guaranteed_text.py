"""The screens' guaranteed figures are rounded up, as the report's are: a bound shown smaller than the solver's would
leave the true pose outside what the screen promises (0.449 mm said as "0.4 mm")."""

from types import SimpleNamespace

import numpy as np

from fixwizard.solver.estimates import Bounds
from fixwizard.solver.solve import Mode, SearchStats, Solution
from fixwizard.tui.results.text import bounds_text as results_bounds_text
from fixwizard.tui.results.text import mode_line
from fixwizard.tui.sampling.text import bounds_text as live_bounds_text
from fixwizard.workflow.details import details_lines
from fixwizard.workflow.live import LiveView
from fixwizard.workflow.missable_move import MissableMove
from fixwizard.workflow.verify import _unique_consistent_line

# each figure just above a rounding step, where rounding to the nearest goes down
BOUNDS = Bounds(np.eye(4), position_m=0.0061401, rotation_rad=np.radians(6.3401), max_point_displacement_m=0.000449)


def test_the_live_line_rounds_its_guaranteed_figures_up():
    view = LiveView(9, "unique", True, BOUNDS, (), None, None, None, None, (), np.zeros((9, 3)))
    assert live_bounds_text(view) == "origin within 6.2 mm, rotation within 6.4 deg, any point within 0.5 mm"


def test_the_results_round_their_guaranteed_figures_up():
    assert results_bounds_text(BOUNDS) == "CAD origin within 6.15 mm, rotation within 6.35 deg"
    assert mode_line(1, Mode(0.6, np.eye(4), BOUNDS, 8)).endswith("; within 6.2 mm, 6.4 deg")


def test_a_figure_already_on_a_step_stays_as_it_is():
    on_step = Bounds(np.eye(4), position_m=0.0062, rotation_rad=np.radians(6.4), max_point_displacement_m=0.0005)
    view = LiveView(9, "unique", True, on_step, (), None, None, None, None, (), np.zeros((9, 3)))
    assert live_bounds_text(view) == "origin within 6.2 mm, rotation within 6.4 deg, any point within 0.5 mm"


def test_the_details_view_rounds_the_solvers_guaranteed_figures_up():
    solution = Solution("unique", np.eye(4), BOUNDS, [], [Mode(1.0, np.eye(4), BOUNDS, 8)], [], None,
                        SearchStats(8, 3, 2, 1.0, 1e6), None, None, np.eye(4))  # type: ignore[arg-type]
    lines = details_lines(solution)
    assert "Mode 1: probability 100.0%, within 6.15 mm, 6.35 deg" in lines
    assert "Bounds: position 6.141 mm, rotation 6.341 deg, any point 0.449 mm." in lines


def test_verify_says_both_of_its_figures_rounded_up_so_keep_using_never_reads_as_a_larger_figure():
    """3.2201 mm seen against 3.2210 mm guaranteed: to the nearest that read "within 3.22 mm ... no more than the
    3.22 mm" at best, and rounding only the first up "within 3.23 mm ... no more than the 3.22 mm"."""
    missable = MissableMove(0.0032201 - 0.05 * 1e-9, 1e-9, np.array([1.0, 0, 0, 0, 0, 0]), np.zeros(3), 0.05)
    guarantee = SimpleNamespace(max_point_displacement_m=0.003221)
    result = SimpleNamespace(missable=missable, seeing_point=SimpleNamespace(where="there"),
                             report=SimpleNamespace(pose_to_use=lambda: (np.eye(4), guarantee)))
    line = _unique_consistent_line(result, "7 taps")  # type: ignore[arg-type]
    assert "within 3.23 mm of the report's pose, no more than the 3.23 mm the report guarantees. Keep using" in line
