"""A Universal Robots arm (e-Series or CB3) through ur_rtde 1.6, safe with a person beside it.

``URRobot`` lives in the wizard's process and owns no ur_rtde client: it is a proxy to a link process
(``fixwizard.robot.ur_link``) that owns them all, started by ``connect`` and ended (killed if need be) on
``close``, on a fault or on the next ``connect``. A native crash, a hang or a GIL-holding constructor there
cannot freeze or kill the wizard: every command has a deadline, and a link process that dies, stalls or
misses its deadline is killed and reported as ``LinkLost``.

Safety lives on the controller (``fixwizard.robot.ur_script``): every motion is a program whose first
statement arms the RTDE watchdog, and a tap's travel, speed and force limits (a move's travel and force) are
the program's own, so a PC that stalls, crashes or loses the link cannot take a tap past its travel limit or
press harder than a limit, and the arm stops at most ``WATCHDOG_PERIODS / watchdog_hz`` s after the link's last
message. An error about a lost link is raised only once that time (plus ``WATCHDOG_MARGIN_S``) has passed since
the link process's last watchdog kick, so nothing moves after the operator sees it: by the call that found the link
lost, and by any call that finds no link while that one waits.

Poses are 4x4 float64 ``base_T_tcp`` transforms of the flange in the robot base frame (m): the programs set
the controller's TCP offset to zero. Speeds m/s, forces N, times s (``time.monotonic``).

Threads: every call may come from a worker thread; ``stop``, ``status`` and ``base_T_tcp`` never wait for a
command and may be called from any thread while a tap or move runs.
"""

import multiprocessing
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from multiprocessing.sharedctypes import Synchronized
from typing import Any

import numpy as np

from fixwizard.child_process import real_stderr
from fixwizard.geometry.se3 import to_ur_pose
from fixwizard.robot.base import (
    MAX_LINEAR_SPEED_M_S,
    ConnectionLost,
    RobotError,
    RobotStatus,
    TapResult,
    check_limit,
    check_move_travel,
    check_tap_request,
)
from fixwizard.robot.ur_errors import LinkLost, unpack_error
from fixwizard.robot.ur_link import DASHBOARD_PORT, PROGRAM_END_TIMEOUT_S, PROGRAM_START_TIMEOUT_S, serve
from fixwizard.robot.ur_script import GO_TIMEOUT_S, RETRACT_SPEED_M_S, SETTLE_TIMEOUT_S
from fixwizard.robot.ur_state import (
    ROBOT_MODE_RUNNING,
    ROBOT_MODE_TEXT,
    ControllerState,
    SharedState,
)

# The watchdog's period, 1 / WATCHDOG_HZ seconds without a message from fixwizard: long enough that a busy PC does
# not stop a tap, short enough that the arm stops within 1 s (below).
WATCHDOG_HZ = 2.0
# A controller checks the watchdog once a period for an update within it, so it fires one to two periods after the
# last kick (a CB3 URSim: 0.5 s on a bare RTDE connection, 1.0 s with I/O and dashboard clients, at 2 Hz).
WATCHDOG_PERIODS = 2
WATCHDOG_MARGIN_S = 0.4  # a controller's cycle and braking, and its scheduling, after the watchdog fired
CONNECT_DEADLINE_S = 10.0  # the link process's start, every port, every client and the first data
COMMAND_DEADLINE_S = 5.0  # a command that does not move (freedrive, unlock)
# a motion's deadline: its own duration plus the longest its program may take to start, to get its go and to end
# when told (each a deadline of the link's own, whose error is the clearer), and a second more
MOTION_SLACK_S = PROGRAM_START_TIMEOUT_S + GO_TIMEOUT_S + PROGRAM_END_TIMEOUT_S + 1.0
LINK_STALE_S = 0.75  # no new sample in the shared state for this long: the link process stalled
LOST_ANSWER_WAIT_S = 0.3  # a link process that saw its connection drop answers with the cause within this
DASHBOARD_STOP_TIMEOUT_S = 1.0
POLL_S = 0.005
LOCK_TIMEOUT_S = 2 * COMMAND_DEADLINE_S
EXIT_WAIT_S = 2.0
# Data gone stale: how long the link process is given to show it is gone (killed, crashed) before the staleness is
# blamed on the network; the watchdog on the controller stops the arm meanwhile either way.
DEAD_LINK_WAIT_S = 0.2
ROTATION_TOLERANCE = 1e-6  # a target's rotation part must be this close to orthonormal


@dataclass
class _LinkProcess:
    """One link process and what the wizard's process shares with it."""

    process: BaseProcess
    conn: Connection
    shared: SharedState
    started_at: float = field(default_factory=time.monotonic)
    connected: bool = False  # its connect came back: until then only ``connect`` asks anything of it

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.conn.close()


class URRobot:
    """A UR arm at ``host`` implementing ``fixwizard.robot.base.Robot``; ``connect`` before anything else.

    Beyond the protocol: ``unlock_protective_stop`` (the dashboard's unlock, allowed 5 s after the stop) and
    ``link_pid`` (the link process). When a tap fails after its contact was recorded, the raised
    ``RobotError`` carries the recorded ``TapResult`` as ``tap_result``; a ``LinkLost`` during a tap says
    whether the tap was recorded.
    """

    def __init__(self, host: str) -> None:
        self.host = host
        self.watchdog_hz = WATCHDOG_HZ  # no parameter: a slower watchdog would let the arm run on longer
        self._context = multiprocessing.get_context("spawn")
        self._link: _LinkProcess | None = None
        self._lock = threading.RLock()
        self._freedrive_run: int | None = None
        self._moving = threading.Event()
        # time.monotonic() by which the watchdog has stopped every program of the links abandoned so far: no error
        # about a lost link is raised before it, from the call that abandoned the link or from any other
        self._stands_by = 0.0
        self._stands_by_lock = threading.Lock()  # two links abandoned at once each raise it, neither lowers it
        # STOP presses, shared with every link process: a motion refuses to start after one pressed since it
        # was asked for (while it waited for the lock or for its program to start)
        self._stop_count: Synchronized = self._context.Value("q", 0, lock=False)

    @property
    def link_pid(self) -> int | None:
        """The link process's id (None when there is none)."""
        link = self._link
        return None if link is None else link.process.pid

    # --- the Robot protocol ---

    def connect(self) -> None:
        """End any link process and start a fresh one connected to the controller, within its deadline."""
        with self._locked("connect"):
            self._end_link()
            self._freedrive_run = None
            shared = SharedState(self._context)
            conn, child_conn = self._context.Pipe()
            process = self._context.Process(target=serve, name="fixwizard-ur-link", daemon=True,
                                            args=(self.host, self.watchdog_hz, child_conn, shared, self._stop_count))
            with real_stderr():
                process.start()
            child_conn.close()
            link = self._link = _LinkProcess(process, conn, shared)
            try:
                self._call(link, "connect", (), CONNECT_DEADLINE_S, " while connecting", watch_state=False)
            except RobotError:
                if self._link is link:  # refused (local control, say): no half-made link that says it still connects
                    self._end_link()
                raise
            link.connected = True

    def close(self) -> None:
        """End fixwizard's program on the robot if one runs, and the link process."""
        with self._locked("close"):
            self._end_link()

    def base_T_tcp(self) -> np.ndarray:
        """Current flange pose (4x4, base frame, m)."""
        return self._live_state(self._live_link("")).base_T_tcp

    def freedrive(self, on: bool, stop_mark: int | None = None) -> None:
        """Let the operator move the arm by hand (teach mode, in a program with its watchdog) or hold it."""
        stop_mark = self._mark(stop_mark)
        with self._locked("switch freedrive"):
            link = self._live_link(" while switching freedrive")
            self._freedrive_run = self._call(link, "freedrive", (on, stop_mark), COMMAND_DEADLINE_S,
                                             " while switching freedrive")

    def tap(self, max_travel_m: float = 0.02, speed_m_s: float = 0.01, force_limit_n: float = 10.0,
            stop_mark: int | None = None, on_contact: Callable[[TapResult], None] | None = None) -> TapResult:
        """Approach along the tool z axis at ``speed_m_s`` (m/s) until the force reaches ``force_limit_n`` (N),
        at most ``max_travel_m`` (m), every limit held by the controller; wait for the contact to settle,
        record the flange pose, retract to the start. ``on_contact``: see ``base.Robot.tap`` (called as the retract
        starts). See the class docstring for ``tap_result``."""
        check_tap_request(max_travel_m, speed_m_s, force_limit_n)
        stop_mark = self._mark(stop_mark)
        with self._locked("tap"), self._motion():
            link = self._live_link(" before the tap")
            self._refuse_in_freedrive()
            deadline_s = max_travel_m / speed_m_s + SETTLE_TIMEOUT_S + 2 * max_travel_m / RETRACT_SPEED_M_S
            try:
                return self._call(link, "tap", (stop_mark, max_travel_m, speed_m_s, force_limit_n),
                                  deadline_s + MOTION_SLACK_S, " during the tap", on_contact=on_contact)
            except ConnectionLost as error:
                raise _with_tap_note(error) from None

    def move_linear(self, base_T_tcp: np.ndarray, speed_m_s: float = 0.05, stop_mark: int | None = None) -> None:
        """Move the flange in a straight line to ``base_T_tcp`` (4x4, base frame, m) at ``speed_m_s`` (m/s), at most
        ``base.MAX_MOVE_TRAVEL_M`` (m) from where it stands; ``MoveBlocked`` (the arm back where it began) if the
        contact force reaches ``base.MOVE_FORCE_LIMIT_N`` on the way. Both limits are held by the controller."""
        check_limit("linear speed", speed_m_s, MAX_LINEAR_SPEED_M_S, "mm/s", 1e3)
        target = _checked_target(base_T_tcp)
        stop_mark = self._mark(stop_mark)
        with self._locked("move"), self._motion():
            link = self._live_link(" before the move")
            self._refuse_in_freedrive()
            distance_m = float(np.linalg.norm(target[:3, 3] - self._live_state(link).base_T_tcp[:3, 3]))
            check_move_travel(distance_m)  # the program holds it too; refused here without sending it
            self._call(link, "move_linear", (stop_mark, [float(value) for value in to_ur_pose(target)], speed_m_s),
                       distance_m / speed_m_s + distance_m / RETRACT_SPEED_M_S + MOTION_SLACK_S, " during the move")

    def status(self) -> RobotStatus:
        """Controller state from the link's latest sample; ``connected=False`` once the link is down or its
        latest sample is older than ``LINK_STALE_S``. Never waits."""
        link = self._link
        state = None if link is None or not link.connected else self._fresh(link)
        if state is None:
            return RobotStatus(False, False, False, False, "disconnected")
        return RobotStatus(True, state.protective_stop, state.emergency_stop, state.program_running,
                           self._mode(state))

    def stop(self) -> None:
        """Stop any motion now, without waiting: the link asks fixwizard's program to stop (a running tap or
        move then raises, and so does one asked for before this STOP that has not started yet), and the
        dashboard's stop is sent from this process too, so the arm stops even if the link process is frozen."""
        self._stop_count.value += 1
        threading.Thread(target=_dashboard_stop, args=(self.host,), name="ur-dashboard-stop", daemon=True).start()

    def stop_count(self) -> int:
        """STOP presses so far (see ``base.Robot.stop_count``)."""
        return int(self._stop_count.value)

    # --- beyond the protocol ---

    def unlock_protective_stop(self) -> None:
        """Unlock a protective stop through the dashboard (the controller allows it 5 s after the stop; look
        at the cause first)."""
        with self._locked("unlock the protective stop"):
            link = self._live_link(" while unlocking the protective stop")
            self._call(link, "unlock_protective_stop", (), COMMAND_DEADLINE_S, " while unlocking the protective stop")

    # --- the link process ---

    def _mark(self, stop_mark: int | None) -> int:
        """The STOP count a motion counts STOPs from: ``stop_mark``, or now."""
        return int(self._stop_count.value) if stop_mark is None else stop_mark

    def _call(self, link: _LinkProcess, command: str, args: tuple, deadline_s: float, context: str,
              watch_state: bool = True, on_contact: Callable[[TapResult], None] | None = None) -> Any:
        """Run ``command`` in the link process and wait for its answer at most ``deadline_s``; a link process
        that dies, stalls (no fresh sample, when ``watch_state``) or misses the deadline is abandoned. A tap's
        contact goes to ``on_contact`` as it arrives; what that raises is raised once the command has answered (the
        link keeps being watched meanwhile)."""
        try:
            link.conn.send((command, args))
        except OSError:
            raise self._abandon(link, f"fixwizard's robot link process is gone{context}") from None
        deadline = time.monotonic() + deadline_s
        step, contact, unsaved = command, None, None
        lost_seen_at = 0.0  # when the link process was first seen to have lost its connection
        while True:
            try:
                ready = link.conn.poll(POLL_S)
                message = link.conn.recv() if ready else None
            except (EOFError, OSError):
                message = None
                ready = True
            if message is not None:
                kind, *payload = message
                if kind == "step":
                    step = payload[0]
                    continue
                if kind == "contact":
                    contact = payload[0]
                    if on_contact is not None:
                        try:
                            on_contact(contact)
                        except Exception as failure:  # raised once the tap has ended, below
                            unsaved = failure
                    continue
                if kind == "done":
                    if unsaved is not None:
                        raise unsaved
                    return payload[0]
                error = unpack_error(*payload)
                if contact is not None and not hasattr(error, "tap_result"):
                    error.tap_result = contact
                if isinstance(error, ConnectionLost):
                    error = self._abandon(link, str(error), getattr(error, "tap_result", None))
                raise _noting_unsaved(error, unsaved)
            problem = None
            ended = f"fixwizard's robot link process ended unexpectedly{context}"
            if ready or not link.process.is_alive():
                link.process.join(EXIT_WAIT_S)  # its pipe closes just before it is gone: wait for its exit code
                problem = f"{ended} ({_exit_text(link.process)})"
            elif watch_state and self._fresh(link) is None:
                if not link.shared.read()[2]:
                    link.process.join(DEAD_LINK_WAIT_S)  # its data stops too where it was killed: say that instead
                    problem = (f"{ended} ({_exit_text(link.process)})" if not link.process.is_alive() else
                               f"no data from the robot for {LINK_STALE_S:g} s{context} (the network dropped, or "
                               "this computer stalled)")
                else:  # the link process saw its connection drop: its answer, coming, names the cause
                    lost_seen_at = lost_seen_at or time.monotonic()
                    if time.monotonic() - lost_seen_at > LOST_ANSWER_WAIT_S:
                        problem = _dropped(link, context)
            elif time.monotonic() > deadline:
                problem = (f"the robot at {self.host} did not answer within {deadline_s:.0f} s{context} while "
                           f"fixwizard was waiting for {step}: check that the controller is running and that "
                           "nothing between this computer and the robot holds the connection")
            if problem is not None:
                raise _noting_unsaved(self._abandon(link, problem, contact), unsaved)

    def _abandon(self, link: _LinkProcess, problem: str, tap_result: TapResult | None = None) -> LinkLost:
        """Kill the link process, send the dashboard's stop, wait until the watchdog has stopped the arm; the
        error to raise for ``problem`` (carrying ``tap_result``, if a tap recorded one)."""
        last_kick_at = self._note_last_kick(link)
        if self._link is link:  # after the time is noted: a call that finds no link waits for it too
            self._link = None
        link.kill()
        threading.Thread(target=_dashboard_stop, args=(self.host,), name="ur-dashboard-stop", daemon=True).start()
        self._until_the_arm_stands()
        link.process.join(EXIT_WAIT_S)
        if not last_kick_at:  # nothing was ever sent that could move the arm
            error = LinkLost(f"{problem}: check that the robot is powered on and reachable, then reconnect")
        else:
            within_s = WATCHDOG_PERIODS / self.watchdog_hz
            error = LinkLost(f"{problem}. The robot's watchdog stopped the arm within {within_s:g} s of fixwizard's "
                             "last message: check the network cable and switch between this computer and the robot, "
                             "then reconnect")
        if tap_result is not None:
            error.tap_result = tap_result
        return error

    def _note_last_kick(self, link: _LinkProcess) -> float:
        """The time of ``link``'s last watchdog kick (0 if none), noted in ``_stands_by``: a program may be running on
        those kicks, and the arm stands once its watchdog fired."""
        _, last_kick_at, _ = link.shared.read()
        if last_kick_at:
            with self._stands_by_lock:
                self._stands_by = max(self._stands_by,
                                      last_kick_at + WATCHDOG_PERIODS / self.watchdog_hz + WATCHDOG_MARGIN_S)
        return last_kick_at

    def _end_link(self) -> None:
        """Close the current link process: ask it to end its program and exit, kill it if it does not."""
        link = self._link
        if link is None:
            return
        self._note_last_kick(link)
        self._link = None
        if link.process.is_alive() and self._fresh(link) is not None:
            try:
                self._call(link, "close", (), COMMAND_DEADLINE_S, " while closing")
            except RobotError:
                pass
            link.process.join(EXIT_WAIT_S)
        link.kill()
        link.process.join(EXIT_WAIT_S)

    def _live_link(self, context: str) -> _LinkProcess:
        """The link process if it runs and its data is fresh; else it is abandoned and ``LinkLost`` raised. A link
        still connecting (in another thread) is left to its connect: a call meanwhile raises ``LinkLost``."""
        link = self._link
        if link is not None and not link.connected:
            self._until_the_arm_stands()  # the link it replaced may have been abandoned a moment ago
            raise LinkLost(f"fixwizard is still connecting to the robot at {self.host}{context}: wait until the "
                           "status line says it is connected, then retry")
        if link is None:
            self._until_the_arm_stands()  # another call may have abandoned the link a moment ago
            raise LinkLost(f"fixwizard is not connected to the robot at {self.host}{context}: reconnect")
        if self._fresh(link) is None:
            raise self._abandon(link, _dropped(link, context) if link.shared.read()[2] else
                                f"no data from the robot{context}")
        return link

    def _until_the_arm_stands(self) -> None:
        """Wait until the watchdog has stopped every program of the links abandoned so far."""
        time.sleep(max(self._stands_by - time.monotonic(), 0.0))

    def _live_state(self, link: _LinkProcess) -> ControllerState:
        state = self._fresh(link)
        if state is None:
            raise self._abandon(link, "no data from the robot")
        return state

    def _fresh(self, link: _LinkProcess) -> ControllerState | None:
        """The latest sample unless the link saw its connection drop, its process ended, or the sample is
        older than ``LINK_STALE_S`` (counted from when it arrived)."""
        state, _, lost = link.shared.read()
        if state is None or lost or not link.process.is_alive():
            return None
        return state if time.monotonic() - state.received_at < LINK_STALE_S else None

    def _mode(self, state: ControllerState) -> str:
        if state.emergency_stop:
            return "emergency stop"
        if state.protective_stop:
            return "protective stop"
        if state.safeguard_stop:
            return "safeguard stop"
        if state.safety_fault:
            return "safety fault"
        if state.robot_mode != ROBOT_MODE_RUNNING:
            return ROBOT_MODE_TEXT.get(state.robot_mode, f"robot mode {state.robot_mode}")
        if state.program_running and state.run_id == self._freedrive_run:
            return "freedrive"
        if self._moving.is_set():
            return "moving"
        if state.program_paused:
            return "program paused"
        return "program running" if state.program_running else "ready"

    # --- helpers ---

    @contextmanager
    def _motion(self) -> Iterator[None]:
        self._moving.set()
        try:
            yield
        finally:
            self._moving.clear()

    def _refuse_in_freedrive(self) -> None:
        if self._freedrive_run is not None:
            raise RobotError("freedrive is on, so the robot cannot move by itself: turn freedrive off, then retry")

    @contextmanager
    def _locked(self, what: str) -> Iterator[None]:
        if not self._lock.acquire(timeout=LOCK_TIMEOUT_S):
            raise RobotError(f"the robot is busy with another command and cannot {what} now: wait, then retry")
        try:
            yield
        finally:
            self._lock.release()


def _checked_target(base_T_tcp: np.ndarray) -> np.ndarray:
    """``base_T_tcp`` as a float 4x4 rigid transform; ``RobotError`` for anything else (NaN, inf, a scaled or
    sheared rotation, a wrong shape)."""
    target = np.asarray(base_T_tcp, dtype=float)
    if target.shape != (4, 4) or not np.all(np.isfinite(target)):
        raise RobotError("the move's target is not a finite 4x4 pose: this is a bug in the step that asked for "
                         "the move; report it")
    rotation = target[:3, :3]
    if (not np.allclose(rotation.T @ rotation, np.eye(3), atol=ROTATION_TOLERANCE)
            or np.linalg.det(rotation) < 0 or not np.allclose(target[3], [0, 0, 0, 1])):
        raise RobotError("the move's target is not a rigid pose (its rotation is not a rotation): this is a bug in "
                         "the step that asked for the move; report it")
    return target


def _noting_unsaved(error: Exception, unsaved: Exception | None) -> Exception:
    """``error``, saying that the contact could not be saved either when ``on_contact`` raised ``unsaved``."""
    if unsaved is not None:
        error.add_note(f"The contact could not be saved either: {unsaved}")
    return error


def _with_tap_note(error: ConnectionLost) -> ConnectionLost:
    """``error`` with a sentence saying whether the tap was recorded."""
    recorded = getattr(error, "tap_result", None)
    note = (" The tap's contact was recorded before the link went down." if recorded is not None
            else " The tap was not recorded: tap that point again after reconnecting.")
    noted = LinkLost(f"{error}.{note}")
    if recorded is not None:
        noted.tap_result = recorded
    return noted


def _dropped(link: _LinkProcess, context: str) -> str:
    """The problem of a ``link`` that saw its connection drop, with the cause it noted."""
    reason = link.shared.lost_reason()
    return f"the link to the robot dropped{context}" + (f" ({reason})" if reason else "")


def _exit_text(process: BaseProcess) -> str:
    code = process.exitcode
    if code is None:
        return "its pipe closed"
    if code < 0:
        return f"killed by {signal.Signals(-code).name}"
    return f"exit code {code}"


def _dashboard_stop(host: str) -> None:
    """Best effort: the dashboard's ``stop`` over a plain socket (no ur_rtde in this process)."""
    try:
        with socket.create_connection((host, DASHBOARD_PORT), timeout=DASHBOARD_STOP_TIMEOUT_S) as dashboard:
            dashboard.settimeout(DASHBOARD_STOP_TIMEOUT_S)
            dashboard.recv(1024)  # the greeting
            dashboard.sendall(b"stop\n")
            dashboard.recv(1024)
    except OSError:
        pass
