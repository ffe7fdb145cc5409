"""Live bounds while the operator taps: the paper's four real runs replayed one tap at a time.

Usage (from the repository root, with ../shared beside it):
    .venv/bin/python benchmarks/live_update.py [--runs student_1,expert]

Each run's taps are fed to the sampling screen's live check (``workflow.live.quick_check``) in the
order they were taken, each check going on from the previous one's set, as in the wizard. Per run it
prints every update's wall time, verdict and guaranteed bounds, then the median update time once the
pose is pinned down (verdict unique or ambiguous) and the time of the last tap's update, next to a
search from scratch of all taps.
"""

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "matlab-logo"
RUNS = ("student_1", "student_2", "student_3", "expert")
BALL_DIAMETER_M = 0.003
SAMPLE_BOUND_M = 0.001


def replay(run: str) -> None:
    """Print one run's live updates and their summary."""
    from fixwizard.fixture import load_fixture
    from fixwizard.geometry.se3 import read_pose_dir, read_pose_file
    from fixwizard.solver.distance_grid import distance_grid_for
    from fixwizard.workflow.import_poses import ball_centres_m
    from fixwizard.workflow.live import quick_check

    tip = read_pose_file(DATA / "calib" / "tcp_t_tip.pose")[:3, 3]
    taps = ball_centres_m(read_pose_dir(DATA / "samples" / run)[1], tip)
    fixture = load_fixture(DATA / "meshes" / "matlab_logo.ply")
    distance_grid_for(fixture.oracle)  # built once per fixture, when the wizard loads it
    check, pinned = None, []
    print(f"{run}: {len(taps)} taps")
    for count in range(3, len(taps) + 1):
        started = time.perf_counter()
        check = quick_check(fixture, taps[:count], BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=check)
        seconds = time.perf_counter() - started
        bounds = check.solution.bounds
        figures = (f"{bounds.position_m * 1e3:6.1f} mm {np.degrees(bounds.rotation_rad):6.1f} deg"
                   if bounds is not None else "")
        print(f"  tap {count:2d}: {seconds:5.2f} s  {check.verdict:12} {figures}")
        if check.verdict in ("unique", "ambiguous"):
            pinned.append(seconds)
    started = time.perf_counter()
    quick_check(fixture, taps, BALL_DIAMETER_M, SAMPLE_BOUND_M)
    scratch = time.perf_counter() - started
    median = f"{statistics.median(pinned):.2f} s over {len(pinned)} updates" if pinned else "never pinned down"
    print(f"  median update once pinned down: {median}; last tap {seconds:.2f} s; all taps from scratch "
          f"{scratch:.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default=",".join(RUNS), help="comma-separated runs (default: all four)")
    args = parser.parse_args()
    for run in args.runs.split(","):
        replay(run)


if __name__ == "__main__":
    main()
