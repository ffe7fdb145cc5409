"""The wizard's first screen, under every step: what the terminal shows until the flow's first step is up, which
with ``--resume`` waits for the session's mesh to load (seconds for a large one), and its help."""

from textual.app import ComposeResult
from textual.screen import Screen
from textual.widgets import Static

OPENING = "Opening the session to resume: loading its fixture and tip calibration..."


class Opening(Screen[None]):
    """The app's default screen; ``resuming``: it says the session is being opened (the app adds the status line
    and the footer)."""

    HELP_TITLE = "starting"
    HELP_ABOUT = ("The wizard is starting. With --resume it first loads the session's fixture and tip calibration "
                  "(seconds for a large mesh), then shows its sampling screen, or the start screen saying why it "
                  "cannot.")

    def __init__(self, resuming: bool) -> None:
        super().__init__(id="_default")
        self.resuming = resuming

    def compose(self) -> ComposeResult:
        if self.resuming:
            yield Static(OPENING, id="opening", markup=False)
