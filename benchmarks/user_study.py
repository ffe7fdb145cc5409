"""The four real user-study runs of the paper, as a user runs them: whole-process wall time of `fixwizard solve`,
peak memory, guaranteed bounds, their reach and the tightness ratio bound / reach.

Usage (from the repository root, with ../shared beside it):
    .venv/bin/python benchmarks/user_study.py [--repeat 3] [--max-cells 1e7] [--compare ../base]

Every solve is a fresh `python -m fixwizard.cli solve ...` process (imports, mesh, cached lattice, solve, report),
timed from start to exit; its peak memory is its own max RSS. ``--compare DIR`` runs another checkout (with its
own ``.venv``) on the same inputs, alternating solve by solve, since these machines drift; medians are printed.

The reach is a lower bound on how far the set of poses that explain the taps really extends: the farthest
certified poses (every tap's distance interval within the bound) found by pushing outward from the expected pose
(``fixwizard.solver.reach``), measured from each report's bound centre. The true extent lies between reach and
bound; ``bound / reach`` is how much looser than necessary the bound can at most be.
"""

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

from cli_process import timed_command

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "matlab-logo"
RUNS = ("student_1", "student_2", "student_3", "expert")
REFERENCE = {"student_1": (3.30, 2.65), "student_2": (2.71, 1.61), "student_3": (3.01, 4.05), "expert": (1.59, 1.16)}


def write_points(folder: Path) -> dict[str, Path]:
    """Each run's ball centres as a POINTS file (the published tip)."""
    from fixwizard.geometry.se3 import read_pose_dir, read_pose_file
    from fixwizard.points import write_points as write
    from fixwizard.workflow.import_poses import ball_centres_m

    tip = read_pose_file(DATA / "calib" / "tcp_t_tip.pose")[:3, 3]
    paths = {}
    for run in RUNS:
        paths[run] = folder / f"{run}.yaml"
        write(paths[run], ball_centres_m(read_pose_dir(DATA / "samples" / run)[1], tip))
    return paths


def solve_process(checkout: Path, points: Path, report: Path, max_cells: float) -> tuple[float, float]:
    """Wall time (s) and peak memory (MB) of one whole `fixwizard solve` process of ``checkout``."""
    seconds, peak_mb, _ = timed_command(checkout, [
        "solve", str(DATA / "meshes" / "matlab_logo.ply"), str(points), "--sample-bound", "1mm", "--ball-diameter",
        "3mm", "--max-cells", f"{max_cells:g}", "-q", "-o", str(report)])
    return seconds, peak_mb


def report_figures(report: Path) -> dict:
    """Status, bounds (mm, deg, mm) and the poses of a report of either schema version."""
    import yaml

    data = yaml.safe_load(report.read_text())
    bounds = data["bounds"]
    return {"status": data["status"], "bounds": (1e3 * bounds["position_m"], bounds["rotation_deg"],
                                                 1e3 * bounds["max_point_displacement_m"]),
            "centre": bounds["center"], "pose": data["pose"]}


def reach_of(run_points: Path, figures: dict) -> tuple[float, float, float]:
    """The certified reach (mm, deg, mm) from the report's bound centre, pushed outward from its expected pose."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from fixwizard.fixture import load_fixture
    from fixwizard.geometry.se3 import make_transform
    from fixwizard.points import load_points
    from fixwizard.solver.estimates import BoundCentre
    from fixwizard.solver.reach import reach
    from fixwizard.solver.search import SearchProblem

    fixture = load_fixture(DATA / "meshes" / "matlab_logo.ply")
    problem = SearchProblem(fixture.oracle, fixture.radius_m, load_points(run_points), 0.0015, 0.001)
    centre = figures["centre"]
    bound_centre = BoundCentre(Rotation.from_rotvec(centre["rotvec_rad"]), np.array(centre["position_m"]))
    pose = figures["pose"]
    start = fixture.base_T_fix(make_transform(Rotation.from_rotvec(pose["rotvec_rad"]), pose["position_m"]))
    found = reach(problem, [start], bound_centre, -fixture.cad_p_center, fixture.oracle.hull_cover,
                  figures["bounds"][2] * 1e-3)
    if found is None:
        return (float("nan"),) * 3
    position_m, rotation_rad, displacement_m = found.figures
    return 1e3 * position_m, float(np.degrees(rotation_rad)), 1e3 * displacement_m


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--max-cells", type=float, default=1e7)
    parser.add_argument("--repeat", type=int, default=3, help="solves per run and checkout; medians are printed")
    parser.add_argument("--compare", type=Path, help="another checkout with its own .venv, run alternately")
    args = parser.parse_args()
    if not DATA.is_dir():
        sys.exit(f"the real data is not at {DATA}")
    checkouts = {"this": REPO} | ({"compare": args.compare.resolve()} if args.compare else {})
    folder = Path(tempfile.mkdtemp(prefix="fixwizard-user-study-"))
    points = write_points(folder)
    print(f"{'run':10} {'version':8} {'status':8} {'wall s':>6} {'peak MB':>7} {'pos mm':>6} {'rot deg':>7} "
          f"{'disp mm':>7} | {'reach mm/deg/mm':>17} | {'bound/reach':>17} | ref mm / deg")
    walls: dict[str, list[float]] = {name: [] for name in checkouts}
    for run in RUNS:
        timings: dict[str, list[tuple[float, float]]] = {name: [] for name in checkouts}
        for _ in range(args.repeat):
            for name, checkout in checkouts.items():
                timings[name].append(solve_process(checkout, points[run], folder / f"{run}-{name}.yaml",
                                                   args.max_cells))
        for name in checkouts:
            figures = report_figures(folder / f"{run}-{name}.yaml")
            reach = reach_of(points[run], figures)
            wall = statistics.median(seconds for seconds, _ in timings[name])
            walls[name].append(wall)
            peak = max(megabytes for _, megabytes in timings[name])
            ratios = [bound / reached for bound, reached in zip(figures["bounds"], reach, strict=True)]
            position, rotation, displacement = figures["bounds"]
            print(f"{run:10} {name:8} {figures['status']:8} {wall:6.1f} {peak:7.0f} {position:6.2f} {rotation:7.2f} "
                  f"{displacement:7.2f} | {reach[0]:5.2f} {reach[1]:5.2f} {reach[2]:5.2f} | "
                  f"{ratios[0]:5.2f} {ratios[1]:5.2f} {ratios[2]:5.2f} | "
                  f"{REFERENCE[run][0]:.2f} / {REFERENCE[run][1]:.2f}")
    for name, values in walls.items():
        print(f"{name}: median whole-process wall time over the runs {statistics.median(values):.1f} s")


if __name__ == "__main__":
    main()
