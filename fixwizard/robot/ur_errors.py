"""The UR link's own errors, and how every robot error crosses from the link process to the wizard's."""

from typing import Any

from fixwizard.robot.base import (
    ConnectionLost,
    EmergencyStop,
    MotionStopped,
    MoveBlocked,
    NoContact,
    NotInRemoteControl,
    ProtectiveStop,
    RobotError,
)


class URProtectiveStop(ProtectiveStop):
    """A protective stop, with UR's recovery: look at the cause, then unlock (pendant or fixwizard)."""

    def __init__(self, context: str = "") -> None:
        RobotError.__init__(self, f"the robot made a protective stop{context}: look at what it hit or what "
                            "stopped it, then unlock the protective stop on the teach pendant or with Unlock in "
                            "fixwizard (at least 5 s after the stop), then retry")


class LinkLost(ConnectionLost):
    """The link to the controller is down; the message names the cause and that the watchdog stops the arm."""

    def __init__(self, message: str) -> None:
        RobotError.__init__(self, message)


_KINDS: dict[str, type[RobotError]] = {kind.__name__: kind for kind in (
    RobotError, ConnectionLost, LinkLost, ProtectiveStop, URProtectiveStop, EmergencyStop, NoContact,
    MotionStopped, MoveBlocked, NotInRemoteControl)}


def pack_error(error: RobotError) -> tuple[str, str, Any]:
    """What the link process sends for ``error``: its kind, its message and the tap it recorded (or None).
    (Exceptions whose constructors take other arguments than their message do not pickle back.)"""
    kind = type(error).__name__ if type(error).__name__ in _KINDS else "RobotError"
    return kind, str(error), getattr(error, "tap_result", None)


def unpack_error(kind: str, message: str, tap_result: Any) -> RobotError:
    """The error ``pack_error`` described, of the same class, with the same message and ``tap_result``."""
    error_class = _KINDS.get(kind, RobotError)
    error = error_class.__new__(error_class)
    Exception.__init__(error, message)
    if tap_result is not None:
        error.tap_result = tap_result
    return error
