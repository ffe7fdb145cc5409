"""What every tip-calibration screen shares: the step title, the workflow it drives, robot calls in a
worker with the step's keys disabled meanwhile, and dismissing with "next", "back" or "redo" (the last step with
the saved calibration instead of "next")"""

import threading
from collections.abc import Callable
from typing import Literal, TypeVar

from textual.app import ComposeResult
from textual.containers import VerticalScroll
from textual.screen import Screen
from textual.widgets import Static

from fixwizard.tui import keys
from fixwizard.tui.cell import Cell, SavedCalibration
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.doing import Doing
from fixwizard.tui.workers import ShownError, in_thread, services
from fixwizard.workflow.robot_calibration import RobotTipCalibration

StepOutcome = Literal["next", "back", "redo"] | SavedCalibration
T = TypeVar("T")
STEP_COUNT = 4


class CalibrationStepScreen(Screen[StepOutcome]):
    """A step of the tip calibration; subclasses set ``STEP``, ``TITLE_TEXT`` and compose ``body``."""

    BINDINGS = [keys.binding(keys.BACK)]
    STEP = 0
    TITLE_TEXT = ""
    HELP_ABOUT = ""

    def __init__(self, cell: Cell, workflow: RobotTipCalibration) -> None:
        super().__init__()
        self.cell = cell
        self.workflow = workflow
        self.busy = False
        self.HELP_TITLE = f"tip calibration, step {self.STEP} of {STEP_COUNT}: {self.TITLE_TEXT}"

    def compose(self) -> ComposeResult:
        with VerticalScroll():
            yield Static(f"Tip calibration, step {self.STEP} of {STEP_COUNT}: {self.TITLE_TEXT}", classes="title")
            yield from self.body()
            yield Static("", id="doing", classes="state -empty", markup=False)

    def body(self) -> ComposeResult:
        yield from ()

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in keys.SIMULATED_ACTIONS and self.cell.hands is None:
            return False
        return None if self.busy else True

    def run_robot(self, call: Callable[[], T], on_done: Callable[[T], None],
                  on_failed: Callable[[ShownError], None] | None = None, doing: str | None = None,
                  cancel: threading.Event | None = None) -> None:
        """Run a robot call in a worker with this step's keys disabled until it finishes; ``doing``: what it does,
        said at once (with the seconds it takes) on the step's doing line, which is cleared afterwards; ``cancel``:
        set by STOP while the call runs."""
        self._set_busy(True)
        if cancel is not None:
            services(self).cancel_on_stop(cancel)
        line = self.query_one("#doing", Static)
        shown = None
        if doing is not None:
            shown = Doing(line)
            shown.start(doing)

        def finished() -> None:
            if cancel is not None:
                services(self).forget_cancel(cancel)
            self._set_busy(False)
            if shown is not None:
                shown.done()
                line.update("")
                line.add_class("-empty")

        def done(result: T) -> None:
            finished()
            on_done(result)

        def failed(error: ShownError) -> None:
            finished()
            if on_failed is not None:
                on_failed(error)

        in_thread(self, call, done, failed)

    def _set_busy(self, busy: bool) -> None:
        self.busy = busy
        self.refresh_bindings()

    def action_back(self) -> None:
        self.dismiss("back")

    def confirm_discard(self, what: str, then: Callable[[], None]) -> None:
        """Ask before a step back that drops ``what`` (e.g. "the 4 captured poses"); ``then`` once confirmed."""
        def answered(yes: bool | None) -> None:
            if yes:
                then()

        self.app.push_screen(Confirm("Discard what was recorded?", f"Going back drops {what}; you would record "
                                     "them again.", "Discard and go back", "Stay"), answered)
