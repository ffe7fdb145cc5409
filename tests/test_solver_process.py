"""The solver's own process: live checks, a full solve and their progress come back as events; a newer request
supersedes the running one; a stop or a crash loses no answer the operator needs and the next request is
answered by a fresh process."""

import os
import queue
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fixwizard.demo import demo_cell
from fixwizard.workflow.live import LiveView
from fixwizard.workflow.solver_process import (
    Failed,
    Finished,
    LiveRequest,
    Progress,
    Solved,
    SolveRequest,
    SolverProcess,
)
from shapes import as_fixture
from tui_cell import SAMPLE_BOUND_M, spread_taps

WAIT_S = 300.0


@pytest.fixture(scope="module")
def tapped():
    cell = demo_cell(0)
    cell.connect()
    return cell, spread_taps(cell, 12)


def events_until_done(events: queue.Queue) -> list:
    """The events of one request up to its Finished or Failed."""
    seen = []
    while not seen or not isinstance(seen[-1], (Finished, Failed)):
        seen.append(events.get(timeout=WAIT_S))
    return seen


def test_live_checks_go_on_in_the_process_and_the_full_solve_comes_back_usable(tapped):
    cell, base_p_taps = tapped
    solver = SolverProcess(cell.fixture)
    events: queue.Queue = queue.Queue()
    ball_m = cell.truth.ball_diameter_m
    solver.submit(LiveRequest(base_p_taps[:2], ball_m, SAMPLE_BOUND_M), events.put)
    assert events_until_done(events) == [Finished()]  # too few taps: nothing to check
    solver.submit(LiveRequest(base_p_taps, ball_m, SAMPLE_BOUND_M), events.put)
    live = events_until_done(events)
    views = [event for event in live if isinstance(event, LiveView)]
    assert any(isinstance(event, Progress) and event.search is not None for event in live)
    assert [view.refined for view in views] == [False, False, True]  # the first look, the quick and refined checks
    assert views[-1].verdict == "unique"
    assert views[-1].distances_m.shape == (12,) and np.all(np.abs(views[-1].distances_m) < 0.005)
    solver.submit(SolveRequest(base_p_taps, ball_m, SAMPLE_BOUND_M, 1e6), events.put)
    solved = events_until_done(events)
    stages = {event.stage.name for event in solved if isinstance(event, Progress) and event.stage is not None}
    assert {"modes", "bounds", "samples", "intervals"} <= stages
    solution = next(event.solution for event in solved if isinstance(event, Solved))
    assert solution.status == "unique" and solution.contains(cell.truth.base_T_cad)
    assert solution.problem.oracle is cell.fixture.oracle  # the wizard's own, not a copy
    assert len(solution.tree.levels) == 1 and solution.tree.final.low_m.shape[1] == 0
    solver.close()


def test_a_newer_request_supersedes_the_running_one(tapped):
    cell, base_p_taps = tapped
    solver = SolverProcess(cell.fixture)
    first: queue.Queue = queue.Queue()
    second: queue.Queue = queue.Queue()
    solver.submit(SolveRequest(base_p_taps, cell.truth.ball_diameter_m, SAMPLE_BOUND_M, 1e7), first.put)
    solver.submit(LiveRequest(base_p_taps[:3], cell.truth.ball_diameter_m, SAMPLE_BOUND_M), second.put)
    views = [event for event in events_until_done(second) if isinstance(event, LiveView)]
    assert views[-1].tap_count == 3 and views[-1].verdict == "undetermined"
    assert not any(isinstance(event, Solved) for event in list(first.queue))
    solver.close()


def test_a_crashed_worker_is_a_readable_failure_and_the_next_request_gets_a_fresh_one(tapped):
    cell, base_p_taps = tapped
    solver = SolverProcess(cell.fixture)
    events: queue.Queue = queue.Queue()
    solver.submit(SolveRequest(base_p_taps, cell.truth.ball_diameter_m, SAMPLE_BOUND_M, 1e7), events.put)
    crashed = solver.pid
    os.kill(crashed, signal.SIGKILL)
    failed = events_until_done(events)[-1]
    assert isinstance(failed, Failed)
    assert "stopped unexpectedly" in failed.message and "no tap is lost" in failed.message
    solver.submit(LiveRequest(base_p_taps[:3], cell.truth.ball_diameter_m, SAMPLE_BOUND_M), events.put)
    assert isinstance(events_until_done(events)[-1], Finished) and solver.pid != crashed
    solver.close()


def test_stop_ends_the_running_solve_without_an_answer_and_starts_a_fresh_worker(tapped):
    cell, base_p_taps = tapped
    solver = SolverProcess(cell.fixture)
    events: queue.Queue = queue.Queue()
    solver.submit(SolveRequest(base_p_taps, cell.truth.ball_diameter_m, SAMPLE_BOUND_M, 1e7), events.put)
    stopped = solver.pid
    solver.stop()
    assert solver.pid is not None and solver.pid != stopped
    solver.submit(LiveRequest(base_p_taps[:3], cell.truth.ball_diameter_m, SAMPLE_BOUND_M), events.put)
    seen = events_until_done(events)
    assert isinstance(seen[-1], Finished) and not any(isinstance(event, (Solved, Failed)) for event in seen)
    solver.close()


def test_starting_a_worker_and_sending_it_requests_never_waits_for_the_worker():
    """The wizard calls these on its event loop: with a fixture far larger than a pipe's buffer, they return at
    once while the worker is still starting (importing, then reading the fixture)."""
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.05)  # 20480 faces: megabytes of state
    solver = SolverProcess(as_fixture("sphere", sphere))
    events: queue.Queue = queue.Queue()
    began = time.monotonic()
    solver.start()
    solver.cancel()
    solver.submit(LiveRequest(np.zeros((2, 3)), 0.003, SAMPLE_BOUND_M), events.put)
    returned_s = time.monotonic() - began
    assert events_until_done(events) == [Finished()]  # answered once the worker has the fixture
    answered_s = time.monotonic() - began
    assert returned_s < 0.1 * answered_s, (returned_s, answered_s)
    solver.close()


KILLED_MID_REQUEST = """
import os, queue, sys
sys.path.insert(0, {tests!r})
from fixwizard.demo import demo_cell
from fixwizard.workflow.solver_process import Progress, SolveRequest, SolverProcess
from tui_cell import SAMPLE_BOUND_M, spread_taps
if __name__ == "__main__":  # the worker is spawned: it imports this file too
    cell = demo_cell(0)
    cell.connect()
    taps = spread_taps(cell, 12)
    solver = SolverProcess(cell.fixture)
    events = queue.Queue()
    solver.submit(SolveRequest(taps, cell.truth.ball_diameter_m, SAMPLE_BOUND_M, 1e7), events.put)
    while not isinstance(events.get(timeout=300), Progress):
        pass
    print(solver.pid, flush=True)
    os._exit(0)  # as kill -9 ends the wizard: no close, no goodbye to the worker
"""


@pytest.mark.slow
def test_a_worker_whose_wizard_was_killed_mid_request_ends_quietly(tmp_path):
    """Its next progress event finds the pipe closed: it ends without a traceback on the operator's terminal."""
    script = tmp_path / "killed.py"
    script.write_text(KILLED_MID_REQUEST.format(tests=str(Path(__file__).parent)))
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    worker = int(result.stdout.split()[0])  # its stderr is the terminal's: this run ends once the worker has
    assert "Traceback" not in result.stderr and "BrokenPipeError" not in result.stderr, result.stderr
    deadline = time.monotonic() + 30.0  # gone: not left computing for no one
    while running(worker) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not running(worker)


def running(pid: int) -> bool:
    """Whether process ``pid`` exists and has not ended (a zombie waiting to be reaped has)."""
    try:
        return "State:\tZ" not in Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
