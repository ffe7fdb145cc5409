"""The robot interface every cell implements (simulated or real), its results and its typed errors.

Poses are 4x4 float64 transforms ``base_T_tcp`` of the flange (tcp without tool offset) in the
robot base frame, metres. Errors say what happened and what the operator should do next.
"""

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from fixwizard.errors import FixwizardError

# Safety limits of a tap and a linear move; a cell refuses requests beyond them.
MAX_TAP_TRAVEL_M = 0.05
MAX_TAP_SPEED_M_S = 0.05
MAX_TAP_FORCE_N = 50.0
MAX_LINEAR_SPEED_M_S = 0.25
MAX_MOVE_TRAVEL_M = 0.5  # the farthest a move's target may be from where the flange stands when it starts
# A move stops when the force on the tool has grown by this (N) since it began, and goes back there: well above
# the force estimate's noise while the arm accelerates (a CB3 estimates it from joint currents), well below the
# 150 N at which a UR's default safety configuration protective-stops, so nothing is pressed harder or longer.
MOVE_FORCE_LIMIT_N = 50.0


class RobotError(FixwizardError):
    """The robot cannot do what was asked; the message says what to do next. An error during a tap may carry
    the recorded ``tap_result`` (the attribute is absent otherwise)."""

    tap_result: "TapResult"


class ProtectiveStop(RobotError):
    """The controller made a protective stop; motion is blocked until it is unlocked."""

    def __init__(self, context: str = "") -> None:
        super().__init__(f"the robot made a protective stop{context}: unlock the protective stop on the teach "
                         "pendant, then retry")


class EmergencyStop(RobotError):
    """The emergency stop is pressed."""

    def __init__(self) -> None:
        super().__init__("the emergency stop is pressed: make the cell safe, release the emergency stop, power on "
                         "and release the brakes on the teach pendant, then retry")


class ConnectionLost(RobotError):
    """The link to the controller is down (never made, closed or dropped)."""

    def __init__(self, context: str = "") -> None:
        super().__init__(f"the connection to the robot is lost{context}: check that the robot is powered on and "
                         "the network cable is plugged in, then reconnect")


class NoContact(RobotError):
    """A tap travelled its full distance without touching anything."""

    def __init__(self, max_travel_m: float) -> None:
        super().__init__(f"the tap found no surface within {max_travel_m * 1e3:.0f} mm: move the tool closer to "
                         "the fixture and retry")


class MotionStopped(RobotError):
    """The operator stopped a motion (the STOP key) before it finished, or freedrive before it came on; nothing was
    recorded from it."""

    def __init__(self, motion: str) -> None:
        if motion == "freedrive":
            super().__init__("freedrive did not come on: STOP was pressed after it was asked for, so the arm holds "
                             "still: check the cell, then turn freedrive on again")
        else:
            super().__init__(f"the {motion} was stopped on request; nothing was recorded from it: check the cell, "
                             "then retry")


class MoveBlocked(RobotError):
    """A move met something on its way: it stopped at ``MOVE_FORCE_LIMIT_N`` and went back to where it began."""

    def __init__(self, peak_force_n: float) -> None:
        super().__init__(f"the arm met something on its way ({peak_force_n:.0f} N), stopped and went back to where "
                         "the move began: clear the path (a hand, a cable, the fixture in the way), then retry")


class NotInRemoteControl(RobotError):
    """The controller is in local mode and refuses commands from outside."""

    def __init__(self) -> None:
        super().__init__("the robot is in local control: switch it to remote control on the teach pendant, "
                         "then retry")


@dataclass(frozen=True)
class RobotStatus:
    """Controller state as the operator should see it; ``mode`` is a short human-readable text."""

    connected: bool
    protective_stop: bool
    emergency_stop: bool
    program_running: bool
    mode: str


@dataclass(frozen=True, eq=False)
class TapResult:
    """One tap: flange pose at contact (base frame, m), travel to contact (m), peak contact force (N),
    time waited for the contact to settle (s)."""

    base_T_tcp_contact: np.ndarray
    travel_m: float
    peak_force_n: float
    settle_s: float


@runtime_checkable
class Robot(Protocol):
    """A robot cell fixwizard can drive. Every call may raise a ``RobotError``."""

    def connect(self) -> None:
        """Open (or reopen) the link to the controller."""

    def close(self) -> None:
        """Close the link; further calls need ``connect`` first."""

    def base_T_tcp(self) -> np.ndarray:
        """Current flange pose as the controller reports it (4x4, base frame, m)."""

    def freedrive(self, on: bool, stop_mark: int | None = None) -> None:
        """Let the operator move the arm by hand (True) or hold it (False); ``stop_mark``: see ``stop_count``."""

    def tap(self, max_travel_m: float = 0.02, speed_m_s: float = 0.01, force_limit_n: float = 10.0,
            stop_mark: int | None = None, on_contact: Callable[[TapResult], None] | None = None) -> TapResult:
        """Approach along the tool z axis until ``force_limit_n`` (N), at most ``max_travel_m`` (m) at
        ``speed_m_s`` (m/s); settle, record the contact flange pose, retract to the start. ``stop_mark``: see
        ``stop_count``. ``on_contact`` is called with the contact as soon as it is recorded, in the caller's thread,
        before the retract has ended (to save it then); what it raises is raised once the tap has ended."""

    def move_linear(self, base_T_tcp: np.ndarray, speed_m_s: float = 0.05, stop_mark: int | None = None) -> None:
        """Move the flange in a straight line to ``base_T_tcp`` (4x4, base frame, m) at ``speed_m_s`` (m/s).
        ``stop_mark``: see ``stop_count``."""

    def status(self) -> RobotStatus:
        """Current controller state; never raises for a lost connection (it shows ``connected=False``)."""

    def stop(self) -> None:
        """Stop any motion now (one that was asked for with a ``stop_mark`` older than this STOP and has not
        started yet never starts); never waits for a motion."""

    def stop_count(self) -> int:
        """How many times ``stop`` was called. Read before a motion is decided on and passed to it as its
        ``stop_mark``, it makes the motion refuse to start (``MotionStopped``) after any STOP since the reading,
        however late the call reaches the robot; a motion asked for with no mark counts STOPs from the call on
        (freedrive off ignores the mark: holding the arm is always allowed)."""


def check_tap_request(max_travel_m: float, speed_m_s: float, force_limit_n: float) -> None:
    """Raise ``RobotError`` unless the tap's travel (m), speed (m/s) and force (N) are within the safety limits."""
    for name, value, limit, unit, scale in (("travel", max_travel_m, MAX_TAP_TRAVEL_M, "mm", 1e3),
                                            ("speed", speed_m_s, MAX_TAP_SPEED_M_S, "mm/s", 1e3),
                                            ("force limit", force_limit_n, MAX_TAP_FORCE_N, "N", 1.0)):
        check_limit(f"tap {name}", value, limit, unit, scale)


def check_limit(name: str, value: float, limit: float, unit: str, scale: float) -> None:
    """Raise ``RobotError`` unless ``0 < value <= limit``; ``scale`` converts SI to the shown ``unit``."""
    if not 0.0 < value <= limit:
        raise RobotError(f"the {name} of {value * scale:g} {unit} is outside the safe range (0, {limit * scale:g}] "
                         f"{unit}: choose a value in that range")


def check_move_travel(distance_m: float) -> None:
    """Raise ``move_too_far`` when a move's target is ``distance_m`` (m) from the flange, beyond
    ``MAX_MOVE_TRAVEL_M``: nothing moves."""
    if distance_m > MAX_MOVE_TRAVEL_M:
        raise move_too_far(distance_m)


def move_too_far(distance_m: float) -> RobotError:
    """The error of a move refused for its target's distance (m) from the flange; at least ``MAX_MOVE_TRAVEL_M`` is
    said (the controller, which refused it, may have measured from where the flange stood a moment later)."""
    return RobotError(f"the move's target is {max(distance_m, MAX_MOVE_TRAVEL_M) * 1e3:.0f} mm from the flange, "
                      f"farther than the {MAX_MOVE_TRAVEL_M * 1e3:.0f} mm one move may go, so the robot did not "
                      "move: bring the arm nearer by hand (freedrive) and retry; if the target is far off, check the "
                      "tip calibration and the fixture's units")
