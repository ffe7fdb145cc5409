"""Which fixture is this? The same taps against several meshes, each searched until it is decided.

A mesh for which no pose explains the taps is *ruled out* (the search keeps every pose that could explain
them, so an empty set is a proof at any cell budget). A mesh whose set is pinned down (``unique`` or
``ambiguous``) *fits*, ranked by how well its most probable pose explains the taps (the residuals, in mm). In
between, the cell budget grows tenfold (``BUDGETS``) until one of the two, the largest budget or the time limit
(a search still running then is stopped): then the mesh is *not decided*, never "fits".

``fixwizard identify POINTS MESH [MESH ...]`` prints one line per mesh, best fit first, and what the verdicts
mean together; the sampling screen's "Which fixture?" runs the same against every mesh the wizard offers.
"""

import argparse
import os
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from fixwizard.errors import FixwizardError, InputError, command_line_text, likely_units
from fixwizard.fixture import Fixture, load_fixture
from fixwizard.interrupt import run_interruptibly
from fixwizard.points import load_points
from fixwizard.solver.search import SearchCancelled
from fixwizard.solver.solve import Solution, solve, validate_inputs
from fixwizard.units import parse_length_m
from fixwizard.workflow.live import tap_surface_distances_m

DEFAULT_MAX_CELLS = 1e7
DEFAULT_TIME_LIMIT_S = 120.0
BUDGETS = (1e5, 1e6, 1e7, 1e8)  # tried in turn up to the largest budget
DEADLINE_POLL_S = 0.05  # how often a running search is checked against the deadline and the caller's cancel
IDENTIFY_SAMPLES = 2000
Verdict = Literal["fits", "ruled out", "not decided", "unreadable"]


@dataclass(frozen=True)
class MeshVerdict:
    """One mesh's verdict; ``rms_mm`` and ``worst_mm``: the taps' distances from the surface at the most
    probable pose (fits and not decided; None otherwise); ``max_cells``: the budget the verdict was reached at;
    ``likely_units``: the units that would make an unreadable mesh plausible, if that is why it is unreadable."""

    mesh: Path
    verdict: Verdict
    message: str
    rms_mm: float | None = None
    worst_mm: float | None = None
    max_cells: float = 0.0
    likely_units: str | None = None


@dataclass(frozen=True)
class IdentifyStep:
    """Progress: a mesh searched at a budget, and what that said so far."""

    mesh: Path
    max_cells: float
    status: str
    elapsed_s: float


def identify(base_p_taps: np.ndarray, meshes: list[tuple[Path, str]], ball_diameter_m: float,
             sample_bound_m: float, max_cells: float = DEFAULT_MAX_CELLS, time_limit_s: float = DEFAULT_TIME_LIMIT_S,
             cancel: threading.Event | None = None,
             progress: Callable[[IdentifyStep], None] | None = None) -> list[MeshVerdict]:
    """The verdict of every mesh (path and its units, "m" or "mm") for the taps (N, 3, base frame, m), in the
    meshes' order; lengths in m. ``time_limit_s`` is shared by all meshes: mesh ``k`` of ``n`` must be decided by
    ``k / n`` of it (time a mesh leaves goes to the next). A mesh that cannot be loaded gets "unreadable" with the
    loader's message instead of stopping the others. Raises ``SearchCancelled`` when ``cancel`` is set meanwhile."""
    base_p_taps = np.asarray(base_p_taps, float)
    validate_inputs(base_p_taps, ball_diameter_m, sample_bound_m, sample_bound_m / 3.0, max_cells)
    started = time.monotonic()
    return [_verdict(base_p_taps, Path(mesh), units, ball_diameter_m, sample_bound_m, max_cells,
                     started + time_limit_s * number / len(meshes), cancel, progress)
            for number, (mesh, units) in enumerate(meshes, start=1)]


RANK = {"fits": 0, "not decided": 1, "ruled out": 2, "unreadable": 3}


def ranked(verdicts: list[MeshVerdict]) -> list[MeshVerdict]:
    """Best fit first (smallest RMS), then not decided, ruled out and unreadable."""
    return sorted(verdicts, key=lambda verdict: (RANK[verdict.verdict], verdict.rms_mm or 0.0))


def _verdict(base_p_taps: np.ndarray, mesh: Path, mesh_units: str, ball_diameter_m: float, sample_bound_m: float,
             max_cells: float, deadline: float, cancel: threading.Event | None,
             progress: Callable[[IdentifyStep], None] | None) -> MeshVerdict:
    """One mesh, searched at growing budgets until it is ruled out or pinned down, or ``deadline`` (monotonic s)
    or ``max_cells`` stop it."""
    try:
        fixture = load_fixture(mesh, mesh_units)
    except FixwizardError as error:
        return MeshVerdict(mesh, "unreadable", str(error), likely_units=likely_units(error))
    budgets = [budget for budget in BUDGETS if budget < max_cells] + [max_cells]
    solution: Solution | None = None
    for budget in budgets:
        started = time.monotonic()
        try:
            solution = _solve_by(deadline, cancel, fixture, base_p_taps, ball_diameter_m, sample_bound_m, budget)
        except _OutOfTime:
            break
        if progress is not None:
            progress(IdentifyStep(mesh, budget, solution.status, time.monotonic() - started))
        if solution.status == "inconsistent" or solution.base_T_cad is None:
            return MeshVerdict(mesh, "ruled out", "no pose of this mesh explains the taps", max_cells=budget)
        rms_mm, worst_mm = _residuals_mm(fixture, base_p_taps, ball_diameter_m, solution.base_T_cad)
        if solution.status in ("unique", "ambiguous"):
            return MeshVerdict(mesh, "fits", f"{_poses_text(solution)}; at the most probable the taps lie "
                               f"{rms_mm:.2f} mm off the surface (RMS, worst {worst_mm:.2f} mm)", rms_mm, worst_mm,
                               budget)
    if solution is None:
        return MeshVerdict(mesh, "not decided", f"its first search ({budgets[0]:.0e} cells) did not end within the "
                           "time limit")
    return MeshVerdict(mesh, "not decided", f"neither ruled out nor pinned down within {solution.stats.max_cells:.0e} "
                       f"cells (RMS {rms_mm:.2f} mm off the surface at the most probable pose so far)", rms_mm,
                       worst_mm, solution.stats.max_cells)


def _poses_text(solution: Solution) -> str:
    """How many poses explain the taps of a pinned-down set: its modes, said to explain them only where a pose
    explaining every tap within the sample bound was found in each (``Solution.explained``); a mode without one may
    hold no pose, which only finer cells could prove."""
    modes, found = len(solution.modes), sum(solution.explained)
    if solution.status == "unique":
        return ("one pose explains the taps" if found else "one pose may explain the taps (none explaining every tap "
                "within the sample bound was found: the taps may fit no pose at this bound)")
    if found == modes:
        return f"{modes} poses explain the taps"
    return (f"{modes} poses may explain the taps (a pose explaining every tap within the sample bound was found for "
            f"{found} of them; the other{'s' if modes - found > 1 else ''} could not be ruled out at this cell budget)")


class _OutOfTime(Exception):
    """The deadline passed while a search ran."""


def _solve_by(deadline: float, cancel: threading.Event | None, fixture: Fixture, base_p_taps: np.ndarray,
              ball_diameter_m: float, sample_bound_m: float, max_cells: float) -> Solution:
    """The solve at ``max_cells``, stopped at ``deadline`` (monotonic s: raises ``_OutOfTime``) or when ``cancel``
    is set (raises ``SearchCancelled``)."""
    if time.monotonic() >= deadline:
        raise _OutOfTime
    stop, done = threading.Event(), threading.Event()

    def watch() -> None:
        while not done.wait(DEADLINE_POLL_S):
            if time.monotonic() >= deadline or (cancel is not None and cancel.is_set()):
                stop.set()
                return

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        return solve(fixture, base_p_taps, ball_diameter_m, sample_bound_m, max_cells=max_cells, cancel=stop,
                     max_samples=IDENTIFY_SAMPLES, diagnose_inconsistent=False)
    except SearchCancelled:
        if cancel is not None and cancel.is_set():
            raise
        raise _OutOfTime from None
    finally:
        done.set()
        watcher.join()


def _residuals_mm(fixture: Fixture, base_p_taps: np.ndarray, ball_diameter_m: float,
                  base_T_cad: np.ndarray) -> tuple[float, float]:
    """RMS and largest distance (mm) of the taps from the surface with the fixture at ``base_T_cad``."""
    distances_mm = 1e3 * tap_surface_distances_m(fixture, base_p_taps, ball_diameter_m, base_T_cad)
    return float(np.sqrt(np.mean(distances_mm**2))), float(np.max(np.abs(distances_mm)))


def summary_lines(verdicts: list[MeshVerdict]) -> list[str]:
    """One line per mesh, best fit first, then what the verdicts mean together."""
    verdicts = ranked(verdicts)
    lines = [f"{verdict.verdict:11} {verdict.mesh}: {command_line_text(verdict.message, verdict.likely_units)}"
             for verdict in verdicts]
    fitting = [verdict for verdict in verdicts if verdict.verdict == "fits"]
    open_ones = [verdict.mesh.name for verdict in verdicts if verdict.verdict == "not decided"]
    if len(fitting) > 1:
        lines.append(f"warning: {len(fitting)} meshes fit these taps ({', '.join(v.mesh.name for v in fitting)}), "
                     f"best {fitting[0].mesh.name}; tap features that differ between them")
    if open_ones:
        lines.append(f"not decided: {', '.join(open_ones)}; tap more points spread over the fixture, or give more "
                     "time (--time-limit) or cells (--max-cells)")
    ruled_out = any(verdict.verdict == "ruled out" for verdict in verdicts)
    if not fitting and not open_ones and ruled_out:
        unread = any(verdict.verdict == "unreadable" for verdict in verdicts)
        lines.append(f"no mesh {'that could be read ' if unread else ''}fits: check the units (--mesh-units), the tip "
                     "calibration and the sample bound, or tap again")
    return lines


def unreadable_sentence(meshes: list[Path]) -> str:
    """What to say of the meshes (as given) that could not be read: each might be the one that fits."""
    if len(meshes) == 1:
        return f"{meshes[0]} could not be read, so whether it fits is not known; fix it or leave it out"
    listed = f"{', '.join(map(str, meshes[:-1]))} and {meshes[-1]}"
    return f"{listed} could not be read, so whether they fit is not known; fix them or leave them out"


def _print_step(step: IdentifyStep) -> None:
    print(f"  {step.mesh.name}: {step.max_cells:.0e} cells: {step.status} ({step.elapsed_s:.1f} s)", file=sys.stderr)


def _same_mesh(first: Path, second: Path) -> bool:
    """Whether two paths name one file: the same file (through links too), or, where one cannot be looked at (a
    missing mesh), the same path once links and '..' are resolved."""
    try:
        return os.path.samefile(first, second)
    except OSError:
        return os.path.realpath(first) == os.path.realpath(second)


def _check_each_mesh_once(paths: list[Path]) -> None:
    """InputError when a mesh file is given twice (by the same path, a link or another path to it; also one that
    does not exist): it would fit twice and the taps be called ambiguous, or be listed twice as unreadable."""
    for later, path in enumerate(paths):
        for earlier in paths[:later]:
            if _same_mesh(earlier, path):
                twice = f"{path}" if str(earlier) == str(path) else f"{earlier} (also given as {path})"
                raise InputError(f"the mesh {twice} is given twice: give each mesh once")


def identify_command(args: argparse.Namespace) -> int:
    """Run ``fixwizard identify``: exit 0 when exactly one mesh fits, 2 when none fits or may fit, 3 when several
    fit, 4 when none fits but some are not decided; 1 when a mesh given could not be read (it may fit too)."""
    _check_each_mesh_once([Path(mesh) for mesh in args.meshes])
    base_p_taps = load_points(args.points)
    meshes = [(Path(mesh), args.mesh_units) for mesh in args.meshes]
    verdicts = run_interruptibly(lambda cancel: identify(
        base_p_taps, meshes, parse_length_m(args.ball_diameter), parse_length_m(args.sample_bound), args.max_cells,
        args.time_limit, cancel, None if args.quiet else _print_step))
    print("\n".join(summary_lines(verdicts)))
    unreadable = [verdict.mesh for verdict in verdicts if verdict.verdict == "unreadable"]
    if unreadable:
        print(f"fixwizard: {unreadable_sentence(unreadable)}", file=sys.stderr)
        return 1
    fitting = sum(verdict.verdict == "fits" for verdict in verdicts)
    if fitting:
        return 0 if fitting == 1 else 3
    return 4 if any(verdict.verdict == "not decided" for verdict in verdicts) else 2
