"""How late the wizard's event loop runs while the solver works, with other busy processes on the machine.

Usage (from the repository root):
    .venv/bin/python benchmarks/responsiveness.py [--taps 8] [--max-cells 1e7] [--busy 2]

Drives the real sampling and solve screens with Pilot on the simulated demo cell (the tests' wizard parts,
tests/loop_lag.py): opens sampling with ``--taps`` spread taps, whose live check starts at once, presses a key
while it runs, then runs the full solve. Meanwhile ``--busy`` processes spin (``while True: pass``). Prints the
median and largest lateness of a 10 ms timer during each phase (and how often it passed 100 ms), and the key's
time to its effect on the screen (including Pilot's own wait for the screen to settle).
The target: no key unanswered for more than 100 ms.
"""

import argparse
import asyncio
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from loop_lag import measure_wizard  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--taps", type=int, default=8)
    parser.add_argument("--max-cells", type=float, default=1e7)
    parser.add_argument("--busy", type=int, default=2, help="busy processes beside the wizard")
    args = parser.parse_args()
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    try:
        with tempfile.TemporaryDirectory() as folder:
            measured = asyncio.run(measure_wizard(Path(folder), args.taps, args.max_cells))
    finally:
        for process in busy:
            process.kill()
    print(f"{args.taps} taps, {args.max_cells:.0e} cells, {args.busy} busy processes")
    print(f"key during the live check answered in {measured.key_s * 1e3:.0f} ms")
    for phase, seconds in (("live", measured.live_s), ("solve", measured.solve_s)):
        lags_ms = [lag * 1e3 for lag in measured.lags_s.get(phase, [])]
        print(f"{phase:5} ({seconds:.1f} s, {len(lags_ms)} ticks): event-loop lag median "
              f"{statistics.median(lags_ms):.1f} ms, max {max(lags_ms):.1f} ms, over 100 ms "
              f"{sum(lag > 100.0 for lag in lags_ms)} times")


if __name__ == "__main__":
    main()
