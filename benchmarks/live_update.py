"""Live bounds while the operator taps: the paper's four real runs replayed one tap at a time.

Usage (from the repository root, with ../shared beside it):
    .venv/bin/python benchmarks/live_update.py [--runs student_1,expert]

Each run's taps are fed to the sampling screen's live check in the order they were taken, each check going on
from the previous one's set, as in the wizard: its first look (``workflow.live.first_look``, what the screen
shows first), then the quick check of the same set (``quick_check``, lightly refined bounds). Per run it prints
every update's wall time to the first look and to the quick check, the verdict and the guaranteed bounds of each,
then the medians once the pose is pinned down (verdict unique or ambiguous) and the last tap's times, next to a
quick check of all taps from scratch.
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
    from fixwizard.workflow.live import first_look, quick_check

    tip = read_pose_file(DATA / "calib" / "tcp_t_tip.pose")[:3, 3]
    taps = ball_centres_m(read_pose_dir(DATA / "samples" / run)[1], tip)
    fixture = load_fixture(DATA / "meshes" / "matlab_logo.ply")
    distance_grid_for(fixture.oracle)  # built once per fixture, when the wizard loads it
    def figures(check) -> str:
        bounds = check.solution.bounds
        return (f"{check.verdict:12} {bounds.position_m * 1e3:5.1f} mm {np.degrees(bounds.rotation_rad):5.1f} deg"
                if bounds is not None else f"{check.verdict:12}")

    check, pinned_first, pinned_quick = None, [], []
    print(f"{run}: {len(taps)} taps")
    for count in range(3, len(taps) + 1):
        started = time.perf_counter()
        first = first_look(fixture, taps[:count], BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=check)
        first_s = time.perf_counter() - started
        check = quick_check(fixture, taps[:count], BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=first)
        quick_s = time.perf_counter() - started
        print(f"  tap {count:2d}: first look {first_s:5.2f} s  {figures(first)} | quick {quick_s:5.2f} s  "
              f"{figures(check)}")
        if first.verdict in ("unique", "ambiguous"):
            pinned_first.append(first_s)
            pinned_quick.append(quick_s)
    started = time.perf_counter()
    quick_check(fixture, taps, BALL_DIAMETER_M, SAMPLE_BOUND_M)
    scratch = time.perf_counter() - started
    if pinned_first:
        print(f"  median once pinned down ({len(pinned_first)} updates): first look "
              f"{statistics.median(pinned_first):.2f} s, quick check {statistics.median(pinned_quick):.2f} s; "
              f"last tap {first_s:.2f} s / {quick_s:.2f} s; all taps from scratch {scratch:.2f} s")
    else:
        print(f"  never pinned down; all taps from scratch {scratch:.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default=",".join(RUNS), help="comma-separated runs (default: all four)")
    args = parser.parse_args()
    for run in args.runs.split(","):
        replay(run)


if __name__ == "__main__":
    main()
