"""The solver's entry point: validate inputs, search, and summarise the guaranteed set.

``solve`` is plain Python: a fixture, taps in the base frame (m), the ball diameter and
the sample error bound in metres; it returns a ``Solution`` with the pose of the CAD frame.
"""

import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.errors import InputError
from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import invert, rotation_angle_rad
from fixwizard.solver.cells import CellSet
from fixwizard.solver.diagnose import Diagnosis, SuspectTap, diagnose
from fixwizard.solver.estimates import (
    Bounds,
    Interval,
    Samples,
    bound_centre,
    bounds_from_figures,
    cell_bound_figures,
    effective_sample_size,
    expected_pose,
    intervals,
    mixture,
    rotation_center,
    sample_cells,
)
from fixwizard.solver.mode_mass import ModeLikelihood, mode_shares
from fixwizard.solver.modes import mode_labels
from fixwizard.solver.reach import certified_start
from fixwizard.solver.refine import refined_largest_figures
from fixwizard.solver.resources import available_memory_bytes, largest_cell_budget, search_peak_bytes
from fixwizard.solver.search import (
    Descent,
    SearchProblem,
    SearchProgress,
    SearchTree,
    Survivors,
    add_taps,
    descend,
    search,
    worth_extending,
)
from fixwizard.solver.verdict import (
    MIN_INTERVAL_SAMPLES,
    Status,
    is_pinned,
    openness,
    probability_text,
    status_of,
    undetermined_message,
)
from fixwizard.units import MAX_REACH_M

DEFAULT_MAX_CELLS = 1e7
# Refining the hull of the set (the cells that decide the bounds) may evaluate HULL_SHARE of the cell budget: 1/10
# in rounds on all bounds, 1/40 more on the point displacement alone (refine.DISPLACEMENT_SHARE of it).
HULL_SHARE = 1 / 8
MIN_MAX_CELLS = 72 * 8
# The searches of a diagnosis only tell an empty set from a non-empty one; a smaller budget keeps it within seconds.
DIAGNOSIS_MAX_CELLS = 1e6
DEFAULT_MAX_SAMPLES = 40_000
MIN_TAPS = 3
MAX_TAPS = 1000  # more is a point cloud, not taps: this search keeps an interval per cell and tap
MAX_SAMPLE_BOUND_M = 0.02  # larger bounds are a unit mistake (1 for 1 mm), not a robot
# No robot taps that accurately (arms repeat to 0.03-0.1 mm, a tip calibration proposes 0.2 mm at least): a smaller
# bound is a unit mistake (1e-6 for 1 mm, 1um); it also asks for cells and likelihoods finer than the report's 0.1 um.
MIN_SAMPLE_BOUND_M = 1e-5
MAX_BALL_DIAMETER_M = 0.05


@dataclass(frozen=True)
class SolveWarning:
    """A warning for the operator: a stable ``code`` and a plain-words ``message``."""

    code: str
    message: str


@dataclass(frozen=True)
class SolveStage:
    """A phase of a solve after its search, for progress displays: grouping the set into modes, refining a mode's
    bounds, sampling its likelihood, weighing the modes, the intervals, or the diagnosis of an empty set. ``mode``
    of ``modes`` (1-based) for the per-mode phases, else 0; ``round``: the bounds' refinement round (1-based; 0
    before the first)."""

    name: Literal["modes", "bounds", "samples", "masses", "intervals", "diagnosis"]
    mode: int = 0
    modes: int = 0
    round: int = 0


Stage = Callable[[SolveStage], None]


@dataclass(frozen=True)
class Mode:
    """One connected group of possible poses: its probability mass, expected CAD pose and bounds."""

    probability: float
    base_T_cad: np.ndarray
    bounds: Bounds
    cell_count: int


@dataclass(frozen=True)
class SearchStats:
    cells: int
    rotation_level: int
    position_level: int
    elapsed_s: float
    max_cells: float


@dataclass
class Solution:
    """Result of ``solve``. For ``inconsistent`` the pose, bounds and intervals are None/empty. ``intervals`` is
    also empty when the likelihood samples are too few to give one (``effective_samples`` below
    ``verdict.MIN_INTERVAL_SAMPLES``)."""

    status: Status
    base_T_cad: np.ndarray | None
    bounds: Bounds | None
    intervals: list[Interval]
    modes: list[Mode]
    warnings: list[SolveWarning]
    suspect_tap: SuspectTap | None
    stats: SearchStats
    tree: SearchTree | None = field(repr=False)
    problem: SearchProblem = field(repr=False)
    fix_T_cad: np.ndarray = field(repr=False)
    effective_samples: float = 0.0
    diagnosis: Diagnosis | None = None
    # Per mode (in ``modes``' order): whether a pose explaining every tap within the sample bound was found in it
    # (``_explained``); empty where that was not looked for (undetermined, inconsistent).
    explained: tuple[bool, ...] = ()

    @property
    def cells(self) -> CellSet | None:
        """The surviving cells (None when the set is empty)."""
        return None if self.tree is None else self.tree.final.cells

    def extends_to(self, problem: SearchProblem) -> bool:
        """Whether ``problem`` is this solution's with the same or more taps: same mesh, ball and bound, earlier taps
        kept."""
        known = self.problem.base_p_taps
        return (self.tree is not None and problem.oracle is self.problem.oracle
                and problem.ball_radius_m == self.problem.ball_radius_m
                and problem.sample_bound_m == self.problem.sample_bound_m
                and len(problem.base_p_taps) >= len(known)
                and np.array_equal(problem.base_p_taps[:len(known)], known))

    def contains(self, base_T_cad: np.ndarray) -> bool:
        """Whether a CAD-frame pose lies in the guaranteed set."""
        return self.cells is not None and self.cells.contains(base_T_cad @ invert(self.fix_T_cad))


def check_reach(base_p_taps: np.ndarray) -> None:
    """InputError naming the first tap (N, 3, m, finite) beyond ``MAX_REACH_M`` of the robot base: millimetres
    read as metres."""
    largest = np.max(np.abs(base_p_taps), axis=1, keepdims=True)  # scaled first: 1e300 m squared overflows
    distances = largest[:, 0] * np.linalg.norm(base_p_taps / np.where(largest > 0.0, largest, 1.0), axis=1)
    far = np.flatnonzero(distances > MAX_REACH_M)
    if len(far):
        raise InputError(f"tap {far[0] + 1} lies {distances[far[0]]:.3g} m from the robot base, "
                         "beyond any robot arm's reach: the points must be in metres (millimetres read as metres?)")


def check_sample_bound(sample_bound_m: float) -> None:
    """InputError with the fix for a sample bound (m) that is no robot tap's: not a positive number, or outside
    ``MIN_SAMPLE_BOUND_M`` to ``MAX_SAMPLE_BOUND_M`` (a unit mistake)."""
    if not np.isfinite(sample_bound_m) or sample_bound_m <= 0:
        raise InputError(f"the sample bound must be a positive length, not {sample_bound_m} m; take it from the "
                         "tip calibration (typically 0.5-2 mm)")
    if sample_bound_m > MAX_SAMPLE_BOUND_M:
        raise InputError(f"a sample bound of {sample_bound_m * 1e3:g} mm is implausible for a robot tap; give it "
                         "with its unit, e.g. --sample-bound 1mm")
    if sample_bound_m < MIN_SAMPLE_BOUND_M:
        raise InputError(f"a sample bound of {sample_bound_m * 1e3:g} mm is implausible for a robot tap: no robot "
                         f"taps to within {MIN_SAMPLE_BOUND_M * 1e3:g} mm (arms repeat to 0.03-0.1 mm); give the "
                         "tip calibration's bound with its unit, e.g. --sample-bound 1mm")


def validate_inputs(base_p_taps: np.ndarray, ball_diameter_m: float, sample_bound_m: float, sigma_m: float,
                    max_cells: float) -> None:
    """Raise ``InputError`` with the fix for taps (N, 3, m), lengths (m) or a cell budget a solve cannot use."""
    if base_p_taps.ndim != 2 or base_p_taps.shape[1] != 3:
        raise InputError("taps must be a list of [x, y, z] points in metres")
    if len(base_p_taps) < MIN_TAPS:
        count = f"{len(base_p_taps)} tap is" if len(base_p_taps) == 1 else f"{len(base_p_taps)} taps are"
        raise InputError(f"{count} not enough: at least {MIN_TAPS} are needed to fix a pose, "
                         "and 10-20 taps spread over several faces give tight bounds")
    if len(base_p_taps) > MAX_TAPS:
        raise InputError(f"{len(base_p_taps)} taps are far more than a calibration needs (10-20 spread over the "
                         f"fixture; at most {MAX_TAPS}): is this a point cloud? Give the tapped ball centres only")
    bad = np.flatnonzero(~np.all(np.isfinite(base_p_taps), axis=1))
    if len(bad):
        raise InputError(f"tap {bad[0] + 1} has a coordinate that is not a finite number; fix or remove it")
    check_reach(base_p_taps)
    check_sample_bound(sample_bound_m)
    if not np.isfinite(ball_diameter_m) or ball_diameter_m < 0:
        raise InputError(f"the ball diameter must be zero or positive, not {ball_diameter_m} m")
    if ball_diameter_m > MAX_BALL_DIAMETER_M:
        raise InputError(f"a {ball_diameter_m * 1e3:g} mm tip ball is implausible; give the diameter with its unit, "
                         "e.g. --ball-diameter 3mm")
    if not np.isfinite(sigma_m) or sigma_m <= 0:
        raise InputError(f"sigma must be a positive length, not {sigma_m} m")
    if sigma_m > sample_bound_m:
        raise InputError(f"a sigma of {sigma_m * 1e3:g} mm is larger than the sample bound of "
                         f"{sample_bound_m * 1e3:g} mm: the taps' errors lie within their bound, so their standard "
                         "deviation does too (by default it is a third of the bound); give it with its unit, e.g. "
                         f"--sigma {sample_bound_m * 1e3 / 3:.2g}mm")
    if not max_cells >= MIN_MAX_CELLS or not np.isfinite(max_cells):
        raise InputError(f"the cell budget must be a number of at least {MIN_MAX_CELLS}, not {max_cells}")


def _mode_separation(modes: list[Mode]) -> tuple[float, float]:
    """Largest CAD-origin distance (m) and rotation angle (rad) between two modes' poses."""
    distance = angle = 0.0
    for i, first in enumerate(modes):
        for second in modes[i + 1:]:
            distance = max(distance, float(np.linalg.norm(first.base_T_cad[:3, 3] - second.base_T_cad[:3, 3])))
            relative = first.base_T_cad[:3, :3].T @ second.base_T_cad[:3, :3]
            angle = max(angle, float(rotation_angle_rad(relative)))
    return distance, angle


def _repeat_warnings(base_p_taps: np.ndarray) -> list[SolveWarning]:
    """A warning naming the taps (N, 3) that repeat an earlier tap exactly (a row pasted twice), if any."""
    _, first, inverse = np.unique(base_p_taps, axis=0, return_index=True, return_inverse=True)
    earlier = first[inverse.ravel()]
    repeats = np.flatnonzero(earlier != np.arange(len(base_p_taps)))
    if not len(repeats):
        return []
    named = ", ".join(f"tap {index + 1} is tap {earlier[index] + 1}" for index in repeats[:3])
    more = ", ..." if len(repeats) > 3 else ""
    count = f"{len(repeats)} taps repeat an earlier one" if len(repeats) > 1 else "A tap repeats an earlier one"
    return [SolveWarning("repeated_taps", f"{count} exactly ({named}{more}): the 95/99 % intervals count each repeat "
                         "as new evidence, so they come out narrower than the taps justify (the guaranteed bounds "
                         "hold). Remove the repeated rows from the points file.")]


def _explained(problem: SearchProblem, mode: Mode, fix_T_cad: np.ndarray) -> bool:
    """Whether a pose was found that explains every tap within the sample bound, from the mode's expected pose
    (itself, its least-squares fit, a feasible pose near that, its Chebyshev fit). Not found: the mode's cells may
    hold no pose at all, which only finer cells could prove."""
    start = [mode.base_T_cad @ invert(fix_T_cad)]
    return certified_start(problem, start, mode.bounds.max_point_displacement_m) is not None


def _unexplained_warnings(problem: SearchProblem) -> list[SolveWarning]:
    """The warning when no mode is explained (``_explained``): the set the cells hold may then be empty, and its
    bounds rest on a sample bound the taps do not keep."""
    return [SolveWarning("unexplained", f"No pose was found that explains every tap within the "
                         f"{problem.sample_bound_m * 1e3:.3g} mm sample bound, so the pose found is not one to use: "
                         "the taps may fit no pose at this bound (a search with a larger cell budget would then say "
                         "inconsistent). Check the sample bound (the tip calibration's) and the ball diameter.")]


def _ambiguous_warning(modes: list[Mode], explained: list[bool]) -> SolveWarning:
    """Several modes, each pinned down; whether a pose was found that explains the taps in each (``explained``, per
    mode) is said, since a mode with none may be empty, which only finer cells could prove."""
    distance, angle = _mode_separation(modes)
    confirmed = sum(explained)
    if confirmed == len(modes):
        said = f"{len(modes)} distinct poses explain the taps"
    else:
        unconfirmed = sum(mode.probability for mode, found in zip(modes, explained, strict=True) if not found)
        others = "the other" if len(modes) - confirmed == 1 else f"the other {len(modes) - confirmed}"
        said = (f"{len(modes)} distinct poses may explain the taps: a pose explaining every tap within the sample "
                f"bound was found for {confirmed} of them, and {others} ({probability_text(unconfirmed)} probable) "
                "could not be ruled out at this cell budget")
    return SolveWarning(
        "ambiguous",
        f"{said}; they lie up to {distance * 1e3:.1f} mm and {np.degrees(angle):.1f} deg apart (a symmetric "
        f"fixture, a repeated feature or taps on too few features). The pose shown is the most probable "
        f"({probability_text(modes[0].probability)}); tap features that tell the poses apart.")


def _inconsistent_warnings(diagnosis: Diagnosis) -> list[SolveWarning]:
    """The inconsistent verdict, then each cause the diagnosis found, most likely first."""
    return [SolveWarning("inconsistent", "No pose of the fixture explains all taps. Most likely cause first:"),
            *(SolveWarning(cause.code, cause.message) for cause in diagnosis.causes)]


@dataclass(frozen=True)
class _Likelihood:
    """What the likelihood samples need: the fixture's oracle and size, sigma (m) and the sample budget."""

    fixture: Fixture
    sigma_m: float
    max_samples: int
    rng: np.random.Generator


def _modes(problem: SearchProblem, survivors: Survivors, likelihood: _Likelihood, fix_p_origin: np.ndarray,
           fix_T_cad: np.ndarray, refine_budget: float, cancel: threading.Event | None,
           stage: Stage) -> tuple[list[Mode], np.ndarray, Samples | None]:
    """The modes of a non-empty set that refinement does not prove empty, most probable first, each with refined
    bounds; which cells belong to them; and likelihood samples of them all.

    Each mode is sampled on its own (an equal share of the budget), and the modes' probabilities come from
    Laplace's approximation (``mode_mass``), not from the samples. A mode's samples are drawn (from its cells as the
    search left them) in a second thread while its bounds are refined, mostly serial work that leaves a core free;
    one sampling thread, the modes in turn, keeps the random draws the same from run to run. A cancel ends the
    sampling before its next round.
    """
    cells = survivors.cells
    labels = mode_labels(cells, problem.fixture_radius_m)
    distinct = np.unique(labels)
    per_mode_samples = max(1, likelihood.max_samples // len(distinct))
    oracle = likelihood.fixture.oracle
    found = []
    sampler = ThreadPoolExecutor(max_workers=1, thread_name_prefix="fixwizard-samples")
    try:
        for number, label in enumerate(distinct, start=1):
            stage(SolveStage("bounds", number, len(distinct)))
            mode_survivors = survivors if len(distinct) == 1 else survivors.subset(labels == label)
            mode_cells = mode_survivors.cells
            sampling = sampler.submit(sample_cells, mode_cells, oracle, problem.base_p_taps, problem.ball_radius_m,
                                      likelihood.sigma_m, per_mode_samples, likelihood.rng, problem.fixture_radius_m,
                                      cancel)
            centre = bound_centre(mode_cells, fix_p_origin, rotation_center(mode_cells.distinct_rotations()[0]))
            def refining(round_: int, mode: int = number) -> None:
                stage(SolveStage("bounds", mode, len(distinct), round_))

            largest = refined_largest_figures(problem, mode_survivors, centre, fix_p_origin,
                                              refine_budget / len(distinct), cancel, refining)
            stage(SolveStage("samples", number, len(distinct)))
            samples = sampling.result()
            if largest is None:
                continue
            bounds = bounds_from_figures(centre, largest)
            found.append((bounds, samples, np.flatnonzero(labels == label),
                          ModeLikelihood(mode_cells, samples, bounds.max_point_displacement_m)))
    finally:  # a cancelled or failed refinement does not wait for its samples
        sampler.shutdown(wait=False, cancel_futures=True)
    if not found:
        return [], np.zeros(len(cells), bool), None
    stage(SolveStage("masses"))
    pinned = all(is_pinned(bounds, problem.fixture_radius_m) for bounds, *_ in found)
    shares = mode_shares(likelihood.fixture, problem.base_p_taps, problem.ball_radius_m, likelihood.sigma_m,
                         problem.sample_bound_m, [mode for *_, mode in found], likelihood.rng, rough=not pinned)
    modes = [Mode(float(share), expected_pose(samples, np.ones(len(samples.weights), bool), fix_T_cad), bounds,
                  len(rows))
             for share, (bounds, samples, rows, _) in zip(shares, found, strict=True)]
    kept = np.zeros(len(cells), bool)
    for _, _, rows, _ in found:
        kept[rows] = True
    samples = mixture([(samples, rows) for _, samples, rows, _ in found], shares)
    return sorted(modes, key=lambda mode: -mode.probability), kept, samples


def _search_tree(problem: SearchProblem, known: SearchTree | None, same_taps: bool, max_cells: float,
                 progress: Callable[[SearchProgress], None] | None, cancel: threading.Event | None,
                 descent: Descent) -> SearchTree | None:
    """The search tree for ``problem``: from ``known`` (a tree of the same taps, or of fewer of them, or None) where
    that helps. ``no_deeper`` always goes on from ``known`` (its set as it is, filtered against new taps); otherwise a
    tree whose root the taps shrink (``worth_extending``) gives way to a search from scratch, which reaches finer
    cells for the budget, and a tree of the same taps is taken further down."""
    if known is None:
        return search(problem, max_cells, progress, cancel, descent)
    if descent == "no_deeper":
        return known if same_taps else add_taps(problem, known, max_cells, progress, cancel, descent)
    if not worth_extending(problem, known):
        return search(problem, max_cells, progress, cancel, descent)
    if same_taps:
        return descend(problem, known, max_cells, progress, cancel, descent)
    return add_taps(problem, known, max_cells, progress, cancel, descent)


def solve(fixture: Fixture, base_p_taps: np.ndarray, ball_diameter_m: float, sample_bound_m: float,
          sigma_m: float | None = None, max_cells: float = DEFAULT_MAX_CELLS,
          progress: Callable[[SearchProgress], None] | None = None, cancel: threading.Event | None = None,
          max_samples: int = DEFAULT_MAX_SAMPLES, seed: int = 0, previous: Solution | None = None,
          hull_cells: float | None = None, diagnose_inconsistent: bool = True, descent: Descent = "thorough",
          stage: Stage | None = None) -> Solution:
    """All poses of ``fixture`` that explain the taps, with estimates; raises InputError for bad input.

    ``base_p_taps`` (N, 3): measured ball centres in the robot base frame (m). ``sigma_m``
    defaults to ``sample_bound_m / 3``. Raises ``SearchCancelled`` if ``cancel`` is set.
    ``previous``: a solution of the same fixture and bounds with fewer taps; when the taps extend its
    taps, the search goes on from its surviving set instead of starting over. With the same taps its set is
    taken further down as ``descent`` says (``no_deeper``: as it is), and the estimates and the hull refinement
    run again (with a larger ``hull_cells``, to tighten the bounds). ``hull_cells``: the cells hull
    refinement may evaluate (default ``HULL_SHARE`` of ``max_cells``). ``diagnose_inconsistent``: look for why no
    pose explains the taps (``diagnose``, seconds of searches) when none does. ``descent``: how far the search
    goes down (``search.Descent``; ``quick`` and ``no_deeper`` for the live check after each tap).
    ``stage``: called as each phase after the search starts (``SolveStage``).
    """
    stage = stage or (lambda _: None)
    base_p_taps = np.asarray(base_p_taps, dtype=float)
    sigma_m = sample_bound_m / 3.0 if sigma_m is None else sigma_m
    validate_inputs(base_p_taps, ball_diameter_m, sample_bound_m, sigma_m, max_cells)
    started = time.perf_counter()
    budget_warnings = []
    largest = largest_cell_budget(len(base_p_taps), available_memory_bytes())
    if max_cells > largest:
        budget_warnings.append(SolveWarning(
            "cell_budget_capped",
            f"The cell budget was capped at {largest:.2g} cells (from {max_cells:.2g}): with {len(base_p_taps)} taps "
            f"the search at {max_cells:.2g} cells could need {search_peak_bytes(max_cells, len(base_p_taps)) / 1e9:.1f}"
            f" GB, and {available_memory_bytes() / 1e9:.1f} GB are free."))
        max_cells = max(largest, MIN_MAX_CELLS)
    problem = SearchProblem(fixture.oracle, fixture.radius_m, base_p_taps, ball_diameter_m / 2.0, sample_bound_m)
    known = previous.tree if previous is not None and previous.extends_to(problem) else None
    tree: SearchTree | None
    same_taps = previous is not None and len(previous.problem.base_p_taps) == len(base_p_taps)
    tree = _search_tree(problem, known, same_taps, max_cells, progress, cancel, descent)
    survivors = None if tree is None else tree.final
    cells = None if survivors is None else survivors.cells
    warnings = ([SolveWarning(code, message) for code, message in fixture.warnings] + budget_warnings
                + _repeat_warnings(base_p_taps))
    fix_T_cad = fixture.fix_T_cad
    def inconsistent() -> Solution:
        if diagnose_inconsistent:
            stage(SolveStage("diagnosis"))
        diagnosis = diagnose(problem, min(max_cells, DIAGNOSIS_MAX_CELLS), cancel) if diagnose_inconsistent else None
        stats = SearchStats(0, cells.rotation_level if cells else 0, cells.position_level if cells else 0,
                            time.perf_counter() - started, max_cells)
        said = _inconsistent_warnings(diagnosis) if diagnosis is not None else [
            SolveWarning("inconsistent", "No pose of the fixture explains all taps.")]
        return Solution("inconsistent", None, None, [], [], warnings + said,
                        None if diagnosis is None else diagnosis.suspect, stats, None, problem, fix_T_cad,
                        diagnosis=diagnosis)

    if survivors is None or cells is None or len(cells) == 0:
        return inconsistent()
    fix_p_origin = -fixture.cad_p_center
    hull_cells = max_cells * HULL_SHARE if hull_cells is None else hull_cells
    likelihood = _Likelihood(fixture, sigma_m, max_samples, np.random.default_rng(seed))
    stage(SolveStage("modes"))
    modes, in_modes, samples = _modes(problem, survivors, likelihood, fix_p_origin, fix_T_cad, hull_cells, cancel,
                                      stage)
    if not modes or samples is None:
        return inconsistent()
    top = modes[0]
    if len(modes) == 1:
        bounds = top.bounds
    else:
        mode_cells = cells.subset(in_modes)
        centre = bound_centre(mode_cells, fix_p_origin, Rotation.from_matrix(top.bounds.base_T_cad_center[:3, :3]))
        bounds = bounds_from_figures(centre, cell_bound_figures(mode_cells, centre, fix_p_origin,
                                                                fixture.oracle.hull_cover).max(1))
    status = status_of([mode.bounds for mode in modes], fixture.radius_m)
    explained = [_explained(problem, mode, fix_T_cad) for mode in modes] if status != "undetermined" else []
    unexplained = _unexplained_warnings(problem) if explained and not any(explained) else []
    if unexplained:  # the set may be empty: its pose is not one a robot may use (see verdict)
        status = "undetermined"
        warnings += unexplained
    if status == "ambiguous":
        warnings.append(_ambiguous_warning(modes, explained))
    if status == "undetermined" and not unexplained:
        widest = max(modes, key=lambda mode: mode.bounds.max_point_displacement_m)
        why = openness(fixture, base_p_taps, sample_bound_m, cells, widest.bounds, top.base_T_cad)
        warnings.append(SolveWarning("undetermined", undetermined_message(why, widest.bounds, fixture.radius_m,
                                                                          max_cells)))
    effective = effective_sample_size(samples.weights)
    stage(SolveStage("intervals"))
    solution_intervals = intervals(samples, top.base_T_cad, fix_p_origin) if effective >= MIN_INTERVAL_SAMPLES else []
    if not solution_intervals:
        warnings.append(SolveWarning(
            "no_intervals",
            f"No 95/99 % intervals: only {effective:.0f} effective likelihood samples (at least "
            f"{MIN_INTERVAL_SAMPLES} are needed), since the cells are coarse next to how sharply the taps decide. "
            "The guaranteed bounds hold; a larger cell budget gives intervals."))
    stats = SearchStats(len(cells), cells.rotation_level, cells.position_level, time.perf_counter() - started,
                        max_cells)
    return Solution(status, top.base_T_cad, bounds, solution_intervals, modes, warnings, None, stats, tree, problem,
                    fix_T_cad, effective, explained=tuple(explained))
