"""Errors as the operator sees them: a modal with what happened and the next step, and the recovery the
wizard can do from there (reconnect; unlock the protective stop, on a UR arm through its dashboard and on a
simulated cell as the teach pendant would)."""

from collections.abc import Iterable
from typing import Literal

from textual.widgets import Button

from fixwizard.calibration.errors import CalibrationError
from fixwizard.errors import FixwizardError, InputError, file_problem, sentence
from fixwizard.robot.base import ConnectionLost, ProtectiveStop, RobotError
from fixwizard.tui.widgets.dialog import Dialog

Recovery = Literal["ok", "reconnect", "unlock"]


class ResumeRefused(InputError):
    """A session that could not be resumed: which one, why, and what to do next."""


def error_title(error: Exception) -> str:
    """A short heading naming what kind of problem it is."""
    if isinstance(error, ResumeRefused):
        return "Cannot resume the session"
    if isinstance(error, RobotError):
        return "Robot problem"
    if isinstance(error, CalibrationError):  # the poses or the arm's place, not a file (that is CalibrationFileError)
        return "Tip calibration problem"
    if isinstance(error, (InputError, OSError)):
        return "File or input problem"
    return "Problem"


def error_text(error: FixwizardError | OSError) -> str:
    """The error's own text (it says what to do next), or a readable clause for a file system error."""
    return file_problem(error) if isinstance(error, OSError) else str(error)


def error_message(error: FixwizardError | OSError) -> str:
    """``error_text`` as a sentence, with the error's notes (e.g. that a tap's contact was kept)."""
    return sentence(error, error_text(error))


class ErrorModal(Dialog[Recovery]):
    """Shows one error; dismisses with "ok", "reconnect" or "unlock" (the caller does the recovery)."""


    def __init__(self, error: FixwizardError | OSError, simulated: bool, can_unlock: bool = False,
                 reconnect: bool = False) -> None:
        super().__init__(error_title(error), error_message(error))
        self.error = error
        self.simulated = simulated
        self.can_unlock = can_unlock  # the robot unlocks a protective stop from fixwizard (a UR arm does)
        self.reconnect = reconnect  # offer Reconnect whatever the error (a connect that failed)

    def buttons(self) -> Iterable[Button]:
        yield Button("OK", id="ok", variant="primary")
        if isinstance(self.error, ConnectionLost) or self.reconnect:
            yield Button("Reconnect", id="reconnect")
        if isinstance(self.error, ProtectiveStop) and self.simulated:
            yield Button("SIMULATED: unlock (teach pendant)", id="unlock")
        elif isinstance(self.error, ProtectiveStop) and self.can_unlock:
            yield Button("Unlock (cell checked)", id="unlock")
