"""How the wizard lets go of a session when the operator is done with it (Pilot, simulated demo cell, a real 64 KiB
tmpfs for the sessions folder): a session whose end could not be saved stays resumable in the same wizard."""

import asyncio
import dataclasses
from pathlib import Path

import pytest
from textual.widgets import Button, Static

from conftest import fill_disk
from fixwizard.calibration.store import load_calibration, save_calibration
from fixwizard.demo import demo_fixture
from fixwizard.journal import read_unfinished
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.cell import Cell, SavedCalibration
from fixwizard.tui.launch import simulated_cell
from fixwizard.tui.results.screen import ResultsScreen
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.start.screen import StartScreen
from fixwizard.tui.start.sessions import start_session
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.workflow.session import KIND
from pilot_wait import dialog_shown, until
from tui_cell import truth_calibration

SIZE = (80, 24)
SEED = 3
TAPS = 10  # at least; more until the journal's last page has no room for the closing record
PAGE_BYTES = 4096  # tmpfs gives a file its room a page at a time
ROOM_LEFT_BYTES = 150  # the closing record, with the report's path, is longer
MAX_CELLS = 4e6
EXAMPLE_CALIBRATION = Path(__file__).resolve().parents[1] / "calibrations" / "example_matlab_logo.yaml"


def tapped_session(sessions_disk: Path, folder: Path) -> tuple[Cell, Path, int]:
    """The demo cell of ``SEED`` with its folders in ``folder`` but the sessions on ``sessions_disk``, and a released
    session started as the wizard starts one, with a tip calibration holding the cell's truth (the example's steps:
    a stored calibration keeps them); ``TAPS`` spread taps or more, until the journal's last page has no room for
    the closing record. Returns the cell, the journal and its number of taps."""
    cell = dataclasses.replace(simulated_cell(SEED, pace_s=0.0, folder=folder), sessions_dir=sessions_disk / "sessions",
                               max_cells=MAX_CELLS)
    robot = cell.hands.cell
    robot.connect()
    truth = truth_calibration(robot)
    calibration = dataclasses.replace(load_calibration(EXAMPLE_CALIBRATION), robot=cell.robot_name,
                                      tcp_p_tip_m=truth.tcp_p_tip_m, ball_diameter_m=truth.ball_diameter_m,
                                      sample_bound_m=truth.sample_bound_m)
    calibration_path = folder / "calibrations" / "truth.yaml"
    calibration_path.parent.mkdir(parents=True)
    save_calibration(calibration, calibration_path)
    session = start_session(cell, demo_fixture(), SavedCalibration(calibration, calibration_path))
    hands = SimulatedHands(robot, seed=SEED)
    index = 0
    while index < TAPS or PAGE_BYTES - session.path.stat().st_size % PAGE_BYTES > ROOM_LEFT_BYTES:
        hands.near_spread_point(index)
        session.record_tap(robot.tap().base_T_tcp_contact)
        index += 1
    session.release()
    return cell, session.path, index


@pytest.mark.slow  # a solve of the taps, about 10 s
def test_a_session_whose_end_the_full_disk_refused_stays_resumable_in_the_same_wizard(small_disk, tmp_path):
    """The session's closing record failed on a full disk after the report was written: the wizard went on to the
    start screen still holding the journal's lock, so resuming it there was refused as "open in another fixwizard"
    until the operator quit. Now the session is let go unfinished, selected to resume, and resuming it works."""
    cell, path, taps = tapped_session(small_disk, tmp_path)

    async def run() -> None:
        app = FixwizardApp(cell, str(path))
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and app.screen.is_mounted
                        and not app.screen.busy)
            await pilot.press("s")
            await until(pilot, lambda: isinstance(app.screen, ResultsScreen) and app.screen.is_mounted)
            await pilot.press("w")
            assert app.screen.written is not None and app.screen.written.is_file()
            filler = fill_disk(small_disk)
            await pilot.press("q")
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            message = str(app.screen.query_one("#dialog-message", Static).render())
            assert "the disk is full" in message and "This end of the session was not saved" in message
            assert "stays unfinished: it is selected on the start screen to resume" in message
            filler.unlink()  # the operator frees space
            await pilot.press("escape")
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and app.screen.is_mounted)
            assert app.screen.query_one("#session").value == str(path)
            app.screen.query_one("#continue", Button).focus()
            await pilot.press("enter")
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and app.screen.is_mounted
                        or isinstance(app.screen, ErrorModal))
            assert isinstance(app.screen, SamplingScreen), str(app.screen.query_one("#dialog-message").render())
            assert len(app.screen.session.taps) == taps

    asyncio.run(run())
    # read without its lock: the app run by the test ends without the flow's own end, which lets the session go
    header_and_records = read_unfinished(KIND, path)
    assert header_and_records is not None, "the session was closed or cannot be read"
    assert [record["id"] for record in header_and_records[1] if record["kind"] == "tap"] == list(range(1, taps + 1))
