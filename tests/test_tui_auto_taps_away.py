"""The automatic tip-calibration taps refuse to start with the ball away from the table corner of A, B and C (the way to
the first tap runs at the approach height), and ask the operator to bring it above the corner B in freedrive: the
screen then offers freedrive (f) and, on the simulated cell, the simulated hands (m), in its footer at 80x23, so that
the operator can do what it asks and start the taps."""

import asyncio

import pytest
from textual.containers import VerticalScroll
from textual.widgets import Static

from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from fixwizard.tui.widgets.errors import ErrorModal
from pilot_wait import dialog_shown, until
from test_tui_app import at_the_automatic_taps
from test_tui_keys import assert_in_view, open_help
from test_tui_small_terminal import TMUX_SIZE
from tui_tip_steps import press_when_ready

pytestmark = pytest.mark.slow  # a tip calibration through its screens, about 10 s


async def back_to_the_pivot_and_on(pilot) -> None:
    """From the automatic taps, Esc, Esc back to the pivot, then m (the simulated hands take the arm to a pivot pose
    and capture it, away from the table corner), n, n, and g: the taps refuse to start, in an error message."""
    app = pilot.app
    await press_when_ready(pilot, "escape")
    await until(pilot, lambda: isinstance(app.screen, TablePointsScreen))
    await press_when_ready(pilot, "escape")
    await until(pilot, lambda: isinstance(app.screen, PivotScreen))
    await press_when_ready(pilot, "m")
    await press_when_ready(pilot, "n")
    await until(pilot, lambda: isinstance(app.screen, TablePointsScreen))
    await press_when_ready(pilot, "n")
    await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))
    await pilot.press("g")
    await until(pilot, lambda: dialog_shown(app, ErrorModal))
    assert "away from the table corner of A, B and C" in str(app.screen.error)
    await pilot.press("escape")
    await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))


def state_of(screen: AutoTapsScreen) -> str:
    return str(screen.query_one("#auto-state", Static).render())


def test_taps_refused_with_the_ball_away_from_the_corner_offer_freedrive_to_bring_it_back(tmp_path):
    """The error asked to bring the ball above the corner B in freedrive, but f and m were off on that screen (the
    calibration had not been continued) and the table points took no more taps: a dead end. Now f and m are in the
    footer at 80x23, the screen says what to do with them, f turns freedrive on, and with the ball brought above B
    the taps run to the result."""
    async def run():
        async with at_the_automatic_taps(tmp_path) as (context, app, pilot):
            await pilot.resize_terminal(*TMUX_SIZE)
            await back_to_the_pivot_and_on(pilot)
            taps = app.screen
            await assert_in_view(pilot, "f12", "escape", "g", "m", "f", "n", "ctrl+q", "question_mark")
            assert taps.query_one(VerticalScroll).max_scroll_y == 0  # every line in view
            state = state_of(taps)
            assert state.startswith("Not started: the ball is ")
            assert "start them again.\nPress f to turn freedrive on, guide the ball there, then press g." in state
            assert "SIMULATED: press m" in state
            assert "f (freedrive) lets you guide it there" in await open_help(pilot)
            await press_when_ready(pilot, "f")
            assert context.robot.status().mode == "freedrive"
            assert state_of(taps).startswith("Freedrive is on: bring the ball a few centimetres above the corner B")
            context.hands.table_point("B")  # the operator's hands, in freedrive
            await press_when_ready(pilot, "g")
            await until(pilot, lambda: isinstance(app.screen, CalibrationResultScreen))
    asyncio.run(run())


def test_the_simulated_hands_bring_the_ball_back_above_the_corner_after_the_refusal(tmp_path):
    async def run():
        async with at_the_automatic_taps(tmp_path) as (_, app, pilot):
            await back_to_the_pivot_and_on(pilot)
            await press_when_ready(pilot, "m")
            assert state_of(app.screen) == "Press g to go on."
            await press_when_ready(pilot, "g")
            await until(pilot, lambda: isinstance(app.screen, CalibrationResultScreen))
    asyncio.run(run())
