"""A Universal Robots arm (e-Series or CB3) through ur_rtde 1.6: RTDE receive for state, RTDE control with
ur_rtde's uploaded control script for motion, the dashboard server for remote control and protective stops.

Poses are 4x4 float64 ``base_T_tcp`` transforms of the flange in the robot base frame (m): fixwizard sets
the controller's TCP offset to zero, so the controller's TCP is the flange. Speeds m/s, forces N, times s.

Safety: the RTDE watchdog stops the control program (and so the arm) when fixwizard stops sending for
``1 / watchdog_hz`` seconds, so a crashed PC or a dropped SSH session stops the robot. A tap runs in force
mode with the approach speed limited along the tool axis; fixwizard ends it at the force threshold or at the
travel limit, which it checks every few milliseconds (a software limit: the safety-rated limits are the
controller's safety configuration).

Threads: every call may come from a worker thread; ``stop``, ``status`` and ``base_T_tcp`` may be called
from another thread while a tap or move runs. ur_rtde commands run on one helper thread with a timeout, so
a lost link raises ``ConnectionLost`` instead of hanging. ur_rtde's constructors hold the GIL while they
wait for the controller, so ``connect`` first checks that the controller's ports answer.
"""

import queue
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fixwizard.geometry.se3 import from_ur_pose, to_ur_pose
from fixwizard.robot.base import (
    MAX_LINEAR_SPEED_M_S,
    ConnectionLost,
    EmergencyStop,
    NoContact,
    NotInRemoteControl,
    ProtectiveStop,
    RobotError,
    RobotStatus,
    TapResult,
    check_limit,
    check_tap_request,
)

DASHBOARD_PORT = 29999
RTDE_PORT = 30004
CONNECT_TIMEOUT_S = 3.0  # each port check and the dashboard connection
SCRIPT_START_TIMEOUT_S = 5.0  # the uploaded control script must be running by then
COMMAND_TIMEOUT_S = 5.0  # one ur_rtde command; ur_rtde itself may wait up to 300 s
STALE_STATE_S = 0.5  # no new RTDE state for this long means the link is down
# The arm stops when fixwizard sends nothing for 1 / WATCHDOG_HZ seconds: long enough that a busy PC (the
# wizard redrawing, a solve in the background) does not stop a tap, short enough to stop within 0.5 s.
WATCHDOG_HZ = 2.0
KICK_PERIOD_S = 0.04  # watchdog kicks when idle; a dozen per watchdog period
POLL_S = 0.004  # motion monitoring period
LOCK_TIMEOUT_S = 2 * COMMAND_TIMEOUT_S
LINEAR_ACCELERATION_M_S2 = 0.5
STOP_DECELERATION_M_S2 = 10.0
RETRACT_SPEED_M_S = 0.05
MOVE_TOLERANCE_M = 0.001  # a finished move must end this close to its target
CONTACT_FORCE_FRACTION = 0.5  # contact once the force reaches this fraction of the force limit
TOUCHING_FORCE_FRACTION = 0.5  # refuse to zero the force sensor above this fraction of the force limit
SETTLE_SPEED_M_S = 0.0005  # settled: the flange slower than this ...
SETTLE_WINDOW_S = 0.1  # ... for this long
SETTLE_TIMEOUT_S = 2.0
DIAGNOSE_WAIT_S = 0.1  # how long a failed command waits for its cause to show in the RTDE state
# force mode: compliant along the task frame's z (the tool axis); largest deviation (m, rad) on the others
TAP_SELECTION = [0, 0, 1, 0, 0, 0]
TAP_DEVIATION_M, TAP_DEVIATION_RAD = 0.01, 0.17
FORCE_FRAME_NOT_TRANSFORMED = 2
# controller states (RTDE guide)
RUNTIME_PLAYING = 2
ROBOT_MODE_RUNNING = 7
ROBOT_MODE_TEXT = {-1: "no controller", 0: "disconnected", 1: "confirm safety", 2: "booting", 3: "powered off",
                   4: "powered on", 5: "brakes on", 6: "releasing brakes", 8: "updating firmware"}
SAFETY_PROTECTIVE_STOP_BIT = 2
SAFETY_EMERGENCY_STOP_BIT = 7
UNLOCK_ACCEPTED = "Protective stop releasing"
RECEIVE_FIELDS = ["timestamp", "actual_TCP_pose", "actual_TCP_speed", "actual_TCP_force", "robot_mode",
                  "safety_status_bits", "runtime_state"]


class URProtectiveStop(ProtectiveStop):
    """A protective stop, with UR's recovery: unlock, then fixwizard re-uploads its control script."""

    def __init__(self, context: str = "") -> None:
        RobotError.__init__(self, f"the robot made a protective stop{context}: look at what it hit or what "
                            "stopped it, then unlock the protective stop on the teach pendant (or from fixwizard, "
                            "at least 5 s after the stop); fixwizard then re-uploads its control script, retry")


@dataclass(frozen=True)
class _State:
    """One RTDE state sample: controller time (s), flange pose, speed (m/s) and force (N), modes."""

    timestamp_s: float
    base_T_tcp: np.ndarray
    speed_m_s: float
    force_n: float
    robot_mode: int
    safety_status_bits: int
    runtime_state: int

    @property
    def protective_stop(self) -> bool:
        return bool(self.safety_status_bits >> SAFETY_PROTECTIVE_STOP_BIT & 1)

    @property
    def emergency_stop(self) -> bool:
        return bool(self.safety_status_bits >> SAFETY_EMERGENCY_STOP_BIT & 1)

    @property
    def program_running(self) -> bool:
        return self.runtime_state == RUNTIME_PLAYING


class _Worker:
    """One daemon thread that runs ur_rtde calls in order; a caller waits at most a timeout for its call.
    After a timeout the worker is abandoned (its call may still be blocked inside ur_rtde)."""

    def __init__(self) -> None:
        self._calls: queue.Queue = queue.Queue()
        self._busy = threading.Event()
        threading.Thread(target=self._run, name="ur-rtde-calls", daemon=True).start()

    def call(self, function: Callable[[], Any], timeout_s: float) -> Any:
        """``function()``'s result or exception; ``TimeoutError`` if it takes longer than ``timeout_s``."""
        outcome, done = self.submit(function)
        if not done.wait(timeout_s):
            raise TimeoutError
        if "error" in outcome:
            raise outcome["error"]
        return outcome["value"]

    def submit(self, function: Callable[[], Any]) -> tuple[dict[str, Any], threading.Event]:
        """Queue ``function``; its outcome (``value`` or ``error``) and an event set once it has run."""
        outcome: dict[str, Any] = {}
        done = threading.Event()
        self._calls.put((function, outcome, done))
        return outcome, done

    def idle(self) -> bool:
        return not self._busy.is_set() and self._calls.empty()

    def close(self) -> None:
        self._calls.put(None)

    def _run(self) -> None:
        while (item := self._calls.get()) is not None:
            function, outcome, done = item
            self._busy.set()
            try:
                outcome["value"] = function()
            except Exception as error:  # noqa: BLE001 - handed to the waiting caller
                outcome["error"] = error
            finally:
                self._busy.clear()
                done.set()


@dataclass
class _Link:
    """The open ur_rtde clients of one connection; ``lost`` is set once the link is known to be down."""

    dashboard: Any
    receive: Any
    worker: _Worker = field(default_factory=_Worker)
    control: Any = None
    lost: threading.Event = field(default_factory=threading.Event)
    closing: threading.Event = field(default_factory=threading.Event)
    last_timestamp_s: float = -1.0
    last_fresh_at: float = field(default_factory=time.monotonic)


class URRobot:
    """A UR arm at ``host`` implementing ``fixwizard.robot.base.Robot``; ``connect`` before anything else.

    Beyond the protocol: ``unlock_protective_stop`` (the dashboard's unlock, allowed 5 s after the stop).
    When a tap fails after the contact was recorded (while ending force mode or retracting), the raised
    ``RobotError`` carries the recorded ``TapResult`` as ``tap_result``.
    """

    def __init__(self, host: str, watchdog_hz: float = WATCHDOG_HZ) -> None:
        self.host = host
        self.watchdog_hz = watchdog_hz
        self._link: _Link | None = None
        self._lock = threading.RLock()
        self._freedrive = False
        self._moving = threading.Event()
        self._stop_requested = threading.Event()

    # --- the Robot protocol ---

    def connect(self) -> None:
        """Open (or reopen) the dashboard and RTDE links and start fixwizard's control script. If a stop keeps
        the script from starting, the links stay open (``status`` shows the stop) and its error is raised."""
        import dashboard_client
        import rtde_receive

        with self._locked("connect"):
            self._close_link()
            self._freedrive = False
            for port in (DASHBOARD_PORT, RTDE_PORT):
                self._check_port(port)
            dashboard = dashboard_client.DashboardClient(self.host)
            try:
                dashboard.connect(int(CONNECT_TIMEOUT_S * 1000))
                if not dashboard.isInRemoteControl():
                    raise NotInRemoteControl()
                receive = rtde_receive.RTDEReceiveInterface(self.host, -1.0, RECEIVE_FIELDS)
            except RuntimeError as error:
                _disconnect_quietly(dashboard)
                raise ConnectionLost(f" to {self.host} ({error})") from error
            except RobotError:
                _disconnect_quietly(dashboard)
                raise
            link = self._link = _Link(dashboard, receive)
            threading.Thread(target=self._kick_watchdog, args=(link,), name="ur-watchdog", daemon=True).start()
            self._ensure_program(" while connecting")

    def close(self) -> None:
        """Stop fixwizard's control script and close every link."""
        with self._locked("close"):
            self._close_link()

    def base_T_tcp(self) -> np.ndarray:
        """Current flange pose (4x4, base frame, m)."""
        return self._state(self._live_link()).base_T_tcp

    def freedrive(self, on: bool) -> None:
        """Let the operator move the arm by hand (teach mode) or hold it."""
        with self._locked("switch freedrive"):
            link = self._ready_link(" while switching freedrive")
            control = link.control
            if on:
                self._command(link, "switch freedrive on", control.teachMode)
            else:
                self._command(link, "switch freedrive off", control.endTeachMode)
            self._freedrive = on

    def tap(self, max_travel_m: float = 0.02, speed_m_s: float = 0.01, force_limit_n: float = 10.0) -> TapResult:
        """Approach along the tool z axis in force mode at ``speed_m_s`` (m/s) until the force reaches half of
        ``force_limit_n`` (N), at most ``max_travel_m`` (m); wait for the contact to settle, record the flange
        pose, end force mode and retract to the start. See the class docstring for ``tap_result``."""
        check_tap_request(max_travel_m, speed_m_s, force_limit_n)
        with self._locked("tap"), self._motion():
            link = self._ready_link(" before the tap")
            self._refuse_in_freedrive()
            start = self._state(link)
            if start.force_n > TOUCHING_FORCE_FRACTION * force_limit_n:
                raise RobotError(f"the tool already pushes on something ({start.force_n:.1f} N) before the tap: "
                                 "move it a few millimetres away from the surface, then retry")
            self._command(link, "zero the force sensor", link.control.zeroFtSensor)
            try:
                result = self._approach(link, start.base_T_tcp, max_travel_m, speed_m_s, force_limit_n)
            except BaseException as error:
                self._end_tap_after_failure(link, start.base_T_tcp, error)
                raise
            try:
                self._end_tap(link, start.base_T_tcp)
            except RobotError as error:
                error.tap_result = result
                raise
            return result

    def move_linear(self, base_T_tcp: np.ndarray, speed_m_s: float = 0.05) -> None:
        """Move the flange in a straight line to ``base_T_tcp`` (4x4, base frame, m) at ``speed_m_s`` (m/s)."""
        check_limit("linear speed", speed_m_s, MAX_LINEAR_SPEED_M_S, "mm/s", 1e3)
        with self._locked("move"), self._motion():
            link = self._ready_link(" before the move")
            self._refuse_in_freedrive()
            self._move(link, np.asarray(base_T_tcp, float), speed_m_s, "the move")

    def status(self) -> RobotStatus:
        """Controller state from the RTDE stream; ``connected=False`` when the link is down."""
        link = self._link
        if link is None or link.lost.is_set() or not self._fresh(link):
            return RobotStatus(False, False, False, False, "disconnected")
        state = self._state(link)
        mode = ("emergency stop" if state.emergency_stop else "protective stop" if state.protective_stop
                else ROBOT_MODE_TEXT.get(state.robot_mode, f"robot mode {state.robot_mode}")
                if state.robot_mode != ROBOT_MODE_RUNNING
                else "control script stopped" if not state.program_running
                else "freedrive" if self._freedrive else "moving" if self._moving.is_set() else "ready")
        return RobotStatus(True, state.protective_stop, state.emergency_stop, state.program_running, mode)

    def stop(self) -> None:
        """Stop any motion now: a running tap or move ends (raising ``RobotError``) after stopping the arm.
        Nothing to do when the link is down: the watchdog has stopped the arm."""
        self._stop_requested.set()
        with self._locked("stop"):
            self._stop_requested.clear()
            link = self._link
            if link is not None and self._can_command(link):
                self._stop_arm(link)

    # --- beyond the protocol ---

    def unlock_protective_stop(self) -> None:
        """Unlock a protective stop through the dashboard (the controller allows it 5 s after the stop; look
        at the cause first) and restart fixwizard's control script."""
        with self._locked("unlock the protective stop"):
            link = self._live_link()
            reply = self._call(link, "unlock the protective stop", lambda: _dashboard(link.dashboard, [
                "close safety popup", "unlock protective stop"])[-1])
            if reply != UNLOCK_ACCEPTED:
                raise RobotError(f"the controller did not unlock the protective stop ({reply!r}): wait 5 s after "
                                 "the stop, or unlock it on the teach pendant, then retry")
            self._wait_for(link, lambda state: not state.protective_stop, 1.0, " while unlocking")
            self._ensure_program(" after unlocking")

    # --- the tap ---

    def _approach(self, link: _Link, base_T_start: np.ndarray, max_travel_m: float, speed_m_s: float,
                  force_limit_n: float) -> TapResult:
        """Force mode along the tool axis until the contact settles; ``NoContact`` beyond ``max_travel_m``.

        ur_rtde sends ``forceMode`` without waiting for the controller, and any later command overwrites it
        before the controller's next cycle may have read it, so it is sent every cycle (which also feeds the
        watchdog), as in ur_rtde's force-mode examples."""
        force_mode = (link.control.forceMode, list(to_ur_pose(base_T_start)), TAP_SELECTION,
                      [0.0, 0.0, force_limit_n, 0.0, 0.0, 0.0], FORCE_FRAME_NOT_TRANSFORMED,
                      [TAP_DEVIATION_M, TAP_DEVIATION_M, speed_m_s] + [TAP_DEVIATION_RAD] * 3)
        base_d_tool = base_T_start[:3, 2]
        started = time.monotonic()
        deadline = started + 2.0 * max_travel_m / speed_m_s + 2.0
        peak_force_n, contact_at = 0.0, None
        settled_since = None
        while True:
            state = self._monitor(link, " during the tap")
            self._command(link, "keep force mode", *force_mode, context=" during the tap")
            now = time.monotonic()
            travel_m = float((state.base_T_tcp[:3, 3] - base_T_start[:3, 3]) @ base_d_tool)
            peak_force_n = max(peak_force_n, state.force_n)
            if travel_m > max_travel_m:
                raise NoContact(max_travel_m) if contact_at is None else RobotError(
                    "the surface gave way after the tool touched it: check that the fixture is clamped, then retry")
            if contact_at is None and state.force_n >= CONTACT_FORCE_FRACTION * force_limit_n:
                contact_at = now
            if contact_at is not None:
                settled_since = (settled_since or now) if state.speed_m_s < SETTLE_SPEED_M_S else None
                if settled_since is not None and now - settled_since >= SETTLE_WINDOW_S:
                    return TapResult(state.base_T_tcp, travel_m, peak_force_n, now - contact_at)
                if now - contact_at > SETTLE_TIMEOUT_S:
                    raise RobotError(f"the contact did not settle within {SETTLE_TIMEOUT_S:g} s: check that the "
                                     "fixture and the tool are tight, then retry")
            if now > deadline:
                raise RobotError(f"the tap moved only {travel_m * 1e3:.1f} mm in {now - started:.0f} s: set the "
                                 "speed slider on the teach pendant to 100 %, then retry")
            time.sleep(POLL_S)

    def _end_tap(self, link: _Link, base_T_start: np.ndarray) -> None:
        """End force mode (which also stops the arm) and, unless a stop was requested, retract to the start."""
        self._command(link, "end force mode", link.control.forceModeStop)
        if not self._stop_requested.is_set():
            self._move(link, base_T_start, RETRACT_SPEED_M_S, "retracting after the tap")

    def _end_tap_after_failure(self, link: _Link, base_T_start: np.ndarray, error: BaseException) -> None:
        """``_end_tap`` if the link and the control script still allow it (after a protective stop, emergency
        stop or lost link the controller has already stopped the arm); its failure is added to ``error``."""
        if not self._can_command(link):
            return
        try:
            self._end_tap(link, base_T_start)
        except RobotError as cleanup_error:
            error.add_note(f"Then: {cleanup_error}")

    # --- motion ---

    def _move(self, link: _Link, base_T_target: np.ndarray, speed_m_s: float, what: str) -> None:
        """Asynchronous ``moveL`` watched until the flange is at the target."""
        control = link.control
        distance_m = float(np.linalg.norm(base_T_target[:3, 3] - self._state(link).base_T_tcp[:3, 3]))
        deadline = time.monotonic() + distance_m / speed_m_s + speed_m_s / LINEAR_ACCELERATION_M_S2 + 2.0
        self._command(link, f"start {what}", control.moveL, list(to_ur_pose(base_T_target)), speed_m_s,
                      LINEAR_ACCELERATION_M_S2, True)
        try:
            while True:
                state = self._monitor(link, f" during {what}")
                remaining_m = float(np.linalg.norm(base_T_target[:3, 3] - state.base_T_tcp[:3, 3]))
                # the control interface has its own RTDE stream: the move counts as done once the arm stands
                if control.getAsyncOperationProgress() < 0 and state.speed_m_s < SETTLE_SPEED_M_S:
                    if remaining_m > MOVE_TOLERANCE_M:
                        raise RobotError(f"{what} ended {remaining_m * 1e3:.1f} mm short of its target: check "
                                         "that the path is free, then retry")
                    return
                if time.monotonic() > deadline:
                    raise RobotError(f"{what} did not finish in time: set the speed slider on the teach pendant "
                                     "to 100 %, then retry")
                self._command(link, "feed the watchdog", control.kickWatchdog, context=f" during {what}")
                time.sleep(POLL_S)
        except BaseException:
            self._halt_quietly(link)
            raise

    def _halt_quietly(self, link: _Link) -> None:
        """Stop the arm if the controller still takes commands; failures are left to the caller's error."""
        if self._can_command(link):
            try:
                self._stop_arm(link)
            except RobotError:
                pass

    def _stop_arm(self, link: _Link) -> None:
        """``stopL`` (ur_rtde returns nothing for it, so success shows as the arm standing still)."""
        self._call(link, "stop the arm", lambda: link.control.stopL(STOP_DECELERATION_M_S2))

    def _can_command(self, link: _Link) -> bool:
        return (link.control is not None and not link.lost.is_set() and self._fresh(link)
                and self._state(link).program_running)

    def _monitor(self, link: _Link, context: str) -> _State:
        """A fresh state sample; raises if the link is down, a stop or a stop request interrupted the motion."""
        if not self._fresh(link):
            raise self._lose(link, context)
        state = self._state(link)
        if self._stop_requested.is_set():
            raise RobotError(f"the motion was stopped on request{context}: retry when ready")
        if state.emergency_stop or state.protective_stop or not state.program_running:
            raise self._diagnose(link, context)
        return state

    @contextmanager
    def _motion(self) -> Iterator[None]:
        self._stop_requested.clear()
        self._moving.set()
        try:
            yield
        finally:
            self._moving.clear()

    def _refuse_in_freedrive(self) -> None:
        if self._freedrive:
            raise RobotError("freedrive is on, so the robot cannot move by itself: turn freedrive off, then retry")

    # --- link, control script and state ---

    def _ready_link(self, context: str) -> _Link:
        """The live link with the control script running (started or re-uploaded if needed)."""
        link = self._live_link()
        self._ensure_program(context)
        return link

    def _live_link(self) -> _Link:
        link = self._link
        if link is None:
            raise ConnectionLost(f" (fixwizard is not connected to {self.host})")
        if link.lost.is_set():
            raise ConnectionLost(" earlier")
        if not self._fresh(link):
            raise self._lose(link, "")
        return link

    def _ensure_program(self, context: str) -> None:
        """Start fixwizard's control script unless it runs: a protective stop, emergency stop, the watchdog
        or the dashboard's stop end it. Then zero the TCP offset and set the watchdog."""
        link = self._live_link()
        state = self._state(link)
        if state.program_running and link.control is not None:
            return
        if (state.emergency_stop or state.protective_stop or state.robot_mode != ROBOT_MODE_RUNNING
                or not self._in_remote_control(link)):
            raise self._diagnose(link, context)
        self._freedrive = False
        if link.control is None:
            import rtde_control

            link.control = self._call(link, "start the control script",
                                      lambda: rtde_control.RTDEControlInterface(self.host),
                                      COMMAND_TIMEOUT_S + SCRIPT_START_TIMEOUT_S)
        else:
            # The new script would first run the last command left in input_int_register_0 (after a stop in a
            # tap: force mode, with the old parameters). A command that finds the script stopped makes ur_rtde
            # clear that register (and returns False, expected here), so send one before re-uploading.
            self._call(link, "clear the command register", link.control.kickWatchdog)
            self._command(link, "re-upload the control script", link.control.reuploadScript)
        self._wait_for(link, lambda sample: sample.program_running, SCRIPT_START_TIMEOUT_S, context)
        self._setup_command(link, "zero the TCP offset", link.control.setTcp, [0.0] * 6)
        self._setup_command(link, "set the RTDE watchdog", link.control.setWatchdog, self.watchdog_hz)

    def _setup_command(self, link: _Link, what: str, command: Callable[..., bool], *args: Any) -> None:
        """An idempotent set-up command right after the script started: a script that runs but does not take
        commands yet (a busy controller) answers ``False`` for a moment, so retry while it keeps running."""
        deadline = time.monotonic() + SCRIPT_START_TIMEOUT_S
        while not self._call(link, what, lambda: command(*args)):
            if not self._state(link).program_running or time.monotonic() > deadline:
                raise self._diagnose(link, f" while trying to {what}")
            time.sleep(POLL_S)

    def _wait_for(self, link: _Link, condition: Callable[[_State], bool], timeout_s: float, context: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition(self._state(link)):
            if not self._fresh(link):
                raise self._lose(link, context)
            if time.monotonic() > deadline:
                raise self._diagnose(link, context)
            time.sleep(POLL_S)

    def _command(self, link: _Link, what: str, command: Callable[..., bool], *args: Any,
                 context: str | None = None) -> None:
        """Run a ur_rtde control command; its ``False`` (how ur_rtde reports failure) raises the cause, told
        as happening ``context`` (default: while trying to do ``what``)."""
        if not self._call(link, what, lambda: command(*args), context=context):
            raise self._diagnose(link, f" while trying to {what}" if context is None else context)

    def _call(self, link: _Link, what: str, function: Callable[[], Any], timeout_s: float = COMMAND_TIMEOUT_S,
              context: str | None = None) -> Any:
        """``function()`` on the link's worker; a timeout or a ur_rtde exception raises a ``RobotError`` told as
        happening ``context`` (default: while trying to do ``what``)."""
        if link.lost.is_set():
            raise ConnectionLost(" earlier")
        told = f" while trying to {what}" if context is None else context
        try:
            return link.worker.call(function, timeout_s)
        except TimeoutError:
            raise self._lose(link, f"{told} (no answer within {timeout_s:g} s)") from None
        except RuntimeError as error:
            if "remote control" in str(error):
                raise NotInRemoteControl() from error
            if "connect" in str(error).lower():  # ur_rtde's own reconnect failed: e.g. "Timeout connecting to ..."
                raise self._lose(link, f"{told} ({error})") from error
            raise self._diagnose(link, f"{told} ({error})") from error

    def _diagnose(self, link: _Link, context: str) -> RobotError:
        """The typed error that explains why the controller did not do what was asked. The control interface
        has its own RTDE stream, so a stop it saw may take a few cycles to show in the state: wait for it."""
        deadline = time.monotonic() + DIAGNOSE_WAIT_S
        while True:
            if link.lost.is_set() or not self._fresh(link):
                return self._lose(link, context)
            state = self._state(link)
            if state.emergency_stop or state.protective_stop or time.monotonic() > deadline:
                break
            time.sleep(POLL_S)
        if state.emergency_stop:
            return EmergencyStop()
        if state.protective_stop:
            return URProtectiveStop(context)
        if not self._in_remote_control(link):
            return NotInRemoteControl()
        if state.robot_mode != ROBOT_MODE_RUNNING:
            mode = ROBOT_MODE_TEXT.get(state.robot_mode, f"in robot mode {state.robot_mode}")
            return RobotError(f"the arm is {mode}{context}: power it on and release the brakes on the teach "
                              "pendant, then retry")
        if not state.program_running:
            return RobotError(f"fixwizard's control script stopped on the robot{context} (the RTDE watchdog, or "
                              "someone pressed stop): retry, fixwizard re-uploads it")
        return RobotError(f"the robot did not do it{context}: check the teach pendant for a message, then retry")

    def _in_remote_control(self, link: _Link) -> bool:
        try:
            return bool(link.worker.call(link.dashboard.isInRemoteControl, COMMAND_TIMEOUT_S))
        except (TimeoutError, RuntimeError):
            return True  # unknown: the caller reports the other causes

    def _lose(self, link: _Link, context: str) -> ConnectionLost:
        link.lost.set()
        return ConnectionLost(f"{context} (the robot stops by itself when fixwizard's link is gone)")

    def _fresh(self, link: _Link) -> bool:
        """Whether RTDE state still arrives: the controller's timestamp advanced within ``STALE_STATE_S``."""
        deadline = time.monotonic() + STALE_STATE_S
        while True:
            timestamp_s = link.receive.getTimestamp() if link.receive.isConnected() else link.last_timestamp_s
            now = time.monotonic()
            if timestamp_s != link.last_timestamp_s:
                link.last_timestamp_s, link.last_fresh_at = timestamp_s, now
            if now - link.last_fresh_at < STALE_STATE_S:
                return True
            if now > deadline:
                return False
            time.sleep(POLL_S)

    def _state(self, link: _Link) -> _State:
        receive = link.receive
        return _State(receive.getTimestamp(), from_ur_pose(receive.getActualTCPPose()),
                      float(np.linalg.norm(receive.getActualTCPSpeed()[:3])),
                      float(np.linalg.norm(receive.getActualTCPForce()[:3])), receive.getRobotMode(),
                      receive.getSafetyStatusBits(), receive.getRuntimeState())

    def _kick_watchdog(self, link: _Link) -> None:
        """Keep the RTDE watchdog fed while the link is open and idle (motion loops feed it themselves: a kick
        would overwrite their force-mode command)."""
        while not link.closing.wait(KICK_PERIOD_S):
            if (link.control is not None and not link.lost.is_set() and not self._moving.is_set()
                    and link.worker.idle()):
                link.worker.submit(link.control.kickWatchdog)

    def _check_port(self, port: int) -> None:
        try:
            socket.create_connection((self.host, port), timeout=CONNECT_TIMEOUT_S).close()
        except OSError as error:
            raise ConnectionLost(f" to {self.host}:{port} ({error.strerror or error})") from error

    def _close_link(self) -> None:
        link, self._link = self._link, None
        if link is None:
            return
        link.closing.set()
        if link.control is not None and not link.lost.is_set():
            try:
                link.worker.call(link.control.stopScript, COMMAND_TIMEOUT_S)
            except (TimeoutError, RuntimeError):
                pass
        link.worker.close()
        # Disconnect before the clients are freed: a client whose link drops starts reconnecting on its own
        # thread, and freeing it meanwhile crashes ur_rtde. Each RTDE disconnect waits 0.5 s (without the GIL;
        # freeing the client later waits another 0.5 s holding it), so they run side by side.
        disconnects = [threading.Thread(target=_disconnect_quietly, args=(client,), daemon=True)
                       for client in (link.control, link.receive, link.dashboard) if client is not None]
        for thread in disconnects:
            thread.start()
        for thread in disconnects:
            thread.join(COMMAND_TIMEOUT_S)

    @contextmanager
    def _locked(self, what: str) -> Iterator[None]:
        if not self._lock.acquire(timeout=LOCK_TIMEOUT_S):
            raise RobotError(f"the robot is busy with another command and cannot {what} now: wait, then retry")
        try:
            yield
        finally:
            self._lock.release()


def _dashboard(dashboard: Any, commands: list[str]) -> list[str]:
    """Send dashboard ``commands`` one by one; their reply lines."""
    replies = []
    for command in commands:
        dashboard.send(f"{command}\n")
        replies.append(dashboard.receive().strip())
    return replies


def _disconnect_quietly(client: Any) -> None:
    try:
        client.disconnect()
    except RuntimeError:
        pass
