"""The tip-calibration screens in order: pivot, table points, automatic taps, result. Back goes one step
back with everything recorded kept; redo starts again with nothing recorded."""

from textual.app import App

from fixwizard.tui.cell import Cell, SavedCalibration
from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import (
    DEFAULT_BALL_DIAMETER_M,
    CalibrationResultScreen,
)
from fixwizard.workflow.robot_calibration import RobotTipCalibration

STEPS = (PivotScreen, TablePointsScreen, AutoTapsScreen, CalibrationResultScreen)


async def calibrate_tip_on_screens(app: App[None], cell: Cell) -> SavedCalibration | None:
    """Walk the operator through a new tip calibration (call from an async worker): the calibration once one is
    accepted and saved, None when they went back from the pivot."""
    workflow = RobotTipCalibration(cell.robot, DEFAULT_BALL_DIAMETER_M)
    step = 0
    while 0 <= step < len(STEPS):
        outcome = await app.push_screen_wait(STEPS[step](cell, workflow))
        if isinstance(outcome, SavedCalibration):
            return outcome
        if outcome == "redo":
            workflow, step = RobotTipCalibration(cell.robot, DEFAULT_BALL_DIAMETER_M), 0
        else:
            step += 1 if outcome == "next" else -1
    return None
