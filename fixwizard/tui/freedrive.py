"""Freedrive as a screen where the operator guides the arm by hand opens (the pivot, the table points, sampling, the
check): on, unless the wizard is STOPPED. After a STOP the arm holds still, as after a stop during a tap
(``tapping``): freedrive stays off until the operator turns it on (f) or re-arms (Ctrl+R), which turns it on on
these screens; the screen says so."""

from collections.abc import Callable

from textual.dom import DOMNode

from fixwizard.robot.base import Robot
from fixwizard.tui import keys
from fixwizard.tui.workers import services

OFF_WHILE_STOPPED = (f"STOPPED: freedrive is off. Once the cell is checked, press {keys.name(keys.FREEDRIVE)} to "
                     f"guide the arm by hand, or re-arm ({keys.name(keys.REARM)}), which turns it on too.")


def freedrive_unless_stopped(node: DOMNode, turn_on: Callable[[], None], say_off: Callable[[str], None]) -> None:
    """``turn_on`` (the screen's freedrive action) as ``node``'s screen opens; while the wizard is STOPPED freedrive
    stays off instead, and ``say_off`` shows ``OFF_WHILE_STOPPED``."""
    if services(node).stopped:
        say_off(OFF_WHILE_STOPPED)
    else:
        turn_on()


def say_off_once_stopped(node: DOMNode, say_off: Callable[[str], None]) -> None:
    """For a screen whose text says freedrive is on: whenever the wizard becomes STOPPED while it is open (STOP or a
    protective stop, which end freedrive), ``say_off(OFF_WHILE_STOPPED)``; turning freedrive on says it again."""
    def changed(stopped: bool) -> None:
        if stopped:
            say_off(OFF_WHILE_STOPPED)

    node.watch(node.app, "stopped", changed, init=False)


def freedrive_on(robot: Robot) -> Callable[[], None]:
    """The call that turns ``robot``'s freedrive on, for a worker thread. Made as the key (or re-arm, or the screen's
    opening) is handled, it reads the robot's STOP count then: a STOP pressed before the worker's call reaches the
    robot keeps the arm held (``MotionStopped``), as it does for a tap asked for before a STOP."""
    stop_mark = robot.stop_count()
    return lambda: robot.freedrive(True, stop_mark=stop_mark)
