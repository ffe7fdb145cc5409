"""Said instead of a screen cut off: the wizard is made for 80x24, and in a smaller terminal its fields, lines and
footer keys would be cut. Below ``MIN_SIZE`` the step's screen is covered by what the terminal measures, what it
needs and what to do, framed as every screen is (status line, footer with STOP, Quit and Help); the screen under it
goes on (an automatic step keeps running) and is back as it was once the terminal is large enough."""

from textual.app import ComposeResult
from textual.geometry import Size
from textual.screen import Screen
from textual.widgets import Static

from fixwizard.tui import keys

MIN_SIZE = Size(80, 23)  # 80x24, less the line tmux keeps for its status bar


def too_small(size: Size) -> bool:
    return size.width < MIN_SIZE.width or size.height < MIN_SIZE.height


def too_small_text(size: Size, step: str) -> str:
    """The notice, its point first (a very small terminal shows only its first line)."""
    return (f"Terminal too small: {size.width}x{size.height}, the wizard needs {MIN_SIZE.width}x{MIN_SIZE.height}.\n\n"
            f"Make the window larger (or the font smaller): this step ({step}) comes back as it was; what it was "
            f"doing goes on meanwhile. {keys.name(keys.STOP)} stops the robot, {keys.name(keys.QUIT)} quits.")


class TooSmall(Screen[None]):
    """Covers the step ``step`` (its help title) while the terminal is too small; the app closes it. A full screen,
    not a modal one: the app's keys (STOP, Quit, Help) stay in its footer."""

    HELP_TITLE = "terminal too small"
    HELP_ABOUT = (f"This terminal is smaller than the {MIN_SIZE.width}x{MIN_SIZE.height} the wizard's screens need. "
                  "Make the window larger: the step comes back as it was, and what it was doing went on meanwhile.")

    def __init__(self, step: str) -> None:
        super().__init__()
        self.step = step

    def compose(self) -> ComposeResult:
        yield Static(too_small_text(self.app.size, self.step), id="too-small", markup=False)

    def on_resize(self) -> None:
        self.query_one("#too-small", Static).update(too_small_text(self.app.size, self.step))
