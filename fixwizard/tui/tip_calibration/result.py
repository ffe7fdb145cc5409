"""The last tip-calibration step: a plain verdict (good / usable / redo, and why), the tip and how far each tap
is trusted, the fit's own figures on Details; accept (name, ball diameter, saved under ``calibrations_dir``) or
redo from the pivot."""

import re
from datetime import datetime
from pathlib import Path

from textual.app import ComposeResult
from textual.containers import Horizontal
from textual.widgets import Button, Input, Static

from fixwizard.calibration.calibrate import MAX_BALL_DIAMETER_M
from fixwizard.calibration.store import TipCalibration, save_calibration
from fixwizard.calibration.verdict import tip_verdict
from fixwizard.tui.cell import SavedCalibration
from fixwizard.tui.dismiss import dismiss_when_on_top
from fixwizard.tui.tip_calibration.step import CalibrationStepScreen
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.dialog import Dialog
from fixwizard.workflow.tip_calibration import summary_lines

DEFAULT_BALL_DIAMETER_M = 0.003
NAME_PATTERN = re.compile(r"[A-Za-z0-9_.-]+")


def default_name(simulated: bool) -> str:
    return f"{'simulated-' if simulated else ''}tip-{datetime.now():%Y%m%d-%H%M}"


def result_lines(calibration: TipCalibration) -> list[str]:
    """The verdict and why, the tip, and how far each tap will be trusted, in plain words."""
    verdict = tip_verdict(calibration)
    x, y, z = calibration.tcp_p_tip_m * 1e3
    return [verdict.headline(), *(f"- {reason[0].upper()}{reason[1:]}." for reason in verdict.reasons),
            f"Ball centre from the flange: x {x:.2f}, y {y:.2f}, z {z:.2f} mm.",
            f"Each tap will be trusted to {calibration.sample_bound_m * 1e3:.1f} mm (the sample bound). Details shows "
            "the fit's own figures."]


def details_lines(calibration: TipCalibration) -> list[str]:
    """The residual figures, then the proposed sample bound with its reason."""
    figures = [line for line in summary_lines(calibration) if not line.startswith("proposed sample bound")]
    return [*figures, f"Proposed sample bound {calibration.sample_bound_reason}"]


class CalibrationResultScreen(CalibrationStepScreen):
    """Show the calibration; Accept saves it and dismisses with it, Redo starts again."""

    STEP = 4
    TITLE_TEXT = "result"
    HELP_ABOUT = ("Read the residuals and the proposed sample bound, check the ball diameter (as measured or from "
                  "the data sheet) and the file name, then accept to save the calibration, or redo it from the "
                  "pivot. Esc goes back to the automatic taps, which are kept. Tab moves between the fields and "
                  "buttons.")

    calibration: TipCalibration | None = None

    def body(self) -> ComposeResult:
        yield Static("Computing...", id="result-figures", markup=False)
        with Horizontal(classes="field"):
            yield Static("Save as", classes="field-label")
            yield Input(default_name(self.cell.simulated), id="name", compact=True)
        with Horizontal(classes="field"):
            yield Static("Ball diameter", classes="field-label")
            yield Input(f"{DEFAULT_BALL_DIAMETER_M * 1e3:g}", id="ball-diameter", compact=True, type="number")
            yield Static(" mm (as measured or from the data sheet)")
        with Horizontal(classes="buttons"):
            yield Button("Accept and save", id="accept", variant="primary", compact=True)
            yield Button("Redo from the pivot", id="redo", compact=True)
            yield Button("Details", id="details", compact=True, disabled=True)

    def on_mount(self) -> None:
        self.query_one("#accept", Button).disabled = True
        self.run_robot(lambda: self.workflow.result(robot=self.cell.robot_name), self._show_result,
                       self._show_problem)
        self.query_one("#accept", Button).focus()

    def _show_result(self, calibration: TipCalibration) -> None:
        self.calibration = calibration
        self.query_one("#result-figures", Static).update("\n".join(result_lines(calibration)))
        self.query_one("#details", Button).disabled = False
        accept = self.query_one("#accept", Button)
        accept.disabled = False
        accept.focus()

    def _show_problem(self, error: Exception) -> None:
        self.query_one("#result-figures", Static).update(f"No calibration: {error}\nRedo it from the pivot.")
        self.query_one("#redo", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if self.busy:
            return
        if event.button.id == "redo":
            self._ask_redo()
        elif event.button.id == "details" and self.calibration is not None:
            self.app.push_screen(Dialog("Tip calibration: details", "\n".join(details_lines(self.calibration))))
        elif event.button.id == "accept":
            self._accept()

    def _ask_redo(self) -> None:
        """Redo starts again from the pivot with nothing recorded: asks first, as going back does."""
        workflow = self.workflow
        recorded = (f"the {len(workflow.poses('pivot'))} pivot poses, the {len(workflow.poses('table_coarse'))} "
                    f"table points and the {len(workflow.poses('table')) + len(workflow.poses('tilted'))} automatic "
                    "taps")

        def answered(yes: bool | None) -> None:
            if yes:
                self.run_robot(workflow.restart, lambda _: dismiss_when_on_top(self, "redo"))

        self.app.push_screen(Confirm("Redo the tip calibration?", f"Redo drops {recorded}, and starts again from "
                                     "the pivot; you would record them again.", "Drop them and redo", "Stay"),
                             answered)

    def _accept(self) -> None:
        name = self.query_one("#name", Input).value.strip()
        if not NAME_PATTERN.fullmatch(name):
            self.notify("Give a file name of letters, digits, '-', '_' or '.'.", severity="warning")
            return
        path = self.cell.calibrations_dir / f"{name}.yaml"
        if path.exists():
            self.notify(f"{path} exists already: choose another name.", severity="warning")
            return
        try:
            ball_diameter_m = float(self.query_one("#ball-diameter", Input).value) / 1e3
        except ValueError:
            ball_diameter_m = 0.0
        if not 0.0 < ball_diameter_m <= MAX_BALL_DIAMETER_M:
            self.notify(f"Give the ball diameter in mm, between 0 and {MAX_BALL_DIAMETER_M * 1e3:.0f}.",
                        severity="warning")
            return
        self.run_robot(lambda: self._save(name, ball_diameter_m, path), self._saved)

    def _save(self, name: str, ball_diameter_m: float, path: Path) -> SavedCalibration:
        """The calibration with the operator's name and ball diameter, written to ``path`` (worker thread)."""
        self.workflow.ball_diameter_m = ball_diameter_m
        calibration = self.workflow.result(name, self.cell.robot_name)
        return SavedCalibration(calibration, save_calibration(calibration, path))

    def _saved(self, saved: SavedCalibration) -> None:
        dismiss_when_on_top(self, saved)  # the sampling screen says where it was saved

