"""The tip-calibration screens in order: pivot, table points, automatic taps, result. Back goes one step
back with everything recorded kept; redo starts again with nothing recorded. Every recorded pose is in the
calibration's journal as it counts, so an unfinished calibration continues at the step it reached."""

import asyncio
from pathlib import Path

from textual.app import App

from fixwizard.calibration.errors import CalibrationError
from fixwizard.journal import said
from fixwizard.tui.cell import Cell, SavedCalibration
from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import (
    DEFAULT_BALL_DIAMETER_M,
    CalibrationResultScreen,
)
from fixwizard.workflow.calibration_journal import CalibrationJournal, CalibrationJournalError, journals_dir
from fixwizard.workflow.robot_calibration import TABLE_POINTS, RobotTipCalibration

STEPS = (PivotScreen, TablePointsScreen, AutoTapsScreen, CalibrationResultScreen)


def open_tip_calibration(cell: Cell, unfinished: Path | None) -> RobotTipCalibration:
    """A new tip calibration on the cell's robot with a new journal, or the unfinished one journaled at
    ``unfinished`` continued (refused when it was taken on another robot). Blocking: call from a worker thread."""
    if unfinished is None:
        return RobotTipCalibration.journaled(cell.robot, cell.robot_name, journals_dir(cell.calibrations_dir),
                                             DEFAULT_BALL_DIAMETER_M)
    journal = CalibrationJournal.open(unfinished)
    try:
        if journal.robot != cell.robot_name:
            raise CalibrationJournalError(f"the tip calibration {unfinished.name} was taken on '{journal.robot}', "
                                          f"not on '{cell.robot_name}': continue it with that robot, or start a new "
                                          "one")
        return RobotTipCalibration.resume(cell.robot, journal)
    except BaseException:
        journal.release()
        raise


def reached_step(workflow: RobotTipCalibration) -> int:
    """The index in ``STEPS`` where a calibration with these poses goes on: the pivot until its fit is good, the
    table points until all three are tapped, else the automatic taps (which show what is done)."""
    try:
        workflow.pivot_fit()
    except CalibrationError:
        return 0
    return 1 if len(workflow.poses("table_coarse")) < len(TABLE_POINTS) else 2


async def calibrate_tip_on_screens(app: App[None], cell: Cell,
                                   workflow: RobotTipCalibration) -> SavedCalibration | None:
    """Walk the operator through the tip calibration ``workflow`` from the step it reached (call from an async
    worker): the calibration once one is accepted and saved, None when they went back from the pivot."""
    if workflow.journal is not None:
        for note in said(workflow.journal.recovered):
            app.notify(f"{note}.", severity="warning", timeout=15)
    step = reached_step(workflow)
    try:
        while 0 <= step < len(STEPS):
            outcome = await app.push_screen_wait(STEPS[step](cell, workflow))
            if isinstance(outcome, SavedCalibration):
                return outcome
            if outcome == "redo":  # the result screen dropped every pose
                step = 0
            else:
                step += 1 if outcome == "next" else -1
    except asyncio.CancelledError:  # the wizard quits: the calibration stays unfinished, to be continued
        if workflow.journal is not None:
            workflow.journal.release()
        raise
    return None
