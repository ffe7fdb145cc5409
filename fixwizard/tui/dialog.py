"""A modal dialog: a title, a message and a row of buttons; subclasses choose the buttons and the result."""

from collections.abc import Iterable
from typing import TypeVar

from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Static

ResultType = TypeVar("ResultType")


class Dialog(ModalScreen[ResultType]):
    """Title in reverse video, the message, then ``buttons()``; the button with id ``focused_id`` has focus."""

    DEFAULT_CSS = """
    Dialog { align: center middle; }
    Dialog > Vertical { width: 72; height: auto; max-height: 20; background: $surface; padding: 0 1; }
    Dialog #dialog-title { text-style: bold reverse; width: 100%; }
    Dialog #dialog-message { margin: 1 0; }
    Dialog Horizontal { height: auto; }
    Dialog Button { margin-right: 1; }
    """
    focused_id = "ok"

    def __init__(self, title: str, message: str) -> None:
        super().__init__()
        self.title_text = title
        self.message = message

    def buttons(self) -> Iterable[Button]:
        yield Button("OK", id="ok", variant="primary")

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static(f" {self.title_text} ", id="dialog-title", markup=False)
            yield Static(self.message, id="dialog-message", markup=False)
            with Horizontal():
                yield from self.buttons()

    def on_mount(self) -> None:
        self.query_one(f"#{self.focused_id}", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id)
