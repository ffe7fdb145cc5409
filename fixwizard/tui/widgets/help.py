"""The help screen (``?`` on every screen): what to do on this step in one paragraph, the keys of this screen
and the ones that work everywhere, each with what it does. Esc, n or ``?`` closes it."""

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Static

from fixwizard.tui import keys

NOT_NOW = " (not now)"


def key_lines(entries: list[tuple[keys.Key, bool]]) -> list[str]:
    """One line per key: its name, label and explanation; ``False`` marks a key that does nothing right now."""
    return [f"  {key.shown:7} {key.label}{'' if enabled else NOT_NOW}: {key.explanation}"
            for key, enabled in entries]


def help_text(about: str, screen_keys: list[tuple[keys.Key, bool]], stopped: bool) -> str:
    """The help screen's text: the step's paragraph, its keys, then the keys of every screen (but ``?``, which the
    reader has just pressed: a line less to fit at 80x24)."""
    lines = [about, ""]
    if stopped:
        lines += [f"STOPPED: the robot keys are refused until you re-arm ({keys.name(keys.REARM)}) once the cell "
                  "is checked and clear.", ""]
    if screen_keys:
        lines += ["Keys on this screen:", *key_lines(screen_keys), ""]
    lines += ["Keys everywhere:", *key_lines([(key, True) for key in keys.GLOBAL_KEYS if key != keys.HELP]),
              "  Tab     moves between fields; Enter opens a list or presses a button"]
    return "\n".join(lines)


class HelpScreen(ModalScreen[None]):
    """The help over the screen it explains; ``text`` from ``help_text``."""

    BINDINGS = [keys.binding(keys.NO, "Close"), keys.binding(keys.HELP, "Close", show=False)]

    def __init__(self, title: str, text: str) -> None:
        super().__init__()
        self.title_text, self.text = title, text

    def compose(self) -> ComposeResult:
        with Vertical() as box:  # the title and how to close it are in its border: every row left is the text's
            box.border_title = Text(f" Help: {self.title_text} ")
            box.border_subtitle = Text(f" {keys.name(keys.NO)} or Esc closes this help; Up/Down scroll it ")
            yield VerticalScroll(Static(self.text, id="help-text", markup=False))

    def action_no(self) -> None:
        self.dismiss(None)

    def action_help(self) -> None:
        self.dismiss(None)
