"""The status bar on top of every screen: SIMULATED badge, robot name, connection, mode, protective and
emergency stop, and the STOP key. It shows ``RobotStatus`` values the app polls in a worker thread."""

from rich.text import Text
from textual.widgets import Static

from fixwizard.robot.base import RobotStatus

STOP_KEYS = "f12,ctrl+x"
STOP_KEY_HINT = "F12 STOP"


def status_text(status: RobotStatus | None, robot_name: str, simulated: bool) -> Text:
    """One line for an 80-column terminal; alarms in reverse video so they stand out without colour. A
    simulated robot's name loses its SIMULATED prefix to the badge."""
    text = Text()
    if simulated:
        text.append(" SIMULATED ", "bold reverse")
        text.append(" ")
        robot_name = robot_name.removeprefix("SIMULATED ")
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
    text.append(f" | {STOP_KEY_HINT}")
    return text


class StatusBar(Static):
    """Docked on top; follows the app's ``robot_status`` (set on the event loop only)."""

    DEFAULT_CSS = """
    StatusBar {
        dock: top;
        height: 1;
        background: $panel;
        color: $foreground;
    }
    StatusBar.-alarm {
        background: $error;
        color: $text;
    }
    """

    def on_mount(self) -> None:
        self.watch(self.app, "robot_status", self._show)

    def _show(self, status: RobotStatus | None) -> None:
        context = self.app.context
        self.update(status_text(status, context.robot_name, context.simulated))
        self.set_class(status is not None and (not status.connected or status.protective_stop
                                               or status.emergency_stop), "-alarm")
