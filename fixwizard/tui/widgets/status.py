"""The status bar on top of every screen: SIMULATED badge, robot name, connection, the robot's own mode,
protective and emergency stop, and the STOP key, or STOPPED with the re-arm key after a STOP. It shows
``RobotStatus`` values the app polls in a worker thread and the app's ``stopped`` state."""

from rich.text import Text
from textual.widgets import Static

from fixwizard.robot.base import RobotStatus
from fixwizard.tui import keys
from fixwizard.tui.workers import services


def status_text(status: RobotStatus | None, robot_name: str, simulated: bool, stopped: bool = False) -> Text:
    """One line for an 80-column terminal; alarms in reverse video so they stand out without colour. A
    simulated robot's name loses its SIMULATED prefix to the badge."""
    text = Text()
    if simulated:
        text.append(" SIMULATED ", "bold reverse")
        text.append(" ")
        robot_name = robot_name.removeprefix("SIMULATED ")
    if stopped:  # first, so that a narrow terminal never cuts it off
        text.append(" STOPPED ", "bold reverse")
        text.append(f" {keys.short_name(keys.REARM)} re-arms | ")
    text.append(robot_name, "bold")
    if status is None:
        text.append(" | status unknown")
    elif not status.connected:
        text.append(" | ")
        text.append(" DISCONNECTED ", "bold reverse")
    else:
        text.append(" | connected | ")
        if status.emergency_stop:
            text.append(" EMERGENCY STOP ", "bold reverse")
        elif status.protective_stop:
            text.append(" PROTECTIVE STOP ", "bold reverse")
        else:
            text.append(status.mode)
    if not stopped:
        text.append(f" | {keys.name(keys.STOP)} {keys.STOP.label}")
    return text


class StatusBar(Static):
    """Docked on top; follows the app's ``robot_status`` (set on the event loop only)."""

    def on_mount(self) -> None:
        self.watch(self.app, "robot_status", lambda _: self._show())
        self.watch(self.app, "stopped", lambda _: self._show())

    def _show(self) -> None:
        app = services(self)
        status, cell, stopped = app.robot_status, app.cell, app.stopped
        self.update(status_text(status, cell.robot_name, cell.simulated, stopped))
        self.set_class(stopped or (status is not None and (not status.connected or status.protective_stop
                                                           or status.emergency_stop)), "-alarm")
