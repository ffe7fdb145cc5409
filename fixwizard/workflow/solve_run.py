"""One headless solve: load the inputs, run the solver, write the report, and summarise it for people."""

import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fixwizard import report
from fixwizard.fixture import Fixture, load_fixture
from fixwizard.points import load_points
from fixwizard.solver.search import SearchProgress
from fixwizard.solver.solve import DEFAULT_MAX_CELLS, Solution, Stage, solve


@dataclass(frozen=True)
class SolveRequest:
    """Everything a solve needs; lengths in metres."""

    mesh_path: Path
    points_path: Path
    ball_diameter_m: float
    sample_bound_m: float
    mesh_units: str = "m"
    sigma_m: float | None = None
    max_cells: float = DEFAULT_MAX_CELLS
    fixture_name: str | None = None  # the report's name of the fixture (default: from the mesh file's stem)


@dataclass(frozen=True)
class SolveOutcome:
    fixture: Fixture
    base_p_taps: np.ndarray
    solution: Solution
    report: dict


def run_solve(request: SolveRequest, progress: Callable[[SearchProgress], None] | None = None,
              cancel: threading.Event | None = None, stage: Stage | None = None) -> SolveOutcome:
    """Load mesh and taps, solve, and build the report dict (not yet written). ``progress`` and ``stage``: called
    with the search's levels and the phases after it."""
    fixture = load_fixture(request.mesh_path, request.mesh_units)
    base_p_taps = load_points(request.points_path)
    sigma_m = request.sigma_m if request.sigma_m is not None else request.sample_bound_m / 3.0
    solution = solve(fixture, base_p_taps, request.ball_diameter_m, request.sample_bound_m, sigma_m,
                     request.max_cells, progress, cancel, stage=stage)
    data = report.report_dict(solution, fixture, base_p_taps, request.ball_diameter_m, request.sample_bound_m,
                              sigma_m, name=request.fixture_name)
    return SolveOutcome(fixture, base_p_taps, solution, data)


def _figures_text(position_m: float, rotation_deg: float, max_point_displacement_m: float) -> str:
    """Guaranteed figures in mm and deg, rounded up (never below what is guaranteed)."""
    return (f"CAD origin within {report.round_up(position_m * 1e3, 2):.2f} mm, rotation within "
            f"{report.round_up(rotation_deg, 2):.2f} deg, any fixture point within "
            f"{report.round_up(max_point_displacement_m * 1e3, 2):.2f} mm")


def summary_lines(outcome: SolveOutcome) -> list[str]:
    """A short human summary in mm and degrees."""
    solution = outcome.solution
    lines = [f"status: {solution.status} ({len(outcome.base_p_taps)} taps, {solution.stats.cells} cells survive, "
             f"{solution.stats.elapsed_s:.1f} s)"]
    if solution.base_T_cad is not None and solution.bounds is not None:
        pose = report.pose_dict(solution.base_T_cad)
        x, y, z = (1e3 * value for value in pose["position_m"])
        bounds, about_pose = solution.bounds, outcome.report["pose"]["guaranteed"]  # as the report and export say
        lines += [f"pose of the CAD frame: x {x:.2f} mm, y {y:.2f} mm, z {z:.2f} mm, "
                  f"rotation {np.degrees(np.linalg.norm(pose['rotvec_rad'])):.2f} deg",
                  f"UR pose: {report.robot_pose_text(solution.status, pose['ur'])}",
                  "guaranteed about this pose: " + _figures_text(*(about_pose[key] for key in (
                      "position_m", "rotation_deg", "max_point_displacement_m"))),
                  "guaranteed about the centre of the set (bounds.center): " + _figures_text(
                      bounds.position_m, np.degrees(bounds.rotation_rad), bounds.max_point_displacement_m)]
        lines += [f"{interval.level:.0%} interval: {interval.position_m * 1e3:.2f} mm, "
                  f"{np.degrees(interval.rotation_rad):.2f} deg" for interval in solution.intervals]
    lines += [f"warning: {warning.message}" for warning in solution.warnings]
    return lines
