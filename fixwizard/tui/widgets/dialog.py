"""A modal dialog: a title, a message (scrolls when it is longer than the screen, by Up/Down and PgUp/PgDn) and a
row of buttons; subclasses choose the buttons and the result. n or Esc closes it as its first button would; ? shows
its help."""

from collections.abc import Iterable
from typing import TypeVar, cast

from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Button, Static

from fixwizard.tui import keys

ResultType = TypeVar("ResultType")


class Dialog(ModalScreen[ResultType]):
    """Title in reverse video, the message, then ``buttons()``; the button with id ``focused_id`` has focus."""

    # ? is the app's, but a modal screen cuts the app's bindings off (all but the priority ones): it is bound here too
    BINDINGS = [keys.binding(keys.NO, "Close"),
                *(keys.binding(key, show=False) for key in (keys.SCROLL_DOWN, keys.SCROLL_UP, keys.PAGE_DOWN,
                                                             keys.PAGE_UP, keys.HELP))]
    focused_id = "ok"
    HELP_TITLE = "a message"
    HELP_ABOUT = ("Read the message (Up/Down and PgUp/PgDn scroll a long one); Enter presses the focused button, Tab "
                  "moves between the buttons.")

    def __init__(self, title: str, message: str) -> None:
        super().__init__()
        self.title_text = title
        self.message = message

    def buttons(self) -> Iterable[Button]:
        yield Button("OK", id="ok", variant="primary")

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static(f" {self.title_text} ", id="dialog-title", markup=False)
            yield VerticalScroll(Static(self.message, id="dialog-message", markup=False), id="dialog-scroll",
                                 can_focus=False)
            with Horizontal():
                yield from self.buttons()

    def on_mount(self) -> None:
        self.query_one(f"#{self.focused_id}", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(self.result_of(event.button.id or ""))

    def result_of(self, button_id: str) -> ResultType:
        """The result of the button ``button_id``: a plain dialog's is the id. Subclasses override this, never the
        handler: Textual calls the handler of every class in the chain, so a second one would close the screen
        under the dialog too."""
        return cast(ResultType, button_id)

    def action_no(self) -> None:
        self.dismiss(cast(ResultType, "ok"))

    def action_help(self) -> None:
        """The app's help, about this dialog."""
        help_of = getattr(self.app, "action_help", None)
        if help_of is not None:
            help_of()

    def action_scroll_summary(self, lines: int) -> None:
        """Scroll the message by ``lines`` (the focus stays on a button, so the keys scroll it from here)."""
        self.query_one("#dialog-scroll", VerticalScroll).scroll_relative(y=lines, animate=False)
