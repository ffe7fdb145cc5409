"""How long the start screen takes to list what can be continued, in a cell that has been in use for a while.

Usage (from the repository root):
    .venv/bin/python benchmarks/start_lists.py [--finished 200] [--unfinished 5] [--records 70]

Writes ``--finished`` closed and ``--unfinished`` open journals of ``--records`` records each, of sampling sessions
and of tip calibrations, into a temporary folder, then times the two lists the start screen builds when it opens
(on the event loop): unfinished sessions and unfinished tip calibrations. Prints the median of 7 runs of each.
"""

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from fixwizard.workflow.calibration_journal import (
    CalibrationJournal,
    find_unfinished_calibrations,
    journals_dir,
)
from fixwizard.workflow.session import SamplingSession, find_unfinished

ROBOT = "benchmark robot"


def write_journals(folder: Path, finished: int, unfinished: int, records: int) -> None:
    """Sessions in ``folder/sessions``, tip calibration journals under ``folder/calibrations``."""
    for index in range(finished + unfinished):
        session = SamplingSession.create(folder / "sessions" / f"s{index:04d}.jsonl", {"name": "bench"},
                                         {"tcp_p_tip_m": [0.0, 0.0, 0.1]}, ROBOT)
        calibration = CalibrationJournal.create(journals_dir(folder / "calibrations"), ROBOT, {})
        for record in range(records):
            pose = np.eye(4)
            pose[:3, 3] = [0.4, 0.001 * record, 0.2]
            session.record_tap(pose)
            calibration.record_pose("table", pose)
        if index < finished:
            session.close(report="r.yaml")
            calibration.close("saved", calibration="c.yaml")
        else:
            session.release()
            calibration.release()


def median_s(call: Callable[[], object], runs: int = 7) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--finished", type=int, default=200)
    parser.add_argument("--unfinished", type=int, default=5)
    parser.add_argument("--records", type=int, default=70)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        write_journals(folder, args.finished, args.unfinished, args.records)
        sessions_s = median_s(lambda: find_unfinished(folder / "sessions"))
        calibrations_s = median_s(lambda: find_unfinished_calibrations(folder / "calibrations", ROBOT))
    print(f"{args.finished} finished and {args.unfinished} unfinished journals of {args.records} records each")
    print(f"unfinished sessions listed in {sessions_s * 1e3:.1f} ms (median of 7)")
    print(f"unfinished tip calibrations listed in {calibrations_s * 1e3:.1f} ms (median of 7)")


if __name__ == "__main__":
    main()
