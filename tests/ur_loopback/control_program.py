"""What the uploaded ur_rtde control script does on the controller, cycle by cycle: read the command number in
``input_int_register_0`` and its arguments in the other input registers, act on the arm, and answer through
``output_int_register_0`` (1 ready for a command, 2 done with it).

The command numbers are those of the ur_rtde 1.6.5 script (``tests/test_robot_ur.py`` pins its hash). Like
the real script, a command number it has no branch for is acknowledged as done without doing anything; the
numbers are recorded in ``unhandled`` so a test can see them.
"""

from collections.abc import Callable

from ur_loopback.arm import ForceMode, SimulatedArm, transform

READY, DONE = 1, 2

MOVEL = 3
FORCE_MODE = 6
FORCE_MODE_STOP = 7
ZERO_FT_SENSOR = 8
SPEED_STOP = 15
TEACH_MODE = 18
END_TEACH_MODE = 19
FORCE_MODE_SET_DAMPING = 20
FORCE_MODE_SET_GAIN_SCALING = 21
SET_TCP = 29
PROTECTIVE_STOP = 31
STOPL = 33
SET_WATCHDOG = 35
FREEDRIVE_MODE = 52
END_FREEDRIVE_MODE = 53
STOP_SCRIPT = 255
# commands the script processes without blocking and after which it signals ready at once
REALTIME_COMMANDS = {6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71}


class Registers:
    """The RTDE input and output registers the program and the RTDE clients share."""

    def __init__(self) -> None:
        self.inputs: dict[str, float | int] = {}
        self.outputs: dict[str, float | int] = {}

    def input_int(self, index: int) -> int:
        return int(self.inputs.get(f"input_int_register_{index}", 0))

    def input_double(self, index: int) -> float:
        return float(self.inputs.get(f"input_double_register_{index}", 0.0))

    def input_doubles(self, first: int, count: int = 6) -> list[float]:
        return [self.input_double(first + i) for i in range(count)]

    def write_int(self, index: int, value: int) -> None:
        self.outputs[f"output_int_register_{index}"] = value


class ControlProgram:
    """One run of the control script: created when the script arrives, ``step`` once per controller cycle."""

    def __init__(self, arm: SimulatedArm, registers: Registers, on_event: Callable[[str], None]) -> None:
        self.arm = arm
        self.registers = registers
        self.on_event = on_event
        self.running = True
        self.commands: list[int] = []
        self.unhandled: list[int] = []
        self.watchdog_min_frequency_hz: float | None = None
        self._executing = False
        self._busy: Callable[[], bool] | None = None
        self._async_move = False
        self._async_writes = 0
        self._async_operation = 0
        self._write_async_progress(-1)
        registers.write_int(0, READY)

    def step(self) -> None:
        """One pass of the script's main loop (it runs once per ``sync()``)."""
        if self._async_move and not self.arm.moving():
            self._async_move = False
            self._write_async_progress(-1)
        if self._busy is not None:
            if self._busy():
                return
            self._busy = None
            self.registers.write_int(0, DONE)
            return
        command = self.registers.input_int(0)
        if command in REALTIME_COMMANDS:
            self._process(command)
            self.registers.write_int(0, READY)
        elif command == 0:
            self._executing = False
            self.registers.write_int(0, READY)
        elif not self._executing:
            self._executing = True
            self._process(command)
            if command != STOP_SCRIPT and self._busy is None:
                self.registers.write_int(0, DONE)

    def stop(self) -> None:
        """The program ends (stop script, dashboard stop, protective or emergency stop, watchdog)."""
        self.running = False
        self.watchdog_min_frequency_hz = None
        self.arm.freedrive = False

    def _process(self, command: int) -> None:
        self.commands.append(command)
        registers, arm = self.registers, self.arm
        if command == MOVEL:
            arm.move_linear(transform(registers.input_doubles(0)), registers.input_double(6))
            self.on_event("movel")
            if registers.input_int(1) == 1:
                self._async_move = True
                self._write_async_progress(0)
            else:
                self._busy = arm.moving
        elif command == FORCE_MODE:
            first_mode = arm.force_mode is None
            arm.force_mode = ForceMode(transform(registers.input_doubles(0)),
                                       [registers.input_int(2 + i) for i in range(6)],
                                       registers.input_doubles(6), registers.input_doubles(12))
            if first_mode:
                self.on_event("force_mode")
        elif command == FORCE_MODE_STOP:
            self.on_event("force_mode_stop")
            arm.halt()
        elif command in (STOPL, SPEED_STOP):
            arm.halt()
        elif command == ZERO_FT_SENSOR:
            arm.zero_sensor()
        elif command in (TEACH_MODE, FREEDRIVE_MODE):
            arm.halt()
            arm.freedrive = True
        elif command in (END_TEACH_MODE, END_FREEDRIVE_MODE):
            arm.freedrive = False
        elif command == SET_TCP:
            arm.flange_T_tcp = transform(registers.input_doubles(0))
        elif command == SET_WATCHDOG:
            self.watchdog_min_frequency_hz = registers.input_double(0)
        elif command == PROTECTIVE_STOP:
            self.on_event("protective_stop")
        elif command == STOP_SCRIPT:
            self.stop()
        elif command not in (FORCE_MODE_SET_DAMPING, FORCE_MODE_SET_GAIN_SCALING):
            self.unhandled.append(command)

    def _write_async_progress(self, value: int) -> None:
        """The script's ``write_async_progress_register``: operation id, write count, running bit, progress."""
        self._async_writes = (self._async_writes + 1) % 128
        if value == 0:
            self._async_operation = (self._async_operation + 1) % 128
        register = self._async_writes * 65536 + self._async_operation * 16777216
        if value >= 0:
            register += min(value, 32767) + 32768
        self.registers.write_int(2, register)
