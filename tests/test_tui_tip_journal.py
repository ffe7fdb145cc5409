"""The wizard continues a tip calibration it left unfinished: the start screen offers it (chosen already when it is
newer than the robot's saved calibrations) with what it holds; Continue goes on at the step it reached with every
pose kept, and once accepted it is finished and no longer offered. A redo drops the poses for good, going back
from the pivot gives the calibration up."""

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator

import pytest
from textual.containers import VerticalScroll
from textual.pilot import Pilot
from textual.widgets import Button, ProgressBar, Select, Static
from textual.widgets._footer import FooterKey

from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.cell import Cell
from fixwizard.tui.launch import simulated_cell
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.start.screen import UNFINISHED, StartScreen
from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.workflow.calibration_journal import find_unfinished_calibrations
from pilot_wait import dialog_shown, until
from test_tui_app import stop_and_rearm
from test_tui_keys import assert_in_view, open_help
from tui_cell import start_fixture
from tui_tip_steps import press_when_ready, to_automatic_taps, to_result

pytestmark = pytest.mark.slow  # two wizard runs through a tip calibration, about 30 s

SEED = 5
SIZE = (100, 30)
TERMINAL = (80, 24)  # the smallest the wizard is made for


async def at_start(pilot: Pilot) -> StartScreen:
    app = pilot.app
    await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None
                and app.robot_status is not None and app.robot_status.connected)
    return app.screen


async def press_continue(pilot: Pilot) -> None:
    pilot.app.screen.query_one("#continue", Button).focus()
    await pilot.press("enter")


@contextlib.asynccontextmanager
async def continued(cell: Cell, size: tuple[int, int] = SIZE) -> AsyncIterator[tuple[FixwizardApp, Pilot]]:
    """The wizard on ``cell`` after Continue on its start screen, with the tip calibration it chose."""
    app = FixwizardApp(cell)
    async with app.run_test(size=size) as pilot:
        await at_start(pilot)
        await press_continue(pilot)
        yield app, pilot


async def leave_at_the_automatic_taps(cell: Cell, size: tuple[int, int] = SIZE) -> None:
    """A new tip calibration on ``cell`` taken to its automatic taps and left there unfinished (the wizard quits)."""
    async with continued(cell, size) as (app, pilot):
        await to_automatic_taps(pilot, cell.hands.pivot_count)
        await pilot.press("ctrl+q")  # nothing moves: the wizard quits at once, the calibration left unfinished
        await until(pilot, lambda: not app.is_running)


def test_a_calibration_left_during_the_automatic_taps_continues_where_it_stopped(tmp_path):
    cell = simulated_cell(SEED, pace_s=0.02, folder=tmp_path)  # the automatic taps take long enough to leave them

    async def leave_during_the_automatic_taps() -> tuple[int, int]:
        app = FixwizardApp(cell)
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await press_continue(pilot)  # a new tip calibration: nothing saved yet
            await to_automatic_taps(pilot, cell.hands.pivot_count)
            table, tilted = (app.screen.query_one(f"#progress-{step}", ProgressBar) for step in ("table", "tilted"))
            await pilot.press("g")
            await until(pilot, lambda: table.progress >= 4, 20.0)
            await pilot.press("escape")  # cancel after the current tap; then the wizard is gone (as after a crash)
            await until(pilot, lambda: not app.screen.busy)
            return int(table.progress), int(tilted.progress)

    done = asyncio.run(leave_during_the_automatic_taps())
    (unfinished,) = find_unfinished_calibrations(cell.calibrations_dir, cell.robot_name)
    assert (unfinished.counts["table"], unfinished.counts["tilted"]) == done
    assert unfinished.counts["table_coarse"] == 3 and sum(done) < 56

    async def continue_it() -> None:
        app = FixwizardApp(simulated_cell(SEED, pace_s=0.0, folder=tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            start = await at_start(pilot)
            assert start.query_one("#calibration", Select).value == f"{UNFINISHED}{unfinished.path}"
            info = str(start.query_one("#calibration-info", Static).render())
            assert f"{cell.hands.pivot_count} pivot poses, 3 table points, {sum(done)} automatic taps" in info
            await press_continue(pilot)
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen) and app.screen.is_mounted)
            assert "goes on where it stopped" in str(app.screen.query_one("#auto-state", Static).render())
            assert tuple(app.screen.query_one(f"#progress-{step}", ProgressBar).progress
                         for step in ("table", "tilted")) == done
            auto = app.screen
            await pilot.press("g")  # the arm is elsewhere (the new cell's home pose): it does not move
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            shown = "\n".join(str(widget.render()) for widget in app.screen.query(Static))
            assert "mm away from the table corner of A, B and C" in shown and "did not move" in shown
            await pilot.press("escape")
            await until(pilot, lambda: app.screen is auto and not auto.busy)
            await press_when_ready(pilot, "m")  # the simulated hands bring the ball back above the corner B
            await pilot.press("g")
            await until(pilot, lambda: isinstance(app.screen, CalibrationResultScreen) and not app.screen.busy)
            assert {step: len(app.screen.workflow.poses(step)) for step in ("table", "tilted")} == {
                "table": 16, "tilted": 40}
            app.screen.query_one("#accept", Button).focus()
            await pilot.press("enter")
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen))

    asyncio.run(continue_it())
    assert find_unfinished_calibrations(cell.calibrations_dir, cell.robot_name) == []
    closed = json.loads(unfinished.path.read_text().splitlines()[-1])
    assert closed["outcome"] == "saved" and closed["calibration"].startswith(str(cell.calibrations_dir))


def test_a_redo_drops_the_poses_for_good_and_back_from_the_pivot_gives_the_calibration_up(tmp_path):
    cell = simulated_cell(SEED, pace_s=0.0, folder=tmp_path)

    def offered() -> list:
        return find_unfinished_calibrations(cell.calibrations_dir, cell.robot_name)

    async def run() -> None:
        async with continued(cell) as (app, pilot):
            await to_result(pilot, cell.hands.pivot_count)
            (journal,) = offered()
            assert journal.counts["tilted"] == 40
            app.screen.query_one("#redo", Button).press()
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("y")
            await until(pilot, lambda: isinstance(app.screen, PivotScreen) and app.screen.is_mounted)
            assert "Poses captured: 0" in str(app.screen.query_one("#pivot-state", Static).render())
            assert offered() == []  # nothing left to continue

            for _ in range(2):
                await press_when_ready(pilot, "m")
            assert len(offered()) == 1
            await pilot.press("escape")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("y")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            await until(pilot, lambda: offered() == [])
            return journal.path

    path = asyncio.run(run())
    last = json.loads(path.read_text().splitlines()[-1])
    assert last["kind"] == "closed" and last["outcome"] == "discarded"


def test_the_continued_automatic_taps_show_their_text_keys_and_help_whole_at_80x24(tmp_path):
    """Continued, the automatic taps need the operator's hands first (f, or m on the simulated cell): f was not in
    the footer, the help said nothing of it, and the step said 'Press g to start' with the taps half done."""
    cell = simulated_cell(SEED, pace_s=0.0, folder=tmp_path)

    async def continue_it() -> None:
        async with continued(simulated_cell(SEED, pace_s=0.0, folder=tmp_path), TERMINAL) as (app, pilot):
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen) and bool(app.screen.query(FooterKey)))
            await pilot.pause()
            assert app.screen.query_one(VerticalScroll).max_scroll_y == 0  # every line in view
            text = "\n".join(str(widget.render()) for widget in app.screen.query(Static))
            assert "Press g to go on." in text and "turn freedrive on (f)" in text
            assert "press m and the simulated hands bring the ball above B" in text
            await assert_in_view(pilot, "f12", "escape", "g", "m", "f", "n", "ctrl+q", "question_mark")
            assert "f (freedrive) lets you guide it there" in await open_help(pilot)
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped)
            await assert_in_view(pilot, "f12", "escape", "g", "m", "f", "n", "ctrl+q", "ctrl+r", "question_mark")
            await open_help(pilot)

    asyncio.run(leave_at_the_automatic_taps(cell, TERMINAL))
    asyncio.run(continue_it())


def test_re_arming_at_the_continued_automatic_taps_turns_freedrive_on_where_the_operator_had_it_on(tmp_path):
    """Continued, the automatic taps let the operator guide the ball back above B in freedrive (f): a STOP meanwhile
    ends freedrive, and the re-arm turns it on again, as on the steps guided by hand. Once the taps have run, the
    taps hold the arm: a STOP and re-arm leave freedrive off."""
    cell = simulated_cell(SEED, pace_s=0.0, folder=tmp_path)

    async def continue_it() -> None:
        cell = simulated_cell(SEED, pace_s=0.05, folder=tmp_path)  # the taps take long enough to stop them
        robot = cell.robot
        async with continued(cell) as (app, pilot):
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen) and app.screen.is_mounted)
            await press_when_ready(pilot, "m")  # the simulated hands bring the ball back above the corner B
            await press_when_ready(pilot, "f")
            assert robot.status().mode == "freedrive"
            await stop_and_rearm(pilot)
            assert robot.status().mode == "freedrive"
            await pilot.press("g")
            await until(pilot, lambda: app.motion_running())
            await stop_and_rearm(pilot)
            assert robot.status().mode == "idle"

    asyncio.run(leave_at_the_automatic_taps(cell))
    asyncio.run(continue_it())


def test_a_continued_calibration_double_spaced_by_an_editor_says_so_in_one_warning(tmp_path):
    """A warning per blank line stacked a toast for each pose over the step; one names them all."""
    cell = simulated_cell(SEED, pace_s=0.0, folder=tmp_path)
    asyncio.run(leave_at_the_automatic_taps(cell))
    (unfinished,) = find_unfinished_calibrations(cell.calibrations_dir, cell.robot_name)
    lines = unfinished.path.read_bytes().splitlines(keepends=True)
    unfinished.path.write_bytes(b"".join([lines[0]] + [piece for line in lines[1:] for piece in (line, b"\n")]))

    async def continue_it() -> list[str]:
        app = FixwizardApp(simulated_cell(SEED, pace_s=0.0, folder=tmp_path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await at_start(pilot)
            await press_continue(pilot)
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen) and app.screen.is_mounted)
            return [str(note.message) for note in app._notifications if "journal" in str(note.message)]

    (warning,) = asyncio.run(continue_it())
    assert warning.startswith("lines 3, 5, 7, 9, 11 and ")
    assert "more are blank in the tip calibration journal" in warning
