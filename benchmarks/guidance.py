"""How many taps until the guaranteed bounds reach 2 mm and 1.5 deg (and a looser 3 mm and 3 deg): guided taps
against farthest-point and random taps, on the simulated cell.

Usage (from the repository root; the MATLAB logo needs ../shared beside the repository):
    .venv/bin/python benchmarks/guidance.py                          # 20 seeds, all fixtures and strategies
    .venv/bin/python benchmarks/guidance.py --seeds 3 --fixtures bracket --strategies guided --each-run
    .venv/bin/python benchmarks/guidance.py --first-seed 10 --seeds 10 --fixtures plate --each-run   # seeds 10-19

Each run puts a fixture at a random resting pose (seeded) in the simulated cell (1 mm bounded tap error,
3 mm ball, perfect tip calibration) and makes ``--max-taps`` tap attempts, running the live check (the
sampling screen's) after each; a run reaches a target at the first attempt after which the check says
"unique" within both of its bounds. Every tap is a real simulated one: the robot moves to the hover pose
above the chosen point (``workflow.hover``) and taps along its tool axis. The bounds are those the operator
sees a second or two after the tap: the check's set with the full solve's hull refinement (the sampling screen's
live pipeline, ``workflow.live_pipeline``),
computed when the quick bounds are within ``REFINE_WITHIN`` of a target not reached yet (refinement tightens
them by about 10 %; below that a target is out of reach, so skipping it saves time without changing a count)
and after ``PAPER_TAPS`` attempts. A run stops once it has reached both targets and made ``PAPER_TAPS``
attempts. A tap that touches nothing or the table (the operator would see it and undo it) costs its
attempt and adds no point.

Strategies choose the next point among the surface points the tool can reach (``workflow.advice``) and the
robot has a clear way to at the true pose (``workflow.hover``):
- random: a random one, on the true pose (the operator sees the fixture);
- farthest: the one farthest from the points tapped so far (farthest-point sampling), on the true pose;
- guided: farthest-point until the live check has an estimate, then the sampling screen's suggestion
  (``next_tap_and_plan``): the robot goes above it when its way is clear at every pose the bounds allow,
  else the operator guides the ball by hand to the nearest of those points (farthest-point again right
  after a suggestion that touched nothing or the table).
Every move goes through the simulated cell, which makes a protective stop if the ball would hit
something; the summary counts those and the live sets that missed the true pose (both must be 0).
"""

import argparse
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fixwizard.demo import demo_fixture, disc_fixture
from fixwizard.fixture import Fixture, load_fixture
from fixwizard.geometry.se3 import transform_points
from fixwizard.robot.base import NoContact, ProtectiveStop
from fixwizard.robot.sim import SimulatedCell
from fixwizard.solver.estimates import Bounds
from fixwizard.workflow.advice import TapAdvice, reachable_points
from fixwizard.workflow.hover import HoverPlan, hover_path, plan_hover
from fixwizard.workflow.live import LiveCheck
from fixwizard.workflow.live_pipeline import NextTap, live_pipeline

LOGO = Path(__file__).resolve().parents[2] / "shared" / "data" / "matlab-logo" / "meshes" / "matlab_logo.ply"
STRATEGIES = ("guided", "farthest", "random")
BALL_DIAMETER_M = 0.003
SAMPLE_BOUND_M = 0.001
TARGET_POSITION_M = 0.002
TARGET_ROTATION_RAD = np.radians(1.5)
EASY_POSITION_M = 0.003  # a second, looser target: the paper's students reached about this with 15 taps
EASY_ROTATION_RAD = np.radians(3.0)
TARGETS = ((TARGET_POSITION_M, TARGET_ROTATION_RAD), (EASY_POSITION_M, EASY_ROTATION_RAD))
REFINE_WITHIN = 1.3
BY_HAND_TRIES = 20  # reachable points nearest a suggestion the robot cannot go to, tried in turn by hand
PAPER_TAPS = 15  # the paper's students tapped 15 points; the bounds after as many attempts are printed


def fixtures() -> dict[str, callable]:
    found = {"bracket": demo_fixture, "plate": disc_fixture}
    if LOGO.is_file():
        found["logo"] = lambda: load_fixture(LOGO)
    return found


def _farthest(candidates: np.ndarray, tapped: list[np.ndarray], usable: np.ndarray, rng: np.random.Generator) -> int:
    """A random candidate at first, then the usable one farthest from the points tapped so far."""
    if not tapped:
        return int(rng.integers(len(candidates)))
    distances = np.linalg.norm(candidates[:, None, :] - np.array(tapped)[None], axis=2).min(axis=1)
    return int(np.argmax(np.where(usable, distances, -1.0)))


@dataclass
class Run:
    """One run: the guaranteed bounds (m, rad; inf while not unique) after each tap attempt, the protective stops
    of the moves above a point, and the live checks whose set missed the true pose (both must stay 0)."""

    trajectory: list[tuple[float, float]] = field(default_factory=list)
    protective_stops: int = 0
    coverage_misses: int = 0


def _tap_at(cell: SimulatedCell, plan: HoverPlan, run: Run) -> np.ndarray | None:
    """Move above the planned point and tap; the ball centre (base frame, m), or None if a move stopped or the tap
    touched nothing or the table (the operator sees that and undoes the tap)."""
    try:
        for pose in hover_path(plan, cell.truth.tcp_p_tip_m, cell.base_T_tcp()):
            cell.move_linear(pose)
        result = cell.tap()
    except ProtectiveStop:
        run.protective_stops += 1
        cell.unlock()
        return None
    except NoContact:
        return None
    ball = transform_points(result.base_T_tcp_contact, cell.truth.tcp_p_tip_m[None])[0]
    on_table = ball[2] < BALL_DIAMETER_M / 2 + 2 * SAMPLE_BOUND_M
    return None if on_table else ball


def _bounds(check: LiveCheck | None) -> tuple[float, float]:
    """The check's guaranteed position and rotation bounds (m, rad), inf while it is not unique."""
    if check is None or check.verdict != "unique":
        return np.inf, np.inf
    return check.solution.bounds.position_m, check.solution.bounds.rotation_rad


def _worth_refining(bounds: tuple[float, float], reached: list[bool], attempt: int) -> bool:
    """Whether refined bounds could reach a target the quick ``bounds`` have not, or are printed at this attempt."""
    near = any(not done and bounds[0] <= REFINE_WITHIN * position and bounds[1] <= REFINE_WITHIN * rotation
               for done, (position, rotation) in zip(reached, TARGETS, strict=True))
    return np.isfinite(bounds[0]) and (near or attempt == PAPER_TAPS)


def _live(fixture: Fixture, taps: list[np.ndarray], previous: LiveCheck | None, attempt: int, advise: bool,
          reached: list[bool]) -> tuple[LiveCheck | None, NextTap | None]:
    """The live pipeline after a tap: the quick check (after the first look), the next tap (with ``advise``), and the
    refined check (and the next tap again) only when ``_worth_refining``."""
    stages = live_pipeline(fixture, np.array(taps), BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=previous,
                           seed=attempt + 1, advise=advise)
    check = next(stages, None)
    if check is not None and check.rough and check.verdict != "inconsistent":
        check = next(stages)  # the quick check of the same set
    if check is None or check.estimate_base_T_cad is None:
        return check, None
    next_tap = next(stages) if advise else None
    if _worth_refining(_bounds(check), reached, attempt):
        check = next(stages)
        next_tap = next(stages, next_tap)
    return check, next_tap


def run(fixture: Fixture, seed: int, strategy: str, max_taps: int) -> Run:
    """Tap attempts up to ``max_taps``, or until both targets are reached after at least ``PAPER_TAPS``."""
    cell = SimulatedCell.with_fixture(fixture, seed=seed, ball_diameter_m=BALL_DIAMETER_M,
                                      fk_error_bound_m=SAMPLE_BOUND_M)
    cell.connect()
    rng = np.random.default_rng(seed)
    cad_points, base_normals = reachable_points(fixture, cell.truth.base_T_cad, seed)
    base_points = transform_points(cell.truth.base_T_cad, cad_points)
    seen = [Bounds(cell.truth.base_T_cad, 0.0, 0.0, 0.0)]  # the operator sees the fixture where it is
    usable = np.ones(len(base_points), bool)
    taps: list[np.ndarray] = []
    tapped_points: list[np.ndarray] = []
    live = next_tap = None
    bounds = (np.inf, np.inf)
    result = Run()
    reached = [False] * len(TARGETS)
    missed = False
    for attempt in range(1, max_taps + 1):
        plan, by_hand = None, []
        if next_tap is not None and next_tap.advice is not None and not missed:
            advice, plan = next_tap.advice, next_tap.plan
            if plan is None:  # the operator guides the ball to the nearest point they can
                by_hand = list(np.argsort(np.linalg.norm(base_points - advice.base_p_point_m, axis=1))[:BY_HAND_TRIES])
        while plan is None:
            if by_hand:
                index = int(by_hand.pop(0))
            elif strategy == "random":
                index = int(rng.integers(len(base_points)))
            else:
                index = _farthest(base_points, tapped_points, usable, rng)
            plan = None if not usable[index] else plan_hover(
                TapAdvice(base_points[index], cad_points[index], base_normals[index], 0.0), fixture, seen,
                BALL_DIAMETER_M / 2)
            usable[index] = plan is not None  # nobody would pick a point the robot cannot get to
        ball = _tap_at(cell, plan, result)
        missed = ball is None  # the estimate was off: the next tap is chosen by the fallback rule
        if ball is not None:
            taps.append(ball)
            tapped_points.append(plan.advice.base_p_point_m)
            live, next_tap = _live(fixture, taps, live, attempt, strategy == "guided", reached)
            bounds = _bounds(live)
            if live is not None and not live.solution.contains(cell.truth.base_T_cad):
                result.coverage_misses += 1
        result.trajectory.append(bounds)
        reached = [done or (bounds[0] <= position and bounds[1] <= rotation)
                   for done, (position, rotation) in zip(reached, TARGETS, strict=True)]
        if all(reached) and attempt >= PAPER_TAPS:
            break
    return result


def taps_to_reach(trajectory: list[tuple[float, float]], position_m: float, rotation_rad: float) -> int | None:
    """The first tap attempt after which both bounds are within the targets (m, rad); None if none is."""
    for attempt, (position, rotation) in enumerate(trajectory, start=1):
        if position <= position_m and rotation <= rotation_rad:
            return attempt
    return None


def _summary(counts: list[int | None], max_taps: int) -> str:
    values = sorted(count if count is not None else max_taps + 1 for count in counts)
    quartiles = statistics.quantiles(values, n=4, method="inclusive") if len(values) > 1 else [values[0]] * 3
    reached = sum(count is not None for count in counts)
    return (f"median {statistics.median(values):4.1f}  quartiles {quartiles[0]:4.1f}-{quartiles[2]:4.1f}  "
            f"range {values[0]}-{values[-1]}  reached {reached}/{len(counts)}")


def _run_line(one: Run) -> str:
    """One run's attempts to each target ("-" when not reached), its bounds after ``PAPER_TAPS``, and its
    protective stops and coverage misses."""
    counts = [taps_to_reach(one.trajectory, position_m, rotation_rad) for position_m, rotation_rad in TARGETS]
    position_m, rotation_rad = one.trajectory[PAPER_TAPS - 1]
    return (" ".join(f"{position * 1e3:.0f}mm/{np.degrees(rotation):.1f}deg {'-' if count is None else count}"
                     for count, (position, rotation) in zip(counts, TARGETS, strict=True))
            + f"  after {PAPER_TAPS}: {position_m * 1e3:.2f} mm {np.degrees(rotation_rad):.2f} deg"
            + f"  stops {one.protective_stops} misses {one.coverage_misses}")


def _quartiles(values: np.ndarray, spec: str) -> str:
    low, high = np.quantile(values, [0.25, 0.75], method="closest_observation")  # no inf - inf
    return f"{low:{spec}}-{high:{spec}}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0,
                        help="seeds run from this one on (to split a benchmark over processes)")
    parser.add_argument("--fixtures", nargs="*", default=None, help="bracket, plate, logo (default: all found)")
    parser.add_argument("--strategies", nargs="*", default=list(STRATEGIES))
    parser.add_argument("--max-taps", type=int, default=30)
    parser.add_argument("--each-run", action="store_true", help="also print each run's figures as it ends")
    args = parser.parse_args()
    if args.max_taps < PAPER_TAPS:
        parser.error(f"--max-taps must be at least {PAPER_TAPS}")
    available = fixtures()
    names = args.fixtures or list(available)
    if "logo" in names and "logo" not in available:
        sys.exit(f"the MATLAB logo mesh is not at {LOGO}")
    print(f"tap attempts until the guaranteed bounds reach each target ({args.seeds} seeds; a run that does "
          f"not reach it within {args.max_taps} counts as {args.max_taps + 1})")
    for name in names:
        fixture = available[name]()
        for strategy in args.strategies:
            started = time.perf_counter()
            runs = []
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                runs.append(run(fixture, seed, strategy, args.max_taps))
                if args.each_run:
                    print(f"{name:8} {strategy:9} seed {seed:2}: {_run_line(runs[-1])}", flush=True)
            trajectories = [one.trajectory for one in runs]
            for position_m, rotation_rad in TARGETS:
                counts = [taps_to_reach(trajectory, position_m, rotation_rad) for trajectory in trajectories]
                print(f"{name:8} {strategy:9} {position_m * 1e3:.0f} mm {np.degrees(rotation_rad):.1f} deg: "
                      f"{_summary(counts, args.max_taps)}", flush=True)
            after = np.array([trajectory[PAPER_TAPS - 1] for trajectory in trajectories])
            print(f"{name:8} {strategy:9} after {PAPER_TAPS}: median {np.median(after[:, 0]) * 1e3:.1f} mm "
                  f"{np.degrees(np.median(after[:, 1])):.2f} deg, quartiles "
                  f"{_quartiles(after[:, 0] * 1e3, '.1f')} mm {_quartiles(np.degrees(after[:, 1]), '.2f')} deg "
                  f"({time.perf_counter() - started:.0f} s)", flush=True)
            print(f"{name:8} {strategy:9} protective stops {sum(one.protective_stops for one in runs)}, live sets "
                  f"that missed the true pose {sum(one.coverage_misses for one in runs)}", flush=True)


if __name__ == "__main__":
    main()
