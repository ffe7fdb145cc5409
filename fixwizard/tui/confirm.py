"""A yes/no question before the robot moves on its own: y or "Move" confirms, n, Escape or "Cancel" cancels."""

from collections.abc import Iterable

from textual.binding import Binding
from textual.widgets import Button

from fixwizard.tui.dialog import Dialog


class ConfirmMove(Dialog[bool]):
    """Asks before a robot motion; dismisses with True to move."""

    DEFAULT_CSS = "ConfirmMove > Vertical { border: thick $warning; }"
    BINDINGS = [Binding("y", "dismiss(True)", "Move"), Binding("n,escape", "dismiss(False)", "Cancel")]
    focused_id = "cancel"

    def buttons(self) -> Iterable[Button]:
        yield Button("Move (y)", id="move", variant="warning")
        yield Button("Cancel (n)", id="cancel", variant="primary")

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "move")
