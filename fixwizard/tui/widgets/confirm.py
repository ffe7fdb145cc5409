"""Yes/no questions: before the robot moves on its own (``ConfirmMove``) and before anything that drops what was
recorded, quits during motion or re-arms after a STOP (``Confirm``). y or the first button confirms; n, Escape
or the second button cancels, and the second button has the focus."""

from collections.abc import Iterable

from textual.widgets import Button

from fixwizard.tui import keys
from fixwizard.tui.widgets.dialog import Dialog


class Confirm(Dialog[bool]):
    """Asks ``message``; dismisses with True for ``yes_label``, False for ``no_label`` (focused)."""

    BINDINGS = [keys.binding(keys.YES), keys.binding(keys.NO)]
    focused_id = "no"
    HELP_TITLE = "a question"
    HELP_ABOUT = "Answer the question: y does what the first button says, n or Esc changes nothing."

    def __init__(self, title: str, message: str, yes_label: str, no_label: str = "Cancel") -> None:
        super().__init__(title, message)
        self.yes_label, self.no_label = yes_label, no_label

    def buttons(self) -> Iterable[Button]:
        yield Button(f"{self.yes_label} ({keys.name(keys.YES)})", id="yes", variant="warning")
        yield Button(f"{self.no_label} ({keys.name(keys.NO)})", id="no", variant="primary")

    def action_yes(self) -> None:
        self.dismiss(True)

    def action_no(self) -> None:
        self.dismiss(False)

    def result_of(self, button_id: str) -> bool:
        return button_id == "yes"


class ConfirmMove(Confirm):
    """Asks before a robot motion; dismisses with True to move."""

    def __init__(self, title: str, message: str) -> None:
        super().__init__(title, message, "Move")
