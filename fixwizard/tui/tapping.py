"""A tap as the sampling and check screens make it: freedrive off, tap, record the contact; freedrive on again
only after a tap that ended as planned (a contact, or none within its travel) and with no STOP meanwhile. After a
stop or a fault the arm holds still: freedrive stays off until the operator turns it on, and the error says so. A
motion whose key came before a STOP does not start after it (``unless_stopped``, whose mark the motion gets)."""

import contextlib
import threading
from collections.abc import Callable
from typing import TypeVar

from fixwizard.robot.base import MotionStopped, NoContact, Robot, RobotError, TapResult
from fixwizard.tui import keys

T = TypeVar("T")
FREEDRIVE_STAYS_OFF = (f"Freedrive stays off after this: press {keys.name(keys.FREEDRIVE)} to guide the arm by hand "
                       "again once the cell is safe (after a STOP, re-arming turns it on).")


def unless_stopped(robot: Robot, cancel: threading.Event, motion: str) -> int:
    """The ``stop_mark`` to ask ``robot`` for ``motion`` (e.g. "tap") with; ``MotionStopped`` if STOP was pressed
    since its key (``cancel``, which STOP sets before it stops the robot). Called just before the robot call, so that
    a motion asked for before a STOP does not start after it (the robot's own stop halts only a motion that has
    started). The mark is read before ``cancel`` is looked at: a STOP after that look stops the robot after the
    reading too, so the robot refuses the motion, however late the call reaches it."""
    stop_mark = robot.stop_count()
    if cancel.is_set():
        raise MotionStopped(motion)
    return stop_mark


def freedrive_again(robot: Robot, cancel: threading.Event) -> None:
    """Freedrive on, unless STOP was pressed meanwhile (``cancel``, which STOP sets: then the arm holds still, even
    when the motion had ended before the STOP reached the robot); a robot that refuses leaves it to the next robot
    call to tell the operator."""
    with contextlib.suppress(RobotError):
        robot.freedrive(True, stop_mark=unless_stopped(robot, cancel, "freedrive"))


def tap_and_record(robot: Robot, record: Callable[[TapResult], T], tap_count: Callable[[], int],
                   cancel: threading.Event) -> T:
    """Tap and ``record`` the contact as soon as the robot has it, while the ball retracts (a wizard killed then has
    saved it); a contact the robot recorded before a fault is recorded too (the error then holds it as
    ``recorded_tap`` and says it was saved as tap ``tap_count()``). ``cancel``: set by STOP (freedrive then stays
    off). Raises the robot's error, else the error of a record that failed (a full disk)."""
    saved: list[T] = []
    unsaved: list[Exception] = []

    def save(contact: TapResult) -> None:
        if saved or unsaved:  # one contact per tap
            return
        try:
            saved.append(record(contact))
        except Exception as error:  # raised after the tap, which goes on to its retract
            unsaved.append(error)

    robot.freedrive(False)
    try:
        result = robot.tap(stop_mark=unless_stopped(robot, cancel, "tap"), on_contact=save)
    except NoContact:
        freedrive_again(robot, cancel)
        raise
    except RobotError as error:
        recorded = getattr(error, "tap_result", None)
        if recorded is not None:  # the contact came before the fault (while retracting, or the link went down)
            save(recorded)
        if saved:
            error.recorded_tap = saved[0]  # type: ignore[attr-defined]
            error.add_note(f"The contact was saved as tap {tap_count()}.")
        elif unsaved:  # the robot's fault first: it says what the arm did
            error.add_note(f"The contact could not be saved: {unsaved[0]}")
        error.add_note(FREEDRIVE_STAYS_OFF)
        raise
    try:
        save(result)
        if unsaved:
            raise unsaved[0]
        return saved[0]
    finally:
        freedrive_again(robot, cancel)
