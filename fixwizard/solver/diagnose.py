"""Why no pose explains the taps, most likely cause first: one tap off the fixture, a wrong ball diameter, a
sample bound too small for the robot, or the wrong mesh or units.

Every verdict rests on searches, which are proofs when they come out empty ("no pose explains these taps with
a bound of b") and tell only "not ruled out" otherwise:

1. The smallest sample bound that explains all taps: doubled from the given one until a search keeps poses,
   then bisected (geometrically) a few times; the result is a bracket (ruled out, not ruled out). Nothing up
   to ``MAX_RELAXED_BOUND_M``: the wrong mesh or units, said with how far the taps spread against the
   fixture's size.
2. The pose that fits all taps best (least squares from the best cells of that relaxed set), and each tap's
   residual there (signed distance less the ball radius).
3. A single tap: the taps with the largest residuals are left out in turn; if the others fit at the given
   bound, that tap is the suspect, and its distance is the one at the pose the *others* fit best.
4. The ball: a common offset of the residuals is a ball radius that is off. The pose and the ball radius are fitted
   together (the pose by least squares, the radius by the residuals' median, in turn); if the taps fit at the
   given bound with that radius, the ball diameter (or the tip calibration) is wrong.
"""

import threading
from dataclasses import dataclass, replace

import numpy as np

from fixwizard.geometry.se3 import points_in_frames
from fixwizard.solver.cells import CellSet
from fixwizard.solver.mode_mass import laplace_peak
from fixwizard.solver.search import SearchProblem, SearchTree, search

# Each probe only tells empty from not empty. The smallest bound's bracket may be coarse; a probe that clears a tap
# or a ball diameter must not be fooled by coarse cells (at 3e5 cells a wrong ball was blamed on a tap).
BRACKET_MAX_CELLS = 3e5
PROBE_MAX_CELLS = 1e6
MAX_RELAXED_BOUND_M = 0.02
BISECTIONS = 2
SUSPECTS_TRIED = 3  # the taps with the largest residuals at the best fit, left out in turn
FIT_CELLS = 20_000  # cell centres whose residuals pick the starts of the best fit
FIT_STARTS = 3
BALL_FIT_ROUNDS = 4
# Units a mesh may be in, with how many times its size read as millimetres makes the taps spread (up to that many
# times the fixture's size, from 0.3 of it on: taps over part of the fixture). Centimetres and inches overlap.
UNIT_MIXUPS = ((1000.0, "metres"), (25.4, "inches"), (10.0, "centimetres"))


@dataclass(frozen=True)
class SuspectTap:
    """Tap ``index`` (0-based) lies ``distance_m`` off the surface the ball would touch (signed distance less
    the ball radius; positive: short of the surface, negative: inside) at the pose the other taps fit best."""

    index: int
    distance_m: float


@dataclass(frozen=True)
class Cause:
    """One explanation of inconsistent taps: a stable ``code`` and what to do, in plain words."""

    code: str
    message: str


@dataclass(frozen=True)
class Diagnosis:
    """The causes, most likely first; the suspect tap if leaving one out explains the rest; the bracket of the
    smallest sample bound (m) that explains all taps (``(ruled out, not ruled out)``, None when nothing up to
    ``MAX_RELAXED_BOUND_M`` does); a ball diameter (m) that explains them at the given bound, if one was found."""

    causes: list[Cause]
    suspect: SuspectTap | None
    smallest_bound_m: tuple[float, float] | None
    ball_diameter_m: float | None


def _fits(problem: SearchProblem, max_cells: float, cancel: threading.Event | None) -> SearchTree | None:
    """The search tree when some pose is not ruled out, else None."""
    tree = search(problem, max_cells, cancel=cancel, descent="exhaustive")
    return tree if tree is not None and len(tree.final) else None


def _residuals_m(problem: SearchProblem, base_T_fix: np.ndarray) -> np.ndarray:
    """Each tap's signed distance less the ball radius (m) at a pose."""
    return problem.oracle.signed_distance_at_m(base_T_fix, problem.base_p_taps) - problem.ball_radius_m


def _refit(problem: SearchProblem, start: np.ndarray, extent_m: float) -> np.ndarray:
    """The least-squares pose ``base_T_fix`` nearest ``start`` (robust first)."""
    return laplace_peak(problem.oracle, problem.base_p_taps, problem.ball_radius_m, problem.sample_bound_m / 3.0, start,
                        problem.fixture_radius_m, extent_m).base_T_fix


def best_fit(problem: SearchProblem, cells: CellSet, extent_m: float) -> np.ndarray:
    """The pose ``base_T_fix`` that fits the taps best (least squares on the residuals, robust first), started
    from the ``FIT_STARTS`` cell centres with the smallest squared residuals among up to ``FIT_CELLS`` cells."""
    rng = np.random.default_rng(0)
    chosen = np.arange(len(cells)) if len(cells) <= FIT_CELLS else rng.choice(len(cells), FIT_CELLS, replace=False)
    base_R_fix, _ = cells.distinct_rotation_matrices()
    rotations = base_R_fix[cells.rotation_index[chosen]]
    positions = cells.positions_m(chosen)
    fix_p_taps = points_in_frames(rotations, positions, problem.base_p_taps)
    residuals = problem.oracle.signed_distance_m(fix_p_taps.reshape(-1, 3)).reshape(len(chosen), -1)
    chi2 = np.sum((residuals - problem.ball_radius_m) ** 2, axis=1)
    peaks = []
    for row in np.argsort(chi2)[:FIT_STARTS]:
        start = np.eye(4)
        start[:3, :3], start[:3, 3] = rotations[row], positions[row]
        peaks.append(_refit(problem, start, extent_m))
    return min(peaks, key=lambda pose: float(np.sum(_residuals_m(problem, pose) ** 2)))


def _tap_spread_m(base_p_taps: np.ndarray) -> float:
    """Largest distance (m) between two taps."""
    offsets = base_p_taps[:, None, :] - base_p_taps[None, :, :]
    return float(np.sqrt(np.max(np.sum(offsets**2, axis=-1))))


def _mesh_or_units(problem: SearchProblem) -> Cause:
    spread_m = _tap_spread_m(problem.base_p_taps)
    size_m = 2.0 * problem.fixture_radius_m
    ratio = spread_m / size_m
    units = [name for factor, name in UNIT_MIXUPS if 0.3 * factor <= ratio <= 1.2 * factor]
    hint = (f" That is {ratio:.3g} times: a mesh in {' or '.join(units)} read as millimetres would explain it."
            if units else "")
    return Cause("mesh_or_units",
                 f"No pose explains the taps even with a {MAX_RELAXED_BOUND_M * 1e3:.0f} mm sample bound: the taps "
                 f"spread over {spread_m * 1e3:.0f} mm and the fixture is {size_m * 1e3:.0f} mm across.{hint} Check "
                 "that the mesh is this fixture, its units (--mesh-units m or mm; export a mesh in other units in "
                 "one of those) and the tool-tip calibration.")


def _smallest_bound(problem: SearchProblem, max_cells: float,
                    cancel: threading.Event | None) -> tuple[float, float, SearchTree] | None:
    """``(ruled out, not ruled out, tree at the latter)`` for the sample bound, or None up to the largest."""
    low, bound = problem.sample_bound_m, problem.sample_bound_m
    tree = None
    while tree is None:
        bound = min(2.0 * bound, MAX_RELAXED_BOUND_M)
        tree = _fits(replace(problem, sample_bound_m=bound), max_cells, cancel)
        if tree is None and bound >= MAX_RELAXED_BOUND_M:
            return None
        if tree is None:
            low = bound
    high = bound
    for _ in range(BISECTIONS):
        middle = float(np.sqrt(low * high))
        found = _fits(replace(problem, sample_bound_m=middle), max_cells, cancel)
        if found is None:
            low = middle
        else:
            high, tree = middle, found
    return low, high, tree


def _suspect(problem: SearchProblem, residuals_m: np.ndarray, extent_m: float, max_cells: float,
             cancel: threading.Event | None) -> SuspectTap | None:
    """The first of the taps with the largest residuals whose removal lets the others fit; its distance at the
    pose the others fit best."""
    if len(problem.base_p_taps) <= 3:
        return None
    for index in np.argsort(-np.abs(residuals_m))[:SUSPECTS_TRIED]:
        others = replace(problem, base_p_taps=np.delete(problem.base_p_taps, index, axis=0))
        tree = _fits(others, max_cells, cancel)
        if tree is None:
            continue
        pose = best_fit(others, tree.final.cells, extent_m)
        distance = float(_residuals_m(problem, pose)[index])
        return SuspectTap(int(index), distance)
    return None


def _ball_diameter(relaxed: SearchProblem, pose: np.ndarray, extent_m: float, max_cells: float, bound_m: float,
                   cancel: threading.Event | None) -> float | None:
    """A ball diameter (m) with which the taps fit at ``bound_m``, fitted together with the pose from the relaxed
    best fit ``pose``; None when the fitted one is within half the bound of the given one or does not fit either."""
    radius = relaxed.ball_radius_m
    for _ in range(BALL_FIT_ROUNDS):
        radius = max(radius + float(np.median(_residuals_m(replace(relaxed, ball_radius_m=radius), pose))), 0.0)
        pose = _refit(replace(relaxed, ball_radius_m=radius), pose, extent_m)
    if abs(radius - relaxed.ball_radius_m) <= 0.5 * bound_m:
        return None
    corrected = replace(relaxed, ball_radius_m=radius, sample_bound_m=bound_m)
    return 2.0 * radius if _fits(corrected, max_cells, cancel) is not None else None


def diagnose(problem: SearchProblem, max_cells: float, cancel: threading.Event | None = None) -> Diagnosis:
    """Why no pose explains the taps of ``problem`` (see the module doc); raises ``SearchCancelled`` when
    ``cancel`` is set meanwhile."""
    probe_cells = min(max_cells, PROBE_MAX_CELLS)
    relaxed = _smallest_bound(problem, min(max_cells, BRACKET_MAX_CELLS), cancel)
    if relaxed is None:
        return Diagnosis([_mesh_or_units(problem)], None, None, None)
    low, high, tree = relaxed
    extent_m = problem.fixture_radius_m
    pose = best_fit(replace(problem, sample_bound_m=high), tree.final.cells, extent_m)
    residuals = _residuals_m(problem, pose)
    bound = problem.sample_bound_m
    suspect = _suspect(problem, residuals, extent_m, probe_cells, cancel)
    # Tried even when a suspect tap is far off: a wrong ball leaves every tap off by the same amount, so the others'
    # best pose may put one tap far off (and a 6 mm ball on a 3 mm tip was blamed on a tap). A ball with which all
    # taps fit explains more than dropping one; one tap far off moves the residuals' median too little to try one.
    ball_diameter = _ball_diameter(replace(problem, sample_bound_m=high), pose, extent_m, probe_cells, bound, cancel)
    causes = []
    if suspect is not None:
        where = "short of" if suspect.distance_m > 0 else "inside"
        causes.append(Cause("suspect_tap",
                            f"Tap {suspect.index + 1} lies {abs(suspect.distance_m) * 1e3:.1f} mm {where} the surface "
                            "at the pose the other taps fit best, and without it the others are not ruled out: it "
                            "probably missed the fixture or touched something else. Drop it and solve again."))
    if ball_diameter is not None:
        causes.append(Cause("ball_diameter",
                            f"With a {ball_diameter * 1e3:.1f} mm ball instead of {2e3 * problem.ball_radius_m:.1f} mm "
                            "(at the same sample bound) the taps are not ruled out: check the ball diameter and the "
                            "tool-tip calibration."))
    causes.append(Cause("sample_bound",
                        f"With a sample bound of {low * 1e3:.2f} mm no pose explains the taps (that is proved); with "
                        f"{high * 1e3:.2f} mm some poses are not ruled out. If this robot's taps err that much, the "
                        "sample bound is too small: calibrate the tool tip again; otherwise check the mesh, its "
                        "units and the calibration."))
    if ball_diameter is not None:
        causes.sort(key=lambda cause: cause.code != "ball_diameter")
    return Diagnosis(causes, suspect, (low, high), ball_diameter)
