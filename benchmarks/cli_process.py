"""One whole `fixwizard` command in a fresh process, as a user runs it: its wall time and its own peak memory."""

import subprocess
import sys
import time
from pathlib import Path

# runs the CLI as its installed command does (``cli.entry``, or ``main`` then ``sys.exit`` in versions before it)
# and reports its own peak memory on the last line of stderr as it leaves: the high-water mark of its own memory
# since it started (VmHWM; ru_maxrss would count the memory of the process that started it, carried over the fork)
WRAPPER = """\
import os, sys
from fixwizard import cli
def peak_kb():
    return open('/proc/self/status').read().split('VmHWM:')[1].split()[0]
def leave(code, exit_now=os._exit):
    sys.stdout.flush()
    print('MAXRSS_KB', peak_kb(), file=sys.stderr, flush=True)
    exit_now(code)
os._exit = leave
if hasattr(cli, 'entry'):
    try:
        cli.entry()
    except SystemExit as leaving:
        leave(leaving.code or 0)
else:
    leave(cli.main(sys.argv[1:]), sys.exit)
"""
SOLVED = (0, 3, 4)  # unique, ambiguous, undetermined: a solve that ran to its end


def timed_command(checkout: Path, args: list[str]) -> tuple[float, float, list[str]]:
    """Wall time (s), peak memory (MB) and the other lines on stderr of `fixwizard ARGS` run by ``checkout``'s
    ``.venv`` in ``checkout``; the benchmark stops with the command's stderr when its exit code is no solve's."""
    command = [str(checkout / ".venv" / "bin" / "python"), "-c", WRAPPER, *args]
    started = time.perf_counter()
    result = subprocess.run(command, cwd=checkout, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if result.returncode not in SOLVED:
        sys.exit(f"{checkout}: {args[0]} failed ({result.returncode}):\n{result.stderr[-2000:]}")
    lines = result.stderr.strip().splitlines()
    return seconds, float(lines[-1].split()[-1]) / 1024.0, lines[:-1]
