"""What the sampling screen shows after each tap: a quick solve at a small cell budget and each tap's distance
from the fixture surface under the pose it estimates.

The quick solve is the real solver with fewer likelihood samples, so what it says is guaranteed: an empty
set means the taps are inconsistent. After each new tap it goes on from the previous check's set. ``first_look``
is the quick search with bounds straight from its cells and a rough estimate, shown first (within about half a
second once the pose is pinned down); ``quick_check`` of the same taps then takes its set as it is and refines
the hull lightly; ``refine_check`` spends the full solve's hull budget on the same set, for the bounds the report
will give. The verdict is the solver's status: while the taps do not pin the pose down (``undetermined``) no
estimate is offered, but the guaranteed bounds are.
"""

import threading
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from fixwizard.fixture import Fixture
from fixwizard.solver.estimates import Bounds
from fixwizard.solver.search import Descent, SearchProgress
from fixwizard.solver.solve import HULL_SHARE, MIN_TAPS, Mode, Solution, Stage, solve
from fixwizard.solver.verdict import Status
from fixwizard.workflow.ball_check import BallMismatch, ball_mismatch
from fixwizard.workflow.details import details_lines

LIVE_MAX_CELLS = 1e7  # the full solve's budget: the live bounds are as guaranteed and nearly as tight
LIVE_HULL_CELLS = 2.5e5  # less hull refinement than the full solve (2e5 on all bounds), for an update in ~2 s
REFINED_HULL_CELLS = HULL_SHARE * LIVE_MAX_CELLS  # the full solve's hull refinement: its bounds
LIVE_MAX_SAMPLES = 1000
FIRST_LOOK_SAMPLES = 200  # enough for a rough estimate and the taps' distances under it


def tap_surface_distances_m(fixture: Fixture, base_p_taps: np.ndarray, ball_diameter_m: float,
                            base_T_cad: np.ndarray) -> np.ndarray:
    """Distance (N,) in m of each ball centre (base frame) from where it would touch the surface with the
    fixture at ``base_T_cad``: signed distance minus ball radius (positive: the ball stops short of the
    surface; negative: it would be inside; unsigned for an open mesh)."""
    return fixture.signed_distance_at_m(base_T_cad, base_p_taps) - ball_diameter_m / 2.0


@dataclass(frozen=True)
class LiveCheck:
    """A quick solve of the first ``tap_count`` taps and what it allows one to say."""

    solution: Solution
    tap_count: int
    refined: bool = False  # the bounds come from the full solve's hull refinement
    rough: bool = False  # the first look: bounds straight from the search's cells, a rough estimate
    # a first look's: the earlier check whose finest level it filtered alone; later checks go on from that search
    filtered_from: "LiveCheck | None" = None

    @property
    def verdict(self) -> Status:
        return self.solution.status

    @property
    def estimate_base_T_cad(self) -> np.ndarray | None:
        """The most probable pose when the set is narrow enough for it to mean something, else None."""
        return self.solution.base_T_cad if self.verdict in ("unique", "ambiguous") else None


@dataclass(frozen=True)
class LiveView:
    """What the sampling screen shows of a ``LiveCheck``, small enough to pass between processes: the verdict, the
    guaranteed bounds (None when inconsistent), the modes, the most likely cause when inconsistent (or, when
    undetermined, that no pose was found to explain every tap, if so), the estimate
    (as ``LiveCheck.estimate_base_T_cad``), each tap's distance (m, ``tap_surface_distances_m``) under it, a wrong
    ball diameter the taps point to, the solver's own figures (``workflow.details``) and the taps it checked (N, 3,
    base frame, m)."""

    tap_count: int
    verdict: Status
    refined: bool
    bounds: Bounds | None
    modes: tuple[Mode, ...]
    cause: str | None
    estimate_base_T_cad: np.ndarray | None
    distances_m: np.ndarray | None
    ball_mismatch: BallMismatch | None
    details: tuple[str, ...]
    base_p_taps: np.ndarray

    def is_of_first(self, base_p_taps: np.ndarray) -> bool:
        """Whether it checked the first of these taps (N, 3, base frame, m), or all of them: what it says holds for
        them. Not after an undo or a dropped tap: a check that counted a tap now gone may be narrower than the taps
        left allow."""
        count = len(self.base_p_taps)
        return len(base_p_taps) >= count and np.array_equal(base_p_taps[:count], self.base_p_taps)

    @staticmethod
    def of(check: LiveCheck, fixture: Fixture) -> "LiveView":
        solution, estimate = check.solution, check.estimate_base_T_cad
        diagnosis = solution.diagnosis
        unexplained = [warning.message for warning in solution.warnings if warning.code == "unexplained"]
        cause = diagnosis.causes[0].message if diagnosis is not None and diagnosis.causes else None
        return LiveView(check.tap_count, check.verdict, check.refined, solution.bounds, tuple(solution.modes),
                        unexplained[0] if unexplained else cause,
                        estimate, None if estimate is None else tap_surface_distances_m(
                            fixture, solution.problem.base_p_taps, 2.0 * solution.problem.ball_radius_m, estimate),
                        ball_mismatch(solution), tuple(details_lines(solution)), solution.problem.base_p_taps)


def quick_check(fixture: Fixture, base_p_taps: np.ndarray, ball_diameter_m: float, sample_bound_m: float,
                cancel: threading.Event | None = None, max_cells: float = LIVE_MAX_CELLS,
                previous: LiveCheck | None = None, progress: Callable[[SearchProgress], None] | None = None,
                stage: Stage | None = None, hull_cells: float = LIVE_HULL_CELLS,
                max_samples: int = LIVE_MAX_SAMPLES, descent: Descent = "quick") -> LiveCheck | None:
    """A quick solve of the taps (None with fewer than the solver's minimum); raises ``SearchCancelled``
    when ``cancel`` is set meanwhile. With the ``previous`` check of fewer of the same taps, the solve goes
    on from its set (a new tap can only remove poses) instead of starting over; of the same taps (a first look),
    it goes on down from that set. The search is a quick one (coarse levels only while the taps prune hard: a few
    taps are answered in seconds). ``progress`` and ``stage``: as for ``solve``; ``hull_cells``: its hull
    refinement's budget; ``max_samples``: the likelihood samples of the estimate; ``descent``: as for ``solve``."""
    base_p_taps = np.asarray(base_p_taps, float).reshape(-1, 3)
    if len(base_p_taps) < MIN_TAPS:
        return None
    previous = _searched(previous)
    solution = solve(fixture, base_p_taps, ball_diameter_m, sample_bound_m, max_cells=max_cells, cancel=cancel,
                     max_samples=max_samples, previous=None if previous is None else previous.solution,
                     hull_cells=hull_cells, descent=descent, progress=progress, stage=stage)
    return LiveCheck(solution, len(base_p_taps))


def first_look(fixture: Fixture, base_p_taps: np.ndarray, ball_diameter_m: float, sample_bound_m: float,
               cancel: threading.Event | None = None, previous: LiveCheck | None = None,
               progress: Callable[[SearchProgress], None] | None = None,
               stage: Stage | None = None) -> LiveCheck | None:
    """``quick_check`` that goes no deeper than the ``previous`` check's search (the new taps filter its finest
    level; from scratch, as deep as a quick check), without hull refinement and with a rough estimate
    (``FIRST_LOOK_SAMPLES``): the verdict and bounds straight from the cells (guaranteed, looser), shown first.
    Checks after it go on from the search it filtered (``LiveCheck.filtered_from``)."""
    searched = _searched(previous)
    check = quick_check(fixture, base_p_taps, ball_diameter_m, sample_bound_m, cancel, previous=searched,
                        progress=progress, stage=stage, hull_cells=0.0, max_samples=FIRST_LOOK_SAMPLES,
                        descent="no_deeper")
    return None if check is None else replace(check, rough=True, filtered_from=searched)


def _searched(check: LiveCheck | None) -> LiveCheck | None:
    """The check whose search tree a new check goes on from: a first look's tree is that of the check it filtered
    at the finest level only (its coarser levels were not filtered against its new taps)."""
    return check.filtered_from if check is not None and check.filtered_from is not None else check


def refine_check(fixture: Fixture, check: LiveCheck, cancel: threading.Event | None = None,
                 stage: Stage | None = None) -> LiveCheck:
    """The same check with the full solve's hull refinement of its set: bounds as tight as the report's
    (about a second more). Raises ``SearchCancelled`` when ``cancel`` is set meanwhile; ``stage``: as for
    ``solve``."""
    problem = check.solution.problem
    solution = solve(fixture, problem.base_p_taps, 2.0 * problem.ball_radius_m, problem.sample_bound_m,
                     max_cells=check.solution.stats.max_cells, cancel=cancel, max_samples=LIVE_MAX_SAMPLES,
                     previous=check.solution, hull_cells=REFINED_HULL_CELLS, descent="no_deeper", stage=stage)
    return LiveCheck(solution, check.tap_count, refined=True)
