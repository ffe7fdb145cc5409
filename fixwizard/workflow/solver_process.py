"""The solver in its own process, one per fixture, so that the wizard's event loop never waits on a solve and a
crash of the solver cannot take the wizard (or a tap) with it.

The worker holds the fixture (its mesh, distance oracle and distance lattice, built once when it starts) and the
latest live check's ``Solution``, so that the check after the next tap goes on from it. ``SolverProcess`` is the
wizard's side: ``submit`` sends a request (``LiveRequest``, ``SolveRequest`` or ``IdentifyRequest``) and returns at
once; a reader thread hands each answer to the request's ``on_event`` as it arrives: ``Progress`` while it works,
its results (``LiveView`` and ``NextTap`` stages, ``Solved`` or ``Identified``), and last ``Finished`` or ``Failed``
(a readable message; also when the process dies). A newer request supersedes the running one, which stops at its
next cancel check (the worker stays, with its fixture and its live check); ``stop`` ends the process at once
(a fresh one starts warm, loading the fixture), ``close`` for good. No call waits on the worker, not even while it
starts: a sender thread writes the fixture and then each request to its pipe. The taps live in the session
journal, never only here.

A full solve's ``Solution`` comes back pickled with only the final level of its search tree, without the per-tap
intervals (the results screen draws the cells; nothing downstream searches on), and with the wizard's own distance
oracle in place of the worker's (``_dumps`` / ``_loads``).
"""

import io
import multiprocessing
import os
import pickle
import queue
import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from multiprocessing.sharedctypes import Synchronized
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from fixwizard.child_process import real_stderr
from fixwizard.errors import FixwizardError, sentence
from fixwizard.fixture import Fixture
from fixwizard.solver.distance_grid import distance_grid_for
from fixwizard.solver.search import SearchCancelled, SearchProgress, SearchTree
from fixwizard.solver.solve import Solution, SolveStage, solve
from fixwizard.solver.warm_up import warm_up_solver
from fixwizard.workflow.identify import IdentifyStep, MeshVerdict, identify
from fixwizard.workflow.live import LiveCheck, LiveView
from fixwizard.workflow.live_pipeline import NextTap, live_pipeline

EXIT_WAIT_S = 1.0  # a terminated worker gets this long before it is killed
NICENESS = 5  # the worker yields the processor to the wizard's event loop (and to the robot's link)
NO_REQUEST = -1


# --- requests (lengths in m, taps (N, 3) in the base frame) ---

@dataclass(frozen=True)
class LiveRequest:
    """The live pipeline for these taps, going on from the worker's last live check when they extend its taps."""

    base_p_taps: np.ndarray
    ball_diameter_m: float
    sample_bound_m: float
    seed: int = 0


@dataclass(frozen=True)
class SolveRequest:
    """The full solve of these taps at ``max_cells``."""

    base_p_taps: np.ndarray
    ball_diameter_m: float
    sample_bound_m: float
    max_cells: float


@dataclass(frozen=True)
class IdentifyRequest:
    """Which of these meshes (path, units) the taps fit (``workflow.identify``); needs no fixture of its own."""

    base_p_taps: np.ndarray
    meshes: list[tuple[Path, str]]
    ball_diameter_m: float
    sample_bound_m: float


Request = LiveRequest | SolveRequest | IdentifyRequest


# --- answers ---

@dataclass(frozen=True)
class Progress:
    """The search finished a level (``search``), a solve entered a phase after its search (``stage``), or
    identify decided a mesh at a budget (``identify``)."""

    search: SearchProgress | None = None
    stage: SolveStage | None = None
    identify: IdentifyStep | None = None


@dataclass(frozen=True)
class Solved:
    solution: Solution


@dataclass(frozen=True)
class Identified:
    verdicts: list[MeshVerdict]


@dataclass(frozen=True)
class Finished:
    """The request has given all its answers."""


@dataclass(frozen=True)
class Failed:
    """The request failed: ``message`` says why and what to do (the operator's problem, or the solver's)."""

    message: str


Event = Progress | LiveView | NextTap | Solved | Identified | Finished | Failed
OnEvent = Callable[[Event], None]


# --- the fixture and the solution across the process boundary ---

def _fixture_state(fixture: Fixture) -> dict[str, Any]:
    """The fixture's fields with its mesh as plain arrays (its distance oracle is rebuilt, not pickled)."""
    state = {field.name: getattr(fixture, field.name) for field in fields(fixture)}
    mesh = fixture.mesh
    state["mesh"] = (np.asarray(mesh.vertices), np.asarray(mesh.faces), np.asarray(mesh.face_normals))
    return state


def _fixture_from_state(state: dict[str, Any]) -> Fixture:
    vertices, faces, face_normals = state["mesh"]
    mesh = trimesh.Trimesh(vertices, faces, face_normals=face_normals, process=False)
    return Fixture(**{**state, "mesh": mesh})


ORACLE_ID = "fixture.oracle"


def _dumps(value: object, fixture: Fixture | None) -> bytes:
    """Pickle ``value`` with the fixture's oracle as a reference to the receiver's own."""
    buffer = io.BytesIO()
    pickler = pickle.Pickler(buffer, protocol=pickle.HIGHEST_PROTOCOL)
    oracle = None if fixture is None else fixture.oracle
    pickler.persistent_id = lambda obj: ORACLE_ID if oracle is not None and obj is oracle else None  # type: ignore
    pickler.dump(value)
    return buffer.getvalue()


def _loads(data: bytes, fixture: Fixture | None) -> Any:
    unpickler = pickle.Unpickler(io.BytesIO(data))

    def persistent_load(pid: str) -> object:
        if pid != ORACLE_ID or fixture is None:
            raise pickle.UnpicklingError(f"unknown reference {pid!r}")
        return fixture.oracle

    unpickler.persistent_load = persistent_load  # type: ignore[method-assign]
    return unpickler.load()


def slim_solution(solution: Solution) -> Solution:
    """The solution with only the final level of its search tree and no per-tap intervals: what a report and the
    results screen use (``cells``, ``contains``), a fraction of the size."""
    tree = solution.tree
    if tree is None:
        return solution
    return replace(solution, tree=SearchTree([tree.final.without_intervals()], tree.evaluated, tree.spent))


# --- the worker process ---

class _Cancel(threading.Event):
    """The solver's cancel event for request ``request_id``: set once the wizard has superseded or cancelled it
    (the shared ``current`` request number moved on)."""

    def __init__(self, current: Synchronized, request_id: int) -> None:
        super().__init__()
        self.current = current
        self.request_id = request_id

    def is_set(self) -> bool:
        return super().is_set() or self.current.value != self.request_id


class _Worker:
    """The worker's state: the fixture and the latest live check of its taps."""

    def __init__(self, conn: Connection, current: Synchronized, fixture: Fixture | None) -> None:
        self.conn = conn
        self.current = current
        self.fixture = fixture
        self.live: LiveCheck | None = None

    def send(self, request_id: int, event: Event) -> None:
        self.conn.send_bytes(_dumps((request_id, event), self.fixture))

    def run(self, request_id: int, request: Request) -> None:
        fixture = self.fixture
        cancel = _Cancel(self.current, request_id)
        if cancel.is_set():
            return  # superseded while it waited
        send = lambda event: self.send(request_id, event)  # noqa: E731
        try:
            if isinstance(request, IdentifyRequest):
                verdicts = identify(request.base_p_taps, request.meshes, request.ball_diameter_m,
                                    request.sample_bound_m, cancel=cancel,
                                    progress=lambda step: send(Progress(identify=step)))
                send(Identified(verdicts))
            elif fixture is None:
                raise RuntimeError("a solve was sent to a process without a fixture")
            elif isinstance(request, LiveRequest):
                self._live(fixture, request, cancel, send)
            else:
                solution = solve(fixture, request.base_p_taps, request.ball_diameter_m, request.sample_bound_m,
                                 max_cells=request.max_cells, cancel=cancel,
                                 progress=lambda search: send(Progress(search=search)),
                                 stage=lambda stage: send(Progress(stage=stage)))
                send(Solved(slim_solution(solution)))
        except SearchCancelled:
            return
        except FixwizardError as error:
            send(Failed(sentence(error)))
            return
        except ConnectionError:
            raise  # the pipe to the wizard is gone (``serve`` ends)
        except Exception as error:  # a bug: said in one line, the wizard and the taps go on
            last = traceback.extract_tb(error.__traceback__)[-1]
            send(Failed(f"The solver failed ({type(error).__name__}: {error}, at {Path(last.filename).name}:"
                        f"{last.lineno}); the taps are saved. Tap again or solve again; if it happens again, "
                        "report it with the session file."))
            return
        send(Finished())

    def _live(self, fixture: Fixture, request: LiveRequest, cancel: _Cancel, send: Callable[[Event], None]) -> None:
        for stage in live_pipeline(fixture, request.base_p_taps, request.ball_diameter_m, request.sample_bound_m,
                                   self.live, cancel, progress=lambda search: send(Progress(search=search)),
                                   stage=lambda stage: send(Progress(stage=stage)), seed=request.seed):
            if isinstance(stage, LiveCheck):
                self.live = stage
                send(LiveView.of(stage, fixture))
            else:
                send(stage)


def serve(conn: Connection, current: Synchronized) -> None:
    """The worker process's main: receive the fixture (its state, or None for identify only) and build it and its
    lattice, load the compiled kernels (``warm_up``), then answer requests until the pipe closes."""
    os.nice(NICENESS)
    try:
        fixture_state = pickle.loads(conn.recv_bytes())
    except (EOFError, OSError):
        return
    fixture = None if fixture_state is None else _fixture_from_state(fixture_state)
    if fixture is not None:
        distance_grid_for(fixture.oracle)  # the search's lattice, before the first request needs it
    warm_up_solver()  # the compiled kernels, too (compiled once after installing: half a minute)
    worker = _Worker(conn, current, fixture)
    while True:
        try:
            request_id, request = pickle.loads(conn.recv_bytes())
            worker.run(request_id, request)
        except (EOFError, OSError):  # the pipe closed: the wizard is gone (quit, or killed mid-request)
            return


# --- the wizard's side ---

def _reap(process: BaseProcess) -> None:
    """Wait for a terminated worker; kill it if it has not ended in time."""
    process.join(EXIT_WAIT_S)
    if process.is_alive():
        process.kill()
        process.join(EXIT_WAIT_S)


@dataclass
class _Running:
    """A started worker and the queue of what its sender thread writes to it (the fixture first, then requests;
    ``_END_SENDER`` ends the sender). Only the sender writes to the pipe, so that no caller waits while the worker
    is still starting and not yet reading; its reader thread reads the answers and closes the pipe."""

    process: BaseProcess
    outbox: "queue.SimpleQueue[object]"


_END_SENDER = object()  # queued last: the sender thread ends


def _send_all(conn: Connection, outbox: "queue.SimpleQueue[object]") -> None:
    """The sender thread of one worker: pickle and write each queued message until told to end or the pipe
    closes (the worker died or was ended; the reader says so)."""
    while (message := outbox.get()) is not _END_SENDER:
        try:
            conn.send_bytes(pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL))
        except (OSError, ValueError):
            return


class SolverProcess:
    """The wizard's handle on one worker process for ``fixture`` (None: a worker for identify only). Thread-safe;
    ``on_event`` callbacks run on the reader thread (hand them to the event loop, e.g. ``App.call_from_thread``)."""

    _open: "set[SolverProcess]" = set()

    def __init__(self, fixture: Fixture | None) -> None:
        self.fixture = fixture
        self._context = multiprocessing.get_context("spawn")
        self._current: Synchronized = self._context.Value("q", NO_REQUEST, lock=False)
        self._lock = threading.Lock()
        self._running: _Running | None = None
        self._next_id = 0
        self._on_event: dict[int, OnEvent] = {}
        self._closed = False
        SolverProcess._open.add(self)

    @property
    def latest_request(self) -> int:
        """The id of the request answers go to (``NO_REQUEST`` after ``cancel`` or ``stop``)."""
        return self._current.value

    @property
    def pid(self) -> int | None:
        running = self._running
        return None if running is None else running.process.pid

    def start(self) -> None:
        """Start the worker now (it loads the fixture) unless it runs."""
        with self._lock:
            self._ensure_running()

    def submit(self, request: Request, on_event: OnEvent) -> int:
        """Send ``request``, superseding the running one, and return its id; answers go to ``on_event``."""
        with self._lock:
            if self._closed:
                raise RuntimeError("the solver process is closed")
            running = self._ensure_running()
            request_id = self._next_id = self._next_id + 1
            self._on_event = {request_id: on_event}
            self._current.value = request_id
            running.outbox.put((request_id, request))
            return request_id

    def cancel(self) -> None:
        """Drop the running request's answers; the worker stops it at its next cancel check and stays."""
        with self._lock:
            self._on_event = {}
            self._current.value = NO_REQUEST

    def stop(self) -> None:
        """End the worker at once (terminate, then kill) and start a fresh one, warm for the next request."""
        with self._lock:
            self._end()
            if not self._closed:
                self._ensure_running()

    def close(self) -> None:
        """End the worker for good."""
        with self._lock:
            self._closed = True
            self._end()
        SolverProcess._open.discard(self)

    @classmethod
    def close_all(cls) -> None:
        """End every worker this process started (the wizard does on quit)."""
        for solver in list(cls._open):
            solver.close()

    def _ensure_running(self) -> _Running:
        running = self._running
        if running is not None and running.process.is_alive():
            return running
        if running is not None:
            self._end()
        conn, child_conn = self._context.Pipe()
        process = self._context.Process(target=serve, name="fixwizard-solver", daemon=True,
                                        args=(child_conn, self._current))
        with real_stderr():
            process.start()
        child_conn.close()
        outbox: queue.SimpleQueue[object] = queue.SimpleQueue()
        outbox.put(None if self.fixture is None else _fixture_state(self.fixture))
        sender = threading.Thread(target=_send_all, args=(conn, outbox), name="fixwizard-solver-sender", daemon=True)
        reader = threading.Thread(target=self._read, args=(process, conn, outbox, sender),
                                  name="fixwizard-solver-reader", daemon=True)
        self._running = _Running(process, outbox)
        sender.start()
        reader.start()
        return self._running

    def _end(self) -> None:
        """End the running worker (lock held) without waiting for it: terminated now, killed by a reaper thread if
        it has not ended within ``EXIT_WAIT_S``; its reader sees the pipe close, says nothing and closes it."""
        running, self._running = self._running, None
        self._on_event = {}
        self._current.value = NO_REQUEST
        if running is None:
            return
        running.outbox.put(_END_SENDER)
        running.process.terminate()
        threading.Thread(target=_reap, args=(running.process,), name="fixwizard-solver-reaper", daemon=True).start()

    def _read(self, process: BaseProcess, conn: Connection, outbox: "queue.SimpleQueue[object]",
              sender: threading.Thread) -> None:
        """The reader thread of one worker: each answer to its request's ``on_event``; a death is said as a Failed.
        Once the worker has ended, it ends the sender and closes the pipe (only then: a descriptor closed under
        another thread's read or write could be reused by the next worker's pipe)."""
        while True:
            try:
                request_id, event = _loads(conn.recv_bytes(), self.fixture)
            except (EOFError, OSError):
                break
            on_event = self._on_event.get(request_id)
            if on_event is not None:
                on_event(event)
        outbox.put(_END_SENDER)
        sender.join()
        conn.close()
        with self._lock:
            if self._running is None or self._running.process is not process:
                return  # stopped on purpose
            process.join(EXIT_WAIT_S)
            pending = self._on_event
            self._on_event = {}
            self._running = None
        for on_event in pending.values():
            on_event(Failed(f"The solver stopped unexpectedly (exit code {process.exitcode}); no tap is lost, they "
                            "are saved in the session. It starts again with the next check or solve."))

