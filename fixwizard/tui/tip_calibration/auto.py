"""The automatic tip-calibration step: the robot taps the table grid, then the tilted taps, with progress
bars and cancel. Recorded taps survive a cancel, a STOP or a robot error; starting again continues."""

import threading

from textual.app import ComposeResult
from textual.containers import Horizontal
from textual.widgets import ProgressBar, Static

from fixwizard.robot.base import ProtectiveStop
from fixwizard.tui import keys
from fixwizard.tui.dismiss import dismiss_when_on_top
from fixwizard.tui.freedrive import freedrive_on
from fixwizard.tui.tip_calibration.step import CalibrationStepScreen
from fixwizard.tui.workers import services
from fixwizard.workflow.robot_calibration import AwayFromCorner, Cancelled, Step

AUTO_TEXT = (
    "The robot now moves by itself: it lifts the ball {height_mm:.0f} mm above the table, taps a {rows} x {cols} "
    "grid in the corner between A, B and C, then taps {tilted} times near B with the tool tilted. Keep clear of "
    "the cell; the STOP key (F12) halts it at once. Press {go} to {start}.")
AWAY_TEXT = "Press {freedrive} to turn freedrive on, guide the ball there, then press {go}."
CONTINUED_TEXT = (
    "This calibration goes on where it stopped, with every tap recorded before. If the arm was moved since, turn "
    "freedrive on ({freedrive}) and bring the ball a few centimetres above the corner B first; then press {go}.")
AUTO_STEPS: tuple[Step, ...] = ("table", "tilted")
STEP_LABELS = {"table": "Table taps", "tilted": "Tilted taps"}
CANCEL_LABEL = "Cancel taps"  # the footer's Esc while the taps run: it cancels them, it does not go back


class AutoTapsScreen(CalibrationStepScreen):
    """Run the table and tilted taps in a worker; Esc cancels between two taps (and goes back when none run), and
    the footer names what it does now. The taps start only with the ball above the corner B: a calibration continued
    after the wizard left it, or taps refused to start with the ball away from it (the arm moved at the pivot
    meanwhile), let the operator guide the arm back there first (f, and m on the simulated cell): only once turned on
    with f is the arm guided by hand here, so that a re-arm after a STOP turns freedrive on again."""

    STEP = 3
    TITLE_TEXT = "automatic taps"
    BINDINGS = [keys.binding(keys.GO), keys.binding(keys.HANDS), keys.binding(keys.FREEDRIVE), keys.binding(keys.NEXT)]
    HELP_ABOUT = ("The robot taps the table by itself: a grid in the corner of A, B and C, then tilted taps near "
                  "B. Keep clear of the cell; STOP (F12) halts it at once, Esc cancels after the current tap and "
                  "going on continues where it stopped. Once all taps are done, go on to the result. The taps start "
                  "with the ball above the corner B: when it is away (a calibration continued, the arm moved), f "
                  "(freedrive) lets you guide it there.")

    _cancel: threading.Event | None = None  # set to cancel the taps that run; None while none run
    _freedrive_on = False  # the operator turned freedrive on (f) and no taps ran since
    _away = False  # the taps refused to start with the ball away from the corner, and none started since

    def body(self) -> ComposeResult:
        workflow = self.workflow
        rows, cols = workflow.table_grid
        started = self._continued() or any(len(self.workflow.poses(step)) for step in AUTO_STEPS)
        yield Static(AUTO_TEXT.format(height_mm=workflow.approach_height_m * 1e3, rows=rows, cols=cols,
                                      tilted=self._totals()["tilted"], go=keys.name(keys.GO),
                                      start="go on" if started else "start"))
        for step in AUTO_STEPS:
            with Horizontal(classes="progress-row"):
                yield Static(STEP_LABELS[step], classes="progress-label")
                yield ProgressBar(total=self._totals()[step], show_eta=False, id=f"progress-{step}")
        yield Static("", id="auto-state", classes="state", markup=False)

    def _totals(self) -> dict[Step, int]:
        rows, cols = self.workflow.table_grid
        return {"table": rows * cols, "tilted": self.workflow.azimuths * len(self.workflow.tilts_deg)}

    def _finished(self) -> bool:
        return all(len(self.workflow.poses(step)) == total for step, total in self._totals().items())

    def on_mount(self) -> None:
        for step in AUTO_STEPS:
            self._progress(step, len(self.workflow.poses(step)))
        if self._finished():
            self._show("All taps are done: press n for the result.")
        elif self._continued():
            self._show(CONTINUED_TEXT.format(freedrive=keys.name(keys.FREEDRIVE), go=keys.name(keys.GO))
                       + self._simulated_hands_line())

    def _simulated_hands_line(self) -> str:
        """On the simulated cell, the line that offers its hands to bring the ball above B (else nothing)."""
        return (f"\nSIMULATED: press {keys.name(keys.HANDS)} and the simulated hands bring the ball above B."
                if self.cell.hands is not None else "")

    def action_freedrive(self) -> None:
        def on(_: None) -> None:
            self._freedrive_on = True
            self._show(f"Freedrive is on: bring the ball a few centimetres above the corner B, then press "
                       f"{keys.name(keys.GO)}.")

        self.run_robot(freedrive_on(self.cell.robot), on)

    def guided_by_hand(self) -> bool:
        """Whether the operator guides the arm by hand here now (freedrive turned on with f, and no taps since): a
        re-arm after a STOP turns freedrive on again only then. Elsewhere the taps hold the arm, or it stands where
        the table point C or the last tap left it."""
        return self._freedrive_on

    def action_simulated_hands(self) -> None:
        hands = self.cell.simulated_hands()
        self.run_robot(lambda: hands.table_point("B"), lambda _: self._show(f"Press {keys.name(keys.GO)} to go on."),
                       doing="SIMULATED: the operator's hands bring the ball above the corner B")

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in (keys.BACK.action, keys.NEXT.action) and self._cancel is not None:
            return True  # Esc cancels the running taps, n says they are running
        if action in (keys.FREEDRIVE.action, keys.HANDS.action) and not (self._continued() or self._away):
            return False  # the arm is where the table point C left it: nothing to guide by hand
        allowed = super().check_action(action, parameters)
        if allowed and action == keys.GO.action and self._finished():
            return None
        return allowed

    def _continued(self) -> bool:
        """Whether this calibration was continued from its journal after the wizard left it."""
        return self.workflow.journal is not None and self.workflow.journal.continued

    def action_go(self) -> None:
        robot, workflow, app = self.cell.robot, self.workflow, self.app
        cancel = threading.Event()
        self._set_taps_cancel(cancel)
        self._freedrive_on = False  # the taps turn it off first
        self._away = False  # they start only with the ball above the corner
        services(self).cancel_on_stop(cancel)

        def progress(step: Step, done: int, total: int) -> None:
            app.call_from_thread(self._progress, step, done)

        def run() -> Cancelled | None:
            robot.freedrive(False)
            try:
                workflow.run_table_taps(progress, cancel)
                workflow.run_tilted_taps(progress, cancel)
            except Cancelled as cancelled:
                return cancelled
            return None

        self._show("Tapping... press Esc to cancel after the current tap.")
        self.run_robot(run, self._ended, lambda error: self._ended(error))

    def action_back(self) -> None:
        """Cancel the running taps (after the current one); else back to the table points, the taps kept."""
        if self._cancel is not None:
            self._cancel.set()
            self._show("Cancelling after the current tap...")
        else:
            super().action_back()

    def action_next(self) -> None:
        if self._finished():
            self.dismiss("next")
        elif self._cancel is not None:
            self.notify("Not yet: the automatic taps are running; the result comes once they are done.")
        else:
            self.notify(f"Not yet: press {keys.name(keys.GO)} to start the automatic taps; the result comes once "
                        "they are done.", severity="warning")

    def _set_taps_cancel(self, cancel: threading.Event | None) -> None:
        """The taps run, ``cancel`` cancels them, and Esc's footer label says so; or none run (None: Esc goes back)."""
        self._cancel = cancel
        keys.relabel(self, keys.BACK, None if cancel is None else CANCEL_LABEL)

    def _ended(self, outcome: Exception | None) -> None:
        if self._cancel is not None:
            services(self).forget_cancel(self._cancel)
        self._set_taps_cancel(None)
        if outcome is None:
            dismiss_when_on_top(self, "next")
        elif services(self).stopped or isinstance(outcome, ProtectiveStop):  # g is refused until re-armed
            self._show(f"Stopped: {outcome}\nOnce the cell is checked and clear, re-arm ({keys.name(keys.REARM)}), "
                       f"then press {keys.name(keys.GO)} to continue.")
        elif isinstance(outcome, AwayFromCorner):
            self._away = True
            self.refresh_bindings()
            away = AWAY_TEXT.format(freedrive=keys.name(keys.FREEDRIVE), go=keys.name(keys.GO))
            self._show(f"Not started: {outcome}.\n{away}{self._simulated_hands_line()}")
        elif isinstance(outcome, Cancelled):
            self._show(f"{outcome}. Press {keys.name(keys.GO)} to continue.")
        else:
            self._show(f"Stopped: {outcome}\nPress {keys.name(keys.GO)} to continue once the cell is ready.")

    def _progress(self, step: Step, done: int) -> None:
        """A tap of ``step`` done (from the taps' thread): the wizard may be quitting, its widgets gone already."""
        for bar in self.query(f"#progress-{step}").results(ProgressBar):
            bar.update(progress=done)

    def _show(self, text: str) -> None:
        self.query_one("#auto-state", Static).update(text)
