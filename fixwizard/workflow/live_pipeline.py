"""The live check after a tap as one pipeline, stage by stage: the first look (bounds straight from the search),
the quick check of the same set, then (once it offers an estimate) where to tap next with the robot's safe way
above it, the refined check, and the way above again when the refined bounds make room for one the quick bounds
did not. The sampling screen's solver process, the tests and
``benchmarks/guidance.py`` all run it; a consumer may stop early (the generator does no more work than asked for).
"""

import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from fixwizard.fixture import Fixture
from fixwizard.solver.search import SearchProgress
from fixwizard.solver.solve import Stage
from fixwizard.workflow.advice import TapAdvice
from fixwizard.workflow.hover import HoverPlan, next_tap_and_plan, plan_hover
from fixwizard.workflow.live import LiveCheck, first_look, quick_check, refine_check


@dataclass(frozen=True)
class NextTap:
    """Where to tap next (None: no reachable point helps) and the robot's safe way above it (None: the operator
    guides the ball)."""

    advice: TapAdvice | None
    plan: HoverPlan | None


LiveStage = LiveCheck | NextTap


def live_pipeline(fixture: Fixture, base_p_taps: np.ndarray, ball_diameter_m: float, sample_bound_m: float,
                  previous: LiveCheck | None = None, cancel: threading.Event | None = None,
                  progress: Callable[[SearchProgress], None] | None = None, stage: Stage | None = None,
                  seed: int = 0, advise: bool = True) -> Iterator[LiveStage]:
    """Yield the first look and the quick ``LiveCheck`` of the taps (N, 3, base frame, m; nothing with fewer than
    the solver's minimum; only the first look when no pose fits); when the quick check offers an estimate, the
    ``NextTap`` (only with ``advise``), the refined ``LiveCheck`` and, when the refinement makes a way above the
    advised point safe, that ``NextTap`` again. Lengths in m; ``previous``: the
    last check of fewer of the same taps (see ``quick_check``); ``seed``: of the advice's candidate points.
    Raises ``SearchCancelled`` when ``cancel`` is set meanwhile."""
    first = first_look(fixture, base_p_taps, ball_diameter_m, sample_bound_m, cancel, previous=previous,
                       progress=progress, stage=stage)
    if first is None:
        return
    yield first
    if first.verdict == "inconsistent":
        return  # nothing to refine: the first look has said why
    check = quick_check(fixture, base_p_taps, ball_diameter_m, sample_bound_m, cancel, previous=first,
                        progress=progress, stage=stage)
    assert check is not None  # as many taps as the first look
    yield check
    if check.estimate_base_T_cad is None:
        return
    ball_radius_m = ball_diameter_m / 2.0
    advice = plan = None
    if advise:
        advice, plan = next_tap_and_plan(fixture, check.solution, sample_bound_m, ball_radius_m, seed)
        yield NextTap(advice, plan)
    refined = refine_check(fixture, check, cancel, stage)
    yield refined
    if advice is not None and plan is None:
        plan = plan_hover(advice, fixture, [mode.bounds for mode in refined.solution.modes], ball_radius_m)
        if plan is not None:
            yield NextTap(advice, plan)
