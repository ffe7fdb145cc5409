"""Errors as the operator sees them: a modal with what happened and the next step, and the recovery the
wizard can do from there (reconnect; on a simulated cell, unlock the protective stop)."""

from typing import Literal

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Static

from fixwizard.errors import FixwizardError, InputError
from fixwizard.robot.base import ConnectionLost, ProtectiveStop, RobotError

Recovery = Literal["ok", "reconnect", "unlock"]


def error_title(error: Exception) -> str:
    """A short heading naming what kind of problem it is."""
    if isinstance(error, RobotError):
        return "Robot problem"
    if isinstance(error, (InputError, OSError)):
        return "File or input problem"
    return "Problem"


def error_message(error: FixwizardError | OSError) -> str:
    """The error's own text (it says what to do next), or a readable line for a file system error."""
    if isinstance(error, OSError):
        where = f" {error.filename}" if error.filename else ""
        return (f"cannot read or write{where}: {error.strerror or error}; check the path and that the folder "
                "is writable, then retry")
    text = str(error)
    return text[:1].upper() + text[1:]


class ErrorModal(ModalScreen[Recovery]):
    """Shows one error; dismisses with "ok", "reconnect" or "unlock" (the caller does the recovery)."""

    DEFAULT_CSS = """
    ErrorModal { align: center middle; }
    ErrorModal > Vertical {
        width: 72; height: auto; max-height: 20;
        border: thick $error; background: $surface; padding: 0 1;
    }
    ErrorModal #error-title { text-style: bold reverse; width: 100%; }
    ErrorModal #error-message { margin: 1 0; }
    ErrorModal Horizontal { height: auto; }
    ErrorModal Button { margin-right: 1; }
    """
    BINDINGS = [Binding("escape", "dismiss('ok')", "Close")]

    def __init__(self, error: FixwizardError | OSError, simulated: bool) -> None:
        super().__init__()
        self.error = error
        self.simulated = simulated

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static(f" {error_title(self.error)} ", id="error-title")
            yield Static(error_message(self.error), id="error-message", markup=False)
            with Horizontal():
                yield Button("OK", id="ok", variant="primary")
                if isinstance(self.error, ConnectionLost):
                    yield Button("Reconnect", id="reconnect")
                if isinstance(self.error, ProtectiveStop) and self.simulated:
                    yield Button("SIMULATED: unlock (teach pendant)", id="unlock")

    def on_mount(self) -> None:
        self.query_one("#ok", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id)
