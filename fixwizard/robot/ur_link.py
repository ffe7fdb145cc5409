"""The UR link process: the only place fixwizard runs ur_rtde. It owns the dashboard client, the RTDE receive
and RTDE I/O interfaces and the script-port socket, publishes every RTDE sample to ``SharedState``, kicks the
programs' watchdog, and runs one command at a time from the wizard's process (``fixwizard.robot.ur``).

A native crash, a hang or a GIL-holding constructor here can freeze or kill only this process; the wizard sees
the link lost. This process never reconnects: once its RTDE data stops or its connection drops it stops
kicking the watchdog (so the controller ends fixwizard's program and the arm stops) and answers every further
command with ``LinkLost``; the wizard ends it and starts a fresh one to reconnect. ur_rtde's control interface
(which reconnects and re-uploads its own control script by itself) is not used at all: every motion is one of
the programs of ``ur_script``, which arm their watchdog before anything else.

Protocol: the wizard sends ``(command, args)``; this process answers ``("done", value)`` or
``("error", kind, message, tap_result)``, and meanwhile may send ``("step", what)`` (what it waits for now,
for the wizard's timeout message) and ``("contact", TapResult)`` (a tap's contact is recorded).
"""

import math
import os
import random
import re
import socket
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.sharedctypes import Synchronized
from typing import Any

import numpy as np

from fixwizard.robot.base import (
    EmergencyStop,
    MotionStopped,
    MoveBlocked,
    NoContact,
    NotInRemoteControl,
    RobotError,
    TapResult,
    move_too_far,
)
from fixwizard.robot.ur_errors import LinkLost, URProtectiveStop, pack_error
from fixwizard.robot.ur_script import (
    FINAL_PHASES,
    GO_TIMEOUT_S,
    KICK_REGISTER,
    PEAK_FORCE_REGISTER,
    PHASE_BACK_OFF_STOPPED,
    PHASE_BACKING_OFF,
    PHASE_BLOCKED,
    PHASE_DONE,
    PHASE_NO_CONTACT,
    PHASE_NO_GO,
    PHASE_NOT_SETTLED,
    PHASE_REGISTER,
    PHASE_RETURN_BLOCKED,
    PHASE_SETTLED,
    PHASE_STOPPED,
    PHASE_TOO_FAR,
    PHASE_WAITING,
    REQUEST_GO,
    REQUEST_REGISTER,
    REQUEST_RETRACT,
    REQUEST_STOP,
    RETRACT_SPEED_M_S,
    RUN_REGISTER,
    SETTLE_REGISTER,
    SETTLE_TIMEOUT_S,
    TRAVEL_REGISTER,
    freedrive_program,
    move_program,
    request_value,
    setup_program,
    tap_program,
)
from fixwizard.robot.ur_state import (
    ROBOT_MODE_RUNNING,
    ROBOT_MODE_TEXT,
    ControllerState,
    SharedState,
)

DASHBOARD_PORT = 29999
RTDE_PORT = 30004
SCRIPT_PORT = 30003
CONNECT_TIMEOUT_S = 2.0  # each port check, the dashboard and the script-port connection
FIRST_DATA_TIMEOUT_S = 2.0
STALE_STATE_S = 0.5  # no new RTDE sample for this long: the link is down
KICK_PERIOD_S = 0.02
POLL_S = 0.002
PROGRAM_START_TIMEOUT_S = 3.0  # a program sent to the script port must publish its run id by then
PROGRAM_END_TIMEOUT_S = 1.0  # a program asked to stop must have ended by then
MOVE_TOLERANCE_M = 0.001  # a finished move (and a tap's retract) must end this close to its target
TOUCHING_FORCE_FRACTION = 0.5  # refuse a tap above this fraction of its force limit (cannot zero the sensor)
UNLOCK_ACCEPTED = "Protective stop releasing"
IN_USE_REPLY = "already in use"  # ur_rtde's error when the controller gives the RTDE inputs to another client
# The dashboard's "is in remote control" exists from PolyScope 5.6 on; ur_rtde's isInRemoteControl asks it on 5.6 to
# 5.x only and says False without asking on any other (a CB3, which has no local mode, an e-Series before 5.6).
REMOTE_CONTROL_QUERY_SINCE = (5, 6)
DASHBOARD = f"the dashboard server (port {DASHBOARD_PORT})"
RECEIVE_FIELDS = ["timestamp", "actual_TCP_pose", "actual_TCP_speed", "actual_TCP_force", "robot_mode",
                  "safety_mode", "safety_status_bits", "runtime_state", "output_int_register_18",
                  "output_int_register_19", "output_double_register_17", "output_double_register_18",
                  "output_double_register_19"]


def serve(host: str, watchdog_hz: float, conn: Connection, shared: SharedState, stop_count: Synchronized) -> None:
    """The link process's main loop (the ``multiprocessing`` target); it ends with the wizard's process."""
    _exit_with(os.getppid())
    link = Link(host, watchdog_hz, conn, shared, stop_count)
    while True:
        try:
            command, args = conn.recv()
        except (EOFError, OSError):
            os._exit(0)
        try:
            answer: tuple = ("done", getattr(link, command)(*args))
        except RobotError as error:
            answer = ("error", *pack_error(error))
        except Exception as error:  # noqa: BLE001 - a bug: the wizard shows it rather than losing the link silently
            # nothing this link does can be trusted now, and a program of its may still move: it stops kicking, so
            # the controller's watchdog ends that program, and the wizard waits for that before it shows the error
            link._lose(f"a bug while trying to {command} ({error!r})")
            message = (f"fixwizard's robot link failed while trying to {command} ({error!r}; if it happens again, "
                       "report it)")
            answer = ("error", "LinkLost", message, None)
        send_or_leave(conn, answer)
        if command == "close":
            os._exit(0)


def send_or_leave(conn: Connection, message: tuple) -> None:
    """Send ``message`` to the wizard's process; where its end is gone (it died before its parent-watch saw it),
    end this process at once and quietly: its kicks stop, so the watchdog ends any program of it."""
    try:
        conn.send(message)
    except OSError:  # BrokenPipeError, ConnectionResetError
        os._exit(0)


class Link:
    """The ur_rtde clients of one connection and the commands the wizard's process sends (see module doc)."""

    def __init__(self, host: str, watchdog_hz: float, conn: Connection, shared: SharedState,
                 stop_count: Synchronized) -> None:
        self.host = host
        self.watchdog_hz = watchdog_hz
        self._conn = conn
        self._shared = shared
        self._stop_count = stop_count
        self._dashboard: Any = None
        self._receive: Any = None
        self._io: Any = None
        self._script: socket.socket | None = None
        self._io_lock = threading.Lock()
        self._asks_remote_control = True  # whether the dashboard can tell remote from local control (``connect``)
        self._polyscope = ""  # the software version the dashboard said (``connect``)
        self._lost: str | None = None  # why the link is down
        self._lose_lock = threading.Lock()
        self._next_run = random.randrange(1, 1 << 24)
        self._current_run: int | None = None
        self._stop_mark = stop_count.value  # the wizard's STOP count when the current motion was asked for

    # --- commands ---

    def connect(self) -> None:
        """Open every client, wait for the first RTDE data; stop a program left running or paused (an earlier
        link's, before its watchdog fired or paused on the pendant as its link died, or anyone's) before anything
        else."""
        import dashboard_client
        import rtde_io
        import rtde_receive

        for port in (DASHBOARD_PORT, RTDE_PORT, SCRIPT_PORT):
            self._check_port(port)
        self._step(DASHBOARD)
        self._dashboard = self._open(DASHBOARD, lambda: dashboard_client.DashboardClient(self.host))
        self._open(DASHBOARD, lambda: self._dashboard.connect(int(CONNECT_TIMEOUT_S * 1000)))
        self._polyscope = self._open(DASHBOARD, self._dashboard.polyscopeVersion)
        self._asks_remote_control = _tells_remote_control(self._polyscope)
        if not self._remote_control():
            raise NotInRemoteControl()
        self._step(f"the RTDE data stream (port {RTDE_PORT})")
        self._receive = self._open(f"the RTDE data stream (port {RTDE_PORT})",
                                   lambda: rtde_receive.RTDEReceiveInterface(self.host, -1.0, RECEIVE_FIELDS))
        self._step(f"the RTDE inputs (port {RTDE_PORT})")
        self._io = self._open_inputs(rtde_io.RTDEIOInterface)
        self._step(f"the script port (port {SCRIPT_PORT})")
        self._script = self._open(f"the script port ({SCRIPT_PORT})", lambda: socket.create_connection(
            (self.host, SCRIPT_PORT), timeout=CONNECT_TIMEOUT_S))
        for loop in (self._publish_loop, self._kick_loop, self._stop_loop):
            threading.Thread(target=loop, name=loop.__name__, daemon=True).start()
        self._step("the first RTDE data")
        deadline = time.monotonic() + FIRST_DATA_TIMEOUT_S
        while (state := self._shared.read()[0]) is None:
            if self._lost is not None or time.monotonic() > deadline:
                raise self._link_lost(" while connecting", self._lost or "the controller sent no RTDE data "
                                      f"within {FIRST_DATA_TIMEOUT_S:g} s")
            time.sleep(POLL_S)
        if state.program_running or state.program_paused:  # paused: play would take its motion on
            self._step("stopping the program that was running on the robot")
            self._dashboard_command("stop")
            self._wait(lambda sample: not (sample.program_running or sample.program_paused), PROGRAM_END_TIMEOUT_S,
                       " while connecting")
        if state.ready_to_move:
            self._step(f"fixwizard's set-up program to start (port {SCRIPT_PORT})")
            self._stop_mark = self._stop_count.value
            run_id = self._start(lambda run: setup_program(run, self.watchdog_hz), " while connecting",
                                 "set-up program")
            self._until_ended(run_id, PROGRAM_START_TIMEOUT_S, " while connecting", "the set-up program")

    def tap(self, stop_mark: int, max_travel_m: float, speed_m_s: float, force_limit_n: float) -> TapResult:
        """Run ``ur_script.tap_program`` unless STOP was pressed since the wizard's STOP count was ``stop_mark``;
        the contact is sent as soon as it is recorded."""
        context = " during the tap"
        self._stop_mark = stop_mark
        start = self._ready_state(" before the tap")
        if start.force_n > TOUCHING_FORCE_FRACTION * force_limit_n:
            raise RobotError(f"the tool already pushes on something ({start.force_n:.1f} N) before the tap: "
                             "move it a few millimetres away from the surface, then retry")
        run_id = self._start(lambda run: tap_program(run, self.watchdog_hz, max_travel_m, speed_m_s,
                                                     force_limit_n), context, "tap")
        deadline = time.monotonic() + max_travel_m / speed_m_s + SETTLE_TIMEOUT_S \
            + 2.0 * max_travel_m / RETRACT_SPEED_M_S + 3.0
        result: TapResult | None = None
        try:
            while True:
                state = self._fresh_state(context)
                if state.phase == PHASE_SETTLED and result is None:
                    result = TapResult(state.base_T_tcp, state.travel_m, state.peak_force_n, state.settle_s)
                    send_or_leave(self._conn, ("contact", result))
                    self._request(run_id, REQUEST_RETRACT, unless_stopped=True)
                if not state.program_running:
                    self._current_run = None
                    return self._tap_outcome(state, start, result, max_travel_m)
                if time.monotonic() > deadline:
                    self._end_run(run_id, context)
                    raise RobotError("the tap did not finish in time: set the speed slider on the teach pendant "
                                     "to 100 %, then retry")
                time.sleep(POLL_S)
        except RobotError as error:
            if result is not None:
                error.tap_result = result
            raise

    def move_linear(self, stop_mark: int, target: list[float], speed_m_s: float) -> None:
        """Run ``ur_script.move_program`` to the UR pose ``target`` unless STOP was pressed since the wizard's
        STOP count was ``stop_mark``; check that the flange got there."""
        context = " during the move"
        self._stop_mark = stop_mark
        start = self._ready_state(" before the move")
        distance_m = float(np.linalg.norm(np.asarray(target[:3]) - start.base_T_tcp[:3, 3]))
        run_id = self._start(lambda run: move_program(run, self.watchdog_hz, target, speed_m_s), context, "move")
        # there, or partway and back (blocked)
        duration_s = distance_m / speed_m_s + distance_m / RETRACT_SPEED_M_S
        state = self._until_ended(run_id, duration_s + 3.0, context, "the move")
        if _way_back_blocked(state, self._stop_requested()):  # a STOP may have cut its back-off short
            raise _return_blocked("move", state)
        if state.phase == PHASE_STOPPED or self._stop_requested():
            raise MotionStopped("move")
        if state.phase == PHASE_TOO_FAR:  # the program refused it on the controller
            raise move_too_far(distance_m)
        if state.phase == PHASE_BLOCKED:
            raise MoveBlocked(state.peak_force_n)
        if state.phase != PHASE_DONE:
            raise self._diagnose(context, state)
        remaining_m = float(np.linalg.norm(np.asarray(target[:3]) - state.base_T_tcp[:3, 3]))
        if remaining_m > MOVE_TOLERANCE_M:
            raise RobotError(f"the move ended {remaining_m * 1e3:.1f} mm short of its target: check that the path "
                             "is free, then retry")

    def freedrive(self, on: bool, stop_mark: int) -> int | None:
        """Start ``ur_script.freedrive_program`` (its run id) unless STOP was pressed since the wizard's STOP count
        was ``stop_mark``, or end it (None)."""
        if on:
            state = self._fresh_state("")
            if state.program_running and self._current_run is not None and state.run_id == self._current_run:
                return self._current_run
            self._stop_mark = stop_mark
            self._ready_state(" while switching freedrive on")
            return self._start(lambda run: freedrive_program(run, self.watchdog_hz), " while switching freedrive on",
                               "freedrive")
        if self._current_run is not None:
            self._end_run(self._current_run, " while switching freedrive off")
        return None

    def unlock_protective_stop(self) -> None:
        """The dashboard's unlock (the controller allows it 5 s after the stop)."""
        replies = [self._dashboard_command(command) for command in ("close safety popup", "unlock protective stop")]
        if replies[-1] != UNLOCK_ACCEPTED:
            raise RobotError(f"the controller did not unlock the protective stop ({replies[-1]!r}): wait 5 s after "
                             "the stop, or unlock it on the teach pendant, then retry")
        self._wait(lambda state: not state.protective_stop, 1.0, " while unlocking")

    def close(self) -> None:
        """End fixwizard's program if one runs (the process exits after answering)."""
        if self._current_run is not None and self._lost is None:
            try:
                self._end_run(self._current_run, " while closing")
            except RobotError:
                pass

    # --- programs ---

    def _start(self, program_for: Callable[[int], str], context: str, what: str) -> int:
        """Send the program for a new run id, wait until it runs (its watchdog is armed by then) and give it the go
        (only this run gets it: one the controller starts after this gave up on it never moves); ``MotionStopped``
        (``what`` was stopped) if STOP was pressed since ``_stop_mark``. A STOP pressed later reaches the run
        through ``_stop_loop``, which the program heeds before it moves."""
        if not self._remote_control():
            raise NotInRemoteControl()
        run_id = self._new_run_id(self._fresh_state(context).run_id)
        program = program_for(run_id)  # refuses limits beyond the safe ranges before anything is asked of the robot
        self._request(run_id, 0)
        self._current_run = run_id
        if self._stop_requested():
            self._current_run = None
            raise MotionStopped(what)
        try:
            assert self._script is not None, "connect opens the script port first"
            self._script.sendall(program.encode())
        except OSError as error:
            raise self._link_lost(context, f"sending fixwizard's program to port {SCRIPT_PORT} failed "
                                  f"({error.strerror or error})") from error
        deadline = time.monotonic() + PROGRAM_START_TIMEOUT_S
        while (state := self._fresh_state(context)).run_id != run_id:
            if time.monotonic() > deadline:
                self._current_run = None
                self._request(run_id, REQUEST_STOP)  # should the controller start it after all, it ends at once
                if state.ready_to_move:
                    local = (", or the pendant in local control, which PolyScope before 5.6 cannot tell fixwizard: "
                             "switch it to remote control" if _unasked_local_control(self._polyscope) else "")
                    raise RobotError(f"the controller took fixwizard's program on port {SCRIPT_PORT} but did not "
                                     f"start it within {PROGRAM_START_TIMEOUT_S:g} s{context}: check the teach "
                                     f"pendant for a message (a program loaded there, a URCap holding the "
                                     f"arm{local}), then retry")
                raise self._diagnose(context, state)
            time.sleep(POLL_S)
        self._request(run_id, REQUEST_GO, unless_stopped=True)  # a STOP meanwhile: the program ends unmoved
        deadline = time.monotonic() + GO_TIMEOUT_S + PROGRAM_END_TIMEOUT_S
        while (state := self._fresh_state(context)).program_running and state.phase == PHASE_WAITING:
            if time.monotonic() > deadline:
                self._end_run(run_id, context)
                break
            time.sleep(POLL_S)
        if state.phase in (PHASE_WAITING, PHASE_NO_GO):
            self._current_run = None
            raise RobotError(f"fixwizard's {what} started on the robot but did not get fixwizard's go within "
                             f"{GO_TIMEOUT_S:g} s{context} (this computer was too busy to answer), so nothing moved: "
                             "retry")
        return run_id

    def _new_run_id(self, stale_run_id: int) -> int:
        """The next run id, never ``stale_run_id`` (the run register's value now: an earlier link's last run, whose
        id this link's random first one may equal). ``_start`` takes the register showing its run id for its
        program running, so a match there would give the go to a program that had not started yet while this link
        took the stale run's end for its own."""
        run_id = self._next_run
        if run_id == stale_run_id:
            run_id = run_id % (1 << 24) + 1
        self._next_run = run_id % (1 << 24) + 1
        return run_id

    def _until_ended(self, run_id: int, timeout_s: float, context: str, what: str) -> ControllerState:
        """Wait for run ``run_id`` to end; asks it to stop (and raises) after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while (state := self._fresh_state(context)).program_running:
            if time.monotonic() > deadline:
                self._end_run(run_id, context)
                raise RobotError(f"{what} did not finish in time: set the speed slider on the teach pendant to "
                                 "100 %, then retry")
            time.sleep(POLL_S)
        self._current_run = None
        return state

    def _end_run(self, run_id: int, context: str) -> None:
        """Ask the run to stop; the dashboard's stop if it still runs after ``PROGRAM_END_TIMEOUT_S``."""
        self._request(run_id, REQUEST_STOP)
        deadline = time.monotonic() + PROGRAM_END_TIMEOUT_S
        while self._fresh_state(context).program_running:
            if time.monotonic() > deadline:
                self._dashboard_command("stop")
                self._wait(lambda state: not state.program_running, PROGRAM_END_TIMEOUT_S, context)
                break
            time.sleep(POLL_S)
        self._current_run = None

    def _tap_outcome(self, state: ControllerState, start: ControllerState, result: TapResult | None,
                     max_travel_m: float) -> TapResult:
        """The recorded contact if the tap program ended well, else the error that says why not."""
        phase = state.phase
        if phase == PHASE_DONE and result is not None:
            remaining_m = float(np.linalg.norm(state.base_T_tcp[:3, 3] - start.base_T_tcp[:3, 3]))
            if remaining_m > MOVE_TOLERANCE_M:
                raise RobotError(f"the retract after the tap ended {remaining_m * 1e3:.1f} mm short of the start; "
                                 "the contact was recorded: check that the path is free, then go on")
            return result
        if phase == PHASE_NO_CONTACT:
            raise NoContact(max_travel_m)
        if _way_back_blocked(state, self._stop_requested()):
            raise _return_blocked("tap", state, recorded=result is not None)
        if phase == PHASE_STOPPED or (self._stop_requested() and phase not in FINAL_PHASES):
            if result is None:
                raise MotionStopped("tap")
            raise RobotError("the retract after the tap was stopped on request; the contact was recorded: check "
                             "the cell, then go on")
        if phase == PHASE_NOT_SETTLED:
            raise RobotError(f"the contact did not settle within {SETTLE_TIMEOUT_S:g} s: check that the fixture and "
                             "the tool are tight, then retry")
        raise self._diagnose(" during the tap", state)

    # --- state ---

    def _fresh_state(self, context: str) -> ControllerState:
        """The latest sample; ``LinkLost`` once the link is down. A paused program while one of fixwizard's runs
        is stopped first (play would take its motion on after the error), and the error says so."""
        state = self._shared.read()[0]
        if self._lost is not None or state is None:
            raise self._link_lost(context, self._lost or "no RTDE data")
        if state.program_paused and self._current_run is not None:
            self._current_run = None
            self._dashboard_command("stop")
            self._wait(lambda sample: not (sample.program_paused or sample.program_running), PROGRAM_END_TIMEOUT_S,
                       context)
            raise RobotError(f"fixwizard's program on the robot was paused{context} (pause on the teach pendant, or "
                             "the dashboard's pause): fixwizard stopped it, so play does not take its motion on: "
                             "check the cell, then retry")
        return state

    def _ready_state(self, context: str) -> ControllerState:
        """The latest sample if the arm may move now (no stop, powered, brakes released), else the cause."""
        state = self._fresh_state(context)
        if not state.ready_to_move:
            raise self._diagnose(context, state)
        if state.program_running:
            raise RobotError(f"a program is running on the robot{context} (freedrive, or one started on the teach "
                             "pendant): turn freedrive off or stop that program, then retry")
        return state

    def _wait(self, condition: Callable[[ControllerState], bool], timeout_s: float, context: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition(state := self._fresh_state(context)):
            if time.monotonic() > deadline:
                raise self._diagnose(context, state)
            time.sleep(POLL_S)

    def _diagnose(self, context: str, state: ControllerState) -> RobotError:
        """The typed error that explains why the controller did not do what was asked; one that ended the program
        as its way back backed off from what it met says so (the arm may still press on it)."""
        if state.phase == PHASE_BACKING_OFF:
            context += (f" as the arm backed off from something it met on its way back ({state.peak_force_n:.0f} N), "
                        "so it may still press on it")
        if state.emergency_stop:
            return EmergencyStop()
        if state.protective_stop:
            return URProtectiveStop(context)
        if state.safeguard_stop:
            return RobotError(f"a safeguard stop (a door, light curtain or enabling device) stopped the arm{context}: "
                              "clear the cell and reset the safeguard, then retry")
        if state.safety_fault:
            return RobotError(f"the controller reports a safety fault{context}: read the message on the teach "
                              "pendant, restart the controller if it says so, then reconnect")
        if not self._in_remote_control():
            return NotInRemoteControl()
        if state.robot_mode != ROBOT_MODE_RUNNING:
            mode = ROBOT_MODE_TEXT.get(state.robot_mode, f"in robot mode {state.robot_mode}")
            return RobotError(f"the arm is {mode}{context}: power it on and release the brakes on the teach "
                              "pendant, then retry")
        return RobotError(f"fixwizard's program on the robot ended{context} without finishing (someone pressed "
                          "stop on the teach pendant, or the controller ended it): check the teach pendant for a "
                          "message, then retry")

    def _remote_control(self) -> bool:
        """Whether the controller takes programs from outside, as far as its dashboard can tell: one that cannot
        (before PolyScope 5.6) is taken to (a CB3 always does; an e-Series in local control then runs no program,
        and the error says it did not start it)."""
        return not self._asks_remote_control or bool(self._open(DASHBOARD, self._dashboard.isInRemoteControl))

    def _in_remote_control(self) -> bool:
        try:
            return not self._asks_remote_control or bool(self._dashboard.isInRemoteControl())
        except RuntimeError:
            return True  # unknown: the caller reports the other causes

    # --- link ---

    def _link_lost(self, context: str, reason: str) -> LinkLost:
        self._lose(reason)
        return LinkLost(f"the link to the robot is down{context}: {reason}")

    def _lose(self, reason: str) -> None:
        """Note the first reason the link went down (from any of its threads) and tell the wizard's process."""
        with self._lose_lock:
            if self._lost is None:
                self._lost = reason
                self._shared.lose(reason)

    def _publish_loop(self) -> None:
        """Publish every new RTDE sample; the link is lost once the stream closes, goes quiet or sends a value that
        is not a finite number (nothing of such a sample is published: no NaN pose, force or tap result), or once
        this process itself did not run for as long as the stream may go quiet (the watchdog may have fired)."""
        receive = self._receive
        last_timestamp, last_at = None, time.monotonic()
        looked_at = last_at
        while self._lost is None:
            try:
                connected = receive.isConnected()
                timestamp = receive.getTimestamp()
                now = time.monotonic()
                if now - looked_at > STALE_STATE_S:  # this process did not run: nothing said the controller is quiet
                    self._lose(f"this computer stalled: fixwizard's robot link did not run for {now - looked_at:.1f} s")
                    return
                looked_at = now
                if not connected:
                    self._lose("the controller closed the RTDE connection")
                    return
                if timestamp != last_timestamp:
                    last_timestamp, last_at = timestamp, now
                    sample = self._sample(receive, now)
                    if garbled := [name for name, value in sample.items() if not math.isfinite(value)]:
                        self._lose(f"the controller's RTDE data holds a value that is not a number ({garbled[0]})")
                        return
                    self._shared.publish(sample)
                elif now - last_at > STALE_STATE_S:
                    self._lose(f"no RTDE data from the controller for {STALE_STATE_S:g} s")
                    return
            except Exception as error:  # noqa: BLE001 - any failure here means no trustworthy data
                self._lose(f"reading the RTDE data failed ({error})")
                return
            time.sleep(POLL_S)

    @staticmethod
    def _sample(receive: Any, now: float) -> dict[str, float]:
        pose = receive.getActualTCPPose()
        return {"received_at": now, "timestamp": receive.getTimestamp(),
                **dict(zip(("x", "y", "z", "rx", "ry", "rz"), pose, strict=True)),
                "speed_m_s": float(np.linalg.norm(receive.getActualTCPSpeed()[:3])),
                "force_n": float(np.linalg.norm(receive.getActualTCPForce()[:3])),
                "robot_mode": receive.getRobotMode(), "safety_mode": receive.getSafetyMode(),
                "safety_status_bits": receive.getSafetyStatusBits(), "runtime_state": receive.getRuntimeState(),
                "run_id": receive.getOutputIntRegister(RUN_REGISTER),
                "phase": receive.getOutputIntRegister(PHASE_REGISTER),
                "travel_m": receive.getOutputDoubleRegister(TRAVEL_REGISTER),
                "peak_force_n": receive.getOutputDoubleRegister(PEAK_FORCE_REGISTER),
                "settle_s": receive.getOutputDoubleRegister(SETTLE_REGISTER)}

    def _kick_loop(self) -> None:
        """Rewrite the kick register until the link is lost; publish when it was last written."""
        count = 0
        while self._lost is None:
            try:
                with self._io_lock:
                    self._write_input(KICK_REGISTER, count)
            except Exception as error:  # noqa: BLE001 - no more kicks: the watchdog stops the arm
                self._lose(f"writing to the controller failed ({error})")
                return
            self._shared.publish({"last_kick_at": time.monotonic()})
            count = (count + 1) % (1 << 31)
            time.sleep(KICK_PERIOD_S)

    def _stop_loop(self) -> None:
        """Turn the wizard's STOP (a counter it bumps) into the running program's stop request."""
        seen = self._stop_count.value
        while self._lost is None:
            if self._stop_count.value != seen:
                seen = self._stop_count.value
                run_id = self._current_run
                if run_id is not None:
                    try:
                        self._request(run_id, REQUEST_STOP)
                    except RobotError:
                        return
            time.sleep(POLL_S)

    def _stop_requested(self) -> bool:
        """Whether the wizard pressed STOP since the current motion began."""
        return self._stop_count.value != self._stop_mark

    def _request(self, run_id: int, request: int, unless_stopped: bool = False) -> None:
        """Write ``request`` for the run; ``unless_stopped``: not when the wizard pressed STOP since the motion
        began, checked under the lock the STOP's own request is written with, so it never overwrites a STOP."""
        try:
            with self._io_lock:
                if not (unless_stopped and self._stop_requested()):
                    self._write_input(REQUEST_REGISTER, request_value(run_id, request))
        except RuntimeError as error:
            raise self._link_lost("", f"writing to the controller failed ({error})") from error

    def _write_input(self, register: int, value: int) -> None:
        """Write an input integer register; ``RuntimeError`` if it did not go out: ur_rtde raises, or, when a send
        failed and it could not redo it, says so only on stdout and returns False."""
        if not self._io.setInputIntRegister(register, value):
            raise RuntimeError("ur_rtde could not send it")

    def _dashboard_command(self, command: str) -> str:
        """One dashboard command and its reply line."""
        def exchange() -> str:
            self._dashboard.send(f"{command}\n")
            return self._dashboard.receive().strip()
        return self._open(DASHBOARD, exchange)

    def _open(self, what: str, call: Callable[[], Any]) -> Any:
        """``call()``; a ur_rtde failure means the link is down."""
        try:
            return call()
        except RuntimeError as error:
            raise self._link_lost("", f"{what} of {self.host} did not answer ({error})") from error

    def _open_inputs(self, interface: Callable[[str], Any]) -> Any:
        """ur_rtde's RTDE I/O ``interface`` to this controller; a ``RobotError`` that moves nothing if another client
        holds the input registers (the controller refuses them to a second one): the link has sent nothing, so
        the other client's motion is left alone (the dashboard's stop of a lost link would end it)."""
        what = f"the RTDE inputs (port {RTDE_PORT})"
        try:
            return interface(self.host)
        except RuntimeError as error:
            if IN_USE_REPLY in str(error):
                raise RobotError(
                    f"another client holds {what} of {self.host} that fixwizard's programs listen on (input registers "
                    f"{KICK_REGISTER} to 23): another fixwizard or program connected to this robot, a connection "
                    "the robot has not closed yet, or a fieldbus adapter (EtherNet/IP, PROFINET, MODBUS) configured "
                    "on it: close that fixwizard or program, or wait a few seconds, then reconnect") from error
            raise self._link_lost("", f"{what} of {self.host} did not answer ({error})") from error

    def _check_port(self, port: int) -> None:
        try:
            socket.create_connection((self.host, port), timeout=CONNECT_TIMEOUT_S).close()
        except OSError as error:
            raise LinkLost(f"cannot connect to the robot at {self.host}: port {port} does not accept connections "
                           f"({error.strerror or error})") from error

    def _step(self, what: str) -> None:
        send_or_leave(self._conn, ("step", what))


def _polyscope_version(answer: str) -> tuple[int, int] | None:
    """(major, minor) from a dashboard's answer to ``PolyscopeVersion`` ("URSoftware 5.15.0.1234 (Nov 11 2023)"),
    None if it names no version."""
    found = re.search(r"(\d+)\.(\d+)", answer)
    return None if found is None else (int(found[1]), int(found[2]))


def _tells_remote_control(polyscope_version: str) -> bool:
    """Whether ur_rtde asks a dashboard that answers ``PolyscopeVersion`` with ``polyscope_version`` "is in remote
    control", rather than saying False without asking."""
    version = _polyscope_version(polyscope_version)
    return version is not None and version[0] == REMOTE_CONTROL_QUERY_SINCE[0] and \
        version[1] >= REMOTE_CONTROL_QUERY_SINCE[1]


def _unasked_local_control(polyscope_version: str) -> bool:
    """Whether a dashboard that answers ``PolyscopeVersion`` with ``polyscope_version`` belongs to an e-Series that
    has local control but cannot be asked about it (PolyScope 5.0 to 5.5): in local control its controller takes a
    program and runs none."""
    version = _polyscope_version(polyscope_version)
    return version is not None and version[0] == REMOTE_CONTROL_QUERY_SINCE[0] and \
        version[1] < REMOTE_CONTROL_QUERY_SINCE[1]


def _way_back_blocked(state: ControllerState, stopped: bool) -> bool:
    """Whether the program that ended in ``state`` met something on its way back and stopped: it backed off, or
    STOP (``stopped``: the wizard pressed it) cut the back-off short, heeded by the program or ending it from
    outside (the dashboard's stop) while it backed off."""
    return state.phase in (PHASE_RETURN_BLOCKED, PHASE_BACK_OFF_STOPPED) or (state.phase == PHASE_BACKING_OFF
                                                                            and stopped)


def _return_blocked(motion: str, state: ControllerState, recorded: bool = False) -> RobotError:
    """The error of a ``motion`` (tap, move) whose way back met something and stopped (``state``: its end, as
    ``_way_back_blocked`` takes it), saying whether it backed off a few millimetres or STOP cut that short (the arm
    may then still press on what it met), and whether a tap's contact was ``recorded``."""
    kept = "; the contact was recorded" if recorded else ""
    met = f"the arm met something on its way back to where the {motion} began ({state.peak_force_n:.0f} N)"
    ended = ", stopped and backed off a few millimetres the way it came" if state.phase == PHASE_RETURN_BLOCKED \
        else " and stopped; STOP halted it while it backed off, so it may still press on what it met"
    return RobotError(f"{met}{ended}{kept}: look at what it met, turn freedrive on and move the arm clear by hand, "
                      "then retry")


def _exit_with(parent_pid: int) -> None:
    """End this process as soon as the wizard's process is gone."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(0.2)
        os._exit(0)

    threading.Thread(target=watch, name="ur-link-parent-watch", daemon=True).start()
