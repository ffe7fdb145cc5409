"""The controller state the UR link process publishes and the wizard's process reads, without a lock either
side could be frozen holding: a sequence counter around the values in shared memory (odd while a write is
under way), so a reader never waits for a writer, even one stopped by SIGSTOP.

Times are ``time.monotonic()`` seconds (one clock for every process on the machine). Poses are 4x4 float64
``base_T_tcp`` of the flange in the robot base frame (m), speeds m/s, forces N.
"""

import ctypes
import multiprocessing
import time
from dataclasses import dataclass
from multiprocessing.sharedctypes import SynchronizedArray

import numpy as np

from fixwizard.geometry.se3 import from_ur_pose

# robot_mode, safety_mode, safety_status_bits and runtime_state values of the RTDE guide
ROBOT_MODE_RUNNING = 7
ROBOT_MODE_TEXT = {-1: "no controller", 0: "disconnected", 1: "confirm safety", 2: "booting", 3: "powered off",
                   4: "powered on", 5: "brakes on", 6: "releasing brakes", 8: "updating firmware"}
SAFETY_MODE_PROTECTIVE_STOP = 3
SAFETY_MODES_EMERGENCY_STOP = {6, 7}  # system (a cell e-stop), robot (the pendant's)
SAFETY_MODES_SAFEGUARD_STOP = {5, 12, 13}  # safeguard, automatic-mode safeguard, three-position enabling stop
SAFETY_MODES_FAULT = {8, 9}  # violation, fault
SAFETY_BIT_PROTECTIVE_STOP = 2
SAFETY_BIT_SAFEGUARD_STOP = 4
SAFETY_BITS_EMERGENCY_STOP = (5, 6, 7)  # system, robot, any emergency stop
SAFETY_BITS_FAULT = (8, 9)
RUNTIME_PLAYING = 2
RUNTIME_PAUSED_STATES = {3, 4, 5}  # pausing, paused, resuming: the program waits for play (pendant or dashboard)

_FIELDS = ("received_at", "timestamp", "x", "y", "z", "rx", "ry", "rz", "speed_m_s", "force_n", "robot_mode",
           "safety_mode", "safety_status_bits", "runtime_state", "run_id", "phase", "travel_m", "peak_force_n",
           "settle_s", "last_kick_at", "lost")
_INDEX = {name: index for index, name in enumerate(_FIELDS)}
READ_ATTEMPTS = 100
LOST_REASON_BYTES = 400  # room for why the link dropped (UTF-8), longer reasons are cut


@dataclass(frozen=True)
class ControllerState:
    """One RTDE sample as the link saw it: when it arrived (monotonic s), the controller's clock (s), the
    flange pose, speed and force, modes, and the registers of fixwizard's programs (see ``ur_script``)."""

    received_at: float
    timestamp_s: float
    base_T_tcp: np.ndarray
    speed_m_s: float
    force_n: float
    robot_mode: int
    safety_mode: int
    safety_status_bits: int
    runtime_state: int
    run_id: int
    phase: int
    travel_m: float
    peak_force_n: float
    settle_s: float

    def _bit(self, bit: int) -> bool:
        return bool(self.safety_status_bits >> bit & 1)

    @property
    def emergency_stop(self) -> bool:
        """From the safety mode and from every emergency-stop bit: either alone counts."""
        return self.safety_mode in SAFETY_MODES_EMERGENCY_STOP or any(map(self._bit, SAFETY_BITS_EMERGENCY_STOP))

    @property
    def protective_stop(self) -> bool:
        return self.safety_mode == SAFETY_MODE_PROTECTIVE_STOP or self._bit(SAFETY_BIT_PROTECTIVE_STOP)

    @property
    def safeguard_stop(self) -> bool:
        return self.safety_mode in SAFETY_MODES_SAFEGUARD_STOP or self._bit(SAFETY_BIT_SAFEGUARD_STOP)

    @property
    def safety_fault(self) -> bool:
        return self.safety_mode in SAFETY_MODES_FAULT or any(map(self._bit, SAFETY_BITS_FAULT))

    @property
    def program_running(self) -> bool:
        return self.runtime_state == RUNTIME_PLAYING

    @property
    def program_paused(self) -> bool:
        """A program is paused (or pausing, or resuming): play on the pendant would take it on where it stopped."""
        return self.runtime_state in RUNTIME_PAUSED_STATES

    @property
    def ready_to_move(self) -> bool:
        return (self.robot_mode == ROBOT_MODE_RUNNING and not self.emergency_stop and not self.protective_stop
                and not self.safeguard_stop and not self.safety_fault)


class SharedState:
    """The latest ``ControllerState``, the time of the link's last watchdog kick and whether (and why) the link saw
    its connection drop. Made in the wizard's process and handed to the link process."""

    def __init__(self, context: multiprocessing.context.BaseContext) -> None:
        self._values: SynchronizedArray = context.Array("d", len(_FIELDS), lock=False)
        self._sequence = context.Value("q", 0, lock=False)
        self._lost_reason: ctypes.Array[ctypes.c_char] = context.Array("c", LOST_REASON_BYTES, lock=False)

    # --- the link process writes ---

    def publish(self, sample: dict[str, float]) -> None:
        """Write some fields (names of ``_FIELDS``)."""
        self._sequence.value += 1
        for name, value in sample.items():
            self._values[_INDEX[name]] = value
        self._sequence.value += 1

    def lose(self, reason: str) -> None:
        """Say that the link saw its connection drop, and why (the link process says its first reason only). The
        reason is written before the flag, so a reader that sees the flag finds it."""
        encoded = reason.encode("utf-8", "replace")[:LOST_REASON_BYTES].decode("utf-8", "ignore").encode("utf-8")
        self._lost_reason.raw = encoded.ljust(LOST_REASON_BYTES, b"\0")  # cut between characters, the rest zeros
        self.publish({"lost": 1.0})

    # --- the wizard's process reads ---

    def read(self) -> tuple[ControllerState | None, float, bool]:
        """The latest sample (None before the first one or if no consistent copy could be read), the time of
        the last watchdog kick, and whether the link saw its connection drop."""
        for _ in range(READ_ATTEMPTS):
            before = self._sequence.value
            values = self._values[:]
            if before % 2 == 0 and self._sequence.value == before:
                break
            time.sleep(0)
        else:
            return None, 0.0, False
        field = dict(zip(_FIELDS, values, strict=True))
        state = None if field["received_at"] == 0.0 else ControllerState(
            field["received_at"], field["timestamp"],
            from_ur_pose(np.array([field[name] for name in ("x", "y", "z", "rx", "ry", "rz")])),
            field["speed_m_s"], field["force_n"], int(field["robot_mode"]), int(field["safety_mode"]),
            int(field["safety_status_bits"]), int(field["runtime_state"]), int(field["run_id"]),
            int(field["phase"]), field["travel_m"], field["peak_force_n"], field["settle_s"])
        return state, field["last_kick_at"], bool(field["lost"])

    def lost_reason(self) -> str:
        """Why the link saw its connection drop ("" before it did)."""
        return self._lost_reason.value.decode("utf-8", "replace") if self.read()[2] else ""
