"""What fixwizard's URScript programs (``fixwizard/robot/ur_script.py``) do on the controller, cycle by cycle.

The loopback does not interpret URScript: it reads a program's name, its ``global NAME = VALUE`` parameters
and its ``rtde_set_watchdog`` line from the text sent to the script port, and runs a Python twin of that
program, one ``sync()`` per controller cycle (a generator that yields where the script calls ``sync()``).
The twins follow the scripts statement by statement; the register numbers and phases are the scripts'.
"""

import re
from collections.abc import Callable, Iterator

import numpy as np

from ur_loopback.arm import SimulatedArm, interpolate_pose, transform

PROGRAM_NAME = re.compile(r"^def fixwizard_(\w+)\(\):\n", re.MULTILINE)
PARAMETER = re.compile(r"^  global (\w+) = (p\[[^\]]*\]|[-+0-9.e]+)$", re.MULTILINE)
WATCHDOG = re.compile(r'^  rtde_set_watchdog\("(\w+)", ([-+0-9.e]+), "stop"\)$', re.MULTILINE)
MOTION_STATEMENTS = ("movel(", "teach_mode(")
# Functions a UR controller's URScript has (the Script Directory's motion, internals, urmath and interfaces
# modules, CB3 3.x and e-Series 5.x). The controller compiles a program before it runs it and refuses one that
# calls any other function it does not define itself: the program never starts (a compile error on the pendant).
URSCRIPT_FUNCTIONS = frozenset({
    "movej", "movel", "movep", "stopj", "stopl", "speedl", "teach_mode", "end_teach_mode", "freedrive_mode", "force",
    "end_freedrive_mode", "force_mode", "end_force_mode", "get_actual_tcp_pose", "get_actual_tcp_speed",
    "get_tcp_force", "get_steptime", "set_tcp", "sync", "sleep", "textmsg", "popup", "acos", "asin", "atan",
    "atan2", "ceil", "cos", "d2r", "floor", "interpolate_pose", "inv", "length", "log", "norm", "normalize",
    "point_dist", "pose_add", "pose_dist", "pose_inv", "pose_sub", "pose_trans", "pow", "r2d", "random", "sin",
    "size", "sqrt", "tan", "read_input_integer_register", "read_input_float_register",
    "write_output_integer_register", "write_output_float_register", "rtde_set_watchdog", "zero_ftsensor"})
CALL = re.compile(r"\b([A-Za-z_]\w*)\(")
ASSIGNMENT = re.compile(r"^\s*(?:global |local )?(\w+)\s*=(?!=)", re.MULTILINE)
DEFINITION = re.compile(r"^\s*(?:def|thread)\s+(\w+)\(", re.MULTILINE)
COMMENT = re.compile(r"#.*$", re.MULTILINE)

RUN_REGISTER, PHASE_REGISTER, REQUEST_REGISTER = 18, 19, 19
TRAVEL_REGISTER, PEAK_FORCE_REGISTER, SETTLE_REGISTER = 17, 18, 19
REQUEST_STOP, REQUEST_RETRACT, REQUEST_GO = 1, 2, 3
PHASE_RUNNING, PHASE_SETTLED, PHASE_DONE, PHASE_NO_CONTACT, PHASE_STOPPED, PHASE_NOT_SETTLED = 1, 2, 3, 4, 5, 6
PHASE_TOO_FAR, PHASE_BLOCKED, PHASE_WAITING, PHASE_NO_GO, PHASE_RETURN_BLOCKED = 7, 8, 9, 10, 11
PHASE_BACKING_OFF, PHASE_BACK_OFF_STOPPED = 12, 13


class Registers:
    """The RTDE input and output registers the programs and the RTDE clients share."""

    def __init__(self) -> None:
        self.inputs: dict[str, float | int] = {}
        self.outputs: dict[str, float | int] = {}

    def input_int(self, index: int) -> int:
        return int(self.inputs.get(f"input_int_register_{index}", 0))

    def write_int(self, index: int, value: int) -> None:
        self.outputs[f"output_int_register_{index}"] = value

    def write_double(self, index: int, value: float) -> None:
        self.outputs[f"output_double_register_{index}"] = value


def parse(text: str) -> tuple[str, dict, tuple[str, float] | None, bool] | None:
    """A fixwizard program's name, parameters, watchdog (variable, minimum frequency) and whether the
    watchdog is armed before the first motion statement; None for any other program."""
    name = PROGRAM_NAME.search(text)
    if name is None:
        return None
    parameters = {key: _value(value) for key, value in PARAMETER.findall(text)}
    watchdog = WATCHDOG.search(text)
    motions = [text.find(statement) for statement in MOTION_STATEMENTS if statement in text]
    armed_first = watchdog is not None and all(watchdog.start() < index for index in motions)
    return name.group(1), parameters, None if watchdog is None else (watchdog.group(1), float(watchdog.group(2))), \
        armed_first


def unknown_functions(text: str) -> set[str]:
    """Functions a program calls that neither URScript nor the program defines (a compile error on a UR)."""
    code = COMMENT.sub("", text)
    return set(CALL.findall(code)) - set(DEFINITION.findall(code)) - URSCRIPT_FUNCTIONS


def variables_named_like_functions(text: str) -> set[str]:
    """Variables a program assigns that bear the name of a URScript function (``force = ...`` beside ``force()``):
    the manual says nothing of which one such a name then means, nor whether a controller compiles it."""
    return set(ASSIGNMENT.findall(COMMENT.sub("", text))) & URSCRIPT_FUNCTIONS


class FixwizardProgram:
    """One run of a fixwizard program: made when the program arrives, ``step`` once per controller cycle."""

    def __init__(self, name: str, parameters: dict, watchdog: tuple[str, float] | None, arm: SimulatedArm,
                 registers: Registers, on_event: Callable[[str], None]) -> None:
        self.name = name
        self.parameters = parameters
        self.arm = arm
        self.registers = registers
        self.on_event = on_event
        self.running = True
        self.run_id = int(parameters["run_id"])
        # the script's first statements: the watchdog, the phase and run id, a zero TCP offset
        self.watchdog_variable, self.watchdog_min_frequency_hz = watchdog if watchdog else (None, None)
        registers.write_int(PHASE_REGISTER, PHASE_WAITING)
        registers.write_int(RUN_REGISTER, self.run_id)
        arm.flange_T_tcp = np.eye(4)
        self.max_travel_m = 0.0  # a tap's deepest travel along the start's tool z axis, for the tests
        self._dt = 0.0
        self._steps = self._started(getattr(self, f"_{name}")())

    def step(self, dt: float) -> None:
        """One cycle; the program ends when its twin returns, or where a fault its event set off stopped it."""
        self._dt = dt
        try:
            next(self._steps)
        except (StopIteration, _Stopped):
            self.running = False

    def stop(self) -> None:
        """The program ends (dashboard stop, protective or emergency stop, watchdog, a new program)."""
        self.running = False
        self.watchdog_min_frequency_hz = None
        self.arm.freedrive = False

    # --- the scripts' helpers ---

    def _event(self, event: str) -> None:
        """Tell the controller; a fault that event sets off (a stop, ``when``) ends the program right there, as
        on a controller, which runs no statement of a stopped program."""
        self.on_event(event)
        if not self.running:
            raise _Stopped

    def _requested(self, request: int) -> bool:
        return self.registers.input_int(REQUEST_REGISTER) == self.run_id * 8 + request

    def _finish(self, phase: int) -> None:
        self.registers.write_int(PHASE_REGISTER, phase)

    def _force_n(self) -> float:
        return float(np.linalg.norm(self.arm.tcp_force()[:3]))

    def _linear(self, base_T_target: np.ndarray, speed_m_s: float) -> None:
        self.arm.move_linear(base_T_target, speed_m_s)
        self._event("movel")

    # --- the programs ---

    def _started(self, body: Iterator[None]) -> Iterator[None]:
        """The scripts' common start after the helpers: wait for the link's go; a stop requested before it, or no
        go within the program's timeout, ends the program unmoved."""
        waited_s = 0.0
        while not self._requested(REQUEST_GO):
            if self._requested(REQUEST_STOP):
                return self._finish(PHASE_STOPPED)
            if waited_s > self.parameters["go_timeout_s"]:
                return self._finish(PHASE_NO_GO)
            waited_s += self._dt
            yield
        self.registers.write_int(PHASE_REGISTER, PHASE_RUNNING)
        yield from body

    def _tap(self) -> Iterator[None]:
        arm, p = self.arm, self.parameters
        start = arm.base_T_flange.copy()
        limit = start @ transform([0.0, 0.0, p["max_travel_m"], 0.0, 0.0, 0.0])
        peak_n = 0.0

        def travel_m() -> float:
            return float((arm.base_T_flange[:3, 3] - start[:3, 3]) @ start[:3, 2])

        arm.zero_sensor()
        self._event("zero_ftsensor")
        yield
        self._linear(limit, p["speed_m_s"])
        self._event("tap")
        while self._force_n() < p["force_limit_n"]:
            self.max_travel_m = max(self.max_travel_m, travel_m())
            peak_n = max(peak_n, self._force_n())
            if self._requested(REQUEST_STOP):
                arm.halt()
                return self._finish(PHASE_STOPPED)
            if not arm.moving():
                yield from self._retract(start, PHASE_NO_CONTACT, self._force_n)
                return
            yield
        arm.halt()
        still_s = waited_s = 0.0
        while still_s < p["settle_window_s"]:
            self.max_travel_m = max(self.max_travel_m, travel_m())
            peak_n = max(peak_n, self._force_n())
            if self._requested(REQUEST_STOP):
                return self._finish(PHASE_STOPPED)
            if waited_s > p["settle_timeout_s"]:
                return self._finish(PHASE_NOT_SETTLED)
            still_s = still_s + self._dt if np.linalg.norm(arm.velocity_m_s) < p["settle_speed_m_s"] else 0.0
            waited_s += self._dt
            yield
        self.registers.write_double(TRAVEL_REGISTER, travel_m())
        self.registers.write_double(PEAK_FORCE_REGISTER, peak_n)
        self.registers.write_double(SETTLE_REGISTER, waited_s)
        self.registers.write_int(PHASE_REGISTER, PHASE_SETTLED)
        self._event("settled")
        while not self._requested(REQUEST_RETRACT):
            if self._requested(REQUEST_STOP):
                return self._finish(PHASE_STOPPED)
            yield
        yield from self._retract(start, PHASE_DONE, self._force_n)

    def _retract(self, start: np.ndarray, phase: int, return_force_n: Callable[[], float]) -> Iterator[None]:
        return_began = self.arm.base_T_flange.copy()
        self._linear(start, self.parameters["retract_speed_m_s"])
        least_n = return_force_n()
        while self.arm.moving():
            if self._requested(REQUEST_STOP):
                self.arm.halt()
                return self._finish(PHASE_STOPPED)
            force = return_force_n()
            least_n = min(least_n, force)
            if force - least_n >= self.parameters["return_force_limit_n"]:
                self.arm.halt()
                self.registers.write_double(PEAK_FORCE_REGISTER, force - least_n)
                yield from self._back_off_and_finish(return_began)
                return
            yield
        self._finish(phase)

    def _back_off_and_finish(self, return_began: np.ndarray) -> Iterator[None]:
        """Half the way back it came, at most ``back_off_m``, towards ``return_began``, saying so (``back_off``
        event); a STOP stops it there."""
        self.registers.write_int(PHASE_REGISTER, PHASE_BACKING_OFF)
        here = self.arm.base_T_flange.copy()
        gone_m = float(np.linalg.norm(here[:3, 3] - return_began[:3, 3]))
        fraction = 0.5 if gone_m * 0.5 <= self.parameters["back_off_m"] else self.parameters["back_off_m"] / gone_m
        self._linear(interpolate_pose(here, return_began, fraction), self.parameters["retract_speed_m_s"])
        self._event("back_off")
        while self.arm.moving():
            if self._requested(REQUEST_STOP):
                self.arm.halt()
                return self._finish(PHASE_BACK_OFF_STOPPED)
            yield
        self._finish(PHASE_RETURN_BLOCKED)

    def _move(self) -> Iterator[None]:
        arm, p = self.arm, self.parameters
        base_T_target = transform(p["target"])
        if np.linalg.norm(base_T_target[:3, 3] - arm.base_T_flange[:3, 3]) > p["max_travel_m"]:
            return self._finish(PHASE_TOO_FAR)
        start = arm.base_T_flange.copy()
        force_at_start = np.array(arm.tcp_force()[:3])

        def force_change_n() -> float:
            return float(np.linalg.norm(np.array(arm.tcp_force()[:3]) - force_at_start))

        self._linear(base_T_target, p["speed_m_s"])
        while arm.moving():
            if self._requested(REQUEST_STOP):
                arm.halt()
                return self._finish(PHASE_STOPPED)
            if force_change_n() >= p["force_limit_n"]:
                arm.halt()
                self.registers.write_double(PEAK_FORCE_REGISTER, force_change_n())
                self._event("blocked")
                yield from self._retract(start, PHASE_BLOCKED, force_change_n)
                return
            yield
        self._finish(PHASE_DONE)

    def _setup(self) -> Iterator[None]:
        self._finish(PHASE_DONE)
        yield from ()

    def _freedrive(self) -> Iterator[None]:
        self.arm.halt()
        self.arm.freedrive = True
        self._event("freedrive")
        while not self._requested(REQUEST_STOP):
            yield
        self.arm.freedrive = False
        self._finish(PHASE_DONE)


class _Stopped(Exception):
    """The program was stopped in the middle of a cycle."""


def _value(text: str) -> float | list[float]:
    if text.startswith("p["):
        return [float(value) for value in text[2:-1].split(",")]
    return float(text)
