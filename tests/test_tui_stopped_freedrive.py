"""The screens where the operator guides the arm by hand turn freedrive on as they open (the pivot, the table points,
sampling, the check); after a STOP the arm holds still until the operator turns freedrive on (f) or re-arms. Opened
while the wizard is STOPPED, such a screen leaves freedrive off and says how to turn it on; f does."""

import asyncio

import pytest
from textual.widgets import Button, Select, Static

from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.check.screen import CheckScreen
from fixwizard.tui.freedrive import OFF_WHILE_STOPPED
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.start.screen import StartScreen
from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from pilot_wait import until
from test_tui_app import at_start, press_button, rearm, screen_text, wizard
from test_tui_check import calibrated, wizard_with_a_report  # noqa: F401 (a fixture)
from test_tui_small_terminal import TMUX_SIZE
from tui_cell import wizard_context
from tui_tip_steps import press_when_ready

pytestmark = pytest.mark.slow  # a tip calibration through its screens, and a check with its report, about 15 s


async def stop(pilot) -> None:
    """F12, and wait until the robot's stop has ended freedrive."""
    await pilot.press("f12")
    await until(pilot, lambda: pilot.app.stopped and pilot.app.cell.robot.status().mode == "idle")


async def opened_stopped_then_f(pilot, screen_type: type) -> None:
    """The screen of ``screen_type`` opened while STOPPED leaves freedrive off and says so (in view at 80x23); f turns
    it on (still STOPPED), and the screen no longer says it is off."""
    app, robot = pilot.app, pilot.app.cell.robot
    await until(pilot, lambda: isinstance(app.screen, screen_type) and not app.screen.busy)
    await pilot.pause(0.2)  # a freedrive the screen turned on as it opened would be on by now
    assert app.stopped and robot.status().mode == "idle"
    said = [widget for widget in app.screen.query(Static) if OFF_WHILE_STOPPED in str(widget.render())]
    assert said and said[0].region.height and said[0].region.bottom <= app.size.height - 1  # in view, above the footer
    await press_when_ready(pilot, "f")
    assert app.stopped and robot.status().mode == "freedrive"
    assert OFF_WHILE_STOPPED not in screen_text(app)


def test_the_calibration_steps_and_sampling_opened_while_stopped_leave_freedrive_off_until_f(tmp_path):
    """STOP on the start screen, then a new calibration: the pivot turned freedrive on as it opened; STOP at the pivot,
    then n: so did the table points; STOP on the tip calibration's result, then Accept: so did sampling, all with the
    wizard STOPPED. Now each leaves it off, says so, and f turns it on."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=TMUX_SIZE) as pilot:
            await at_start(pilot)
            await stop(pilot)
            await press_button(pilot, "#continue")
            await opened_stopped_then_f(pilot, PivotScreen)
            await rearm(pilot)
            for _ in range(app.cell.hands.pivot_count):
                await press_when_ready(pilot, "m")
            await stop(pilot)
            await pilot.press("n")
            await opened_stopped_then_f(pilot, TablePointsScreen)
            await rearm(pilot)
            for _ in range(3):
                await press_when_ready(pilot, "m")
            await pilot.press("n")
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))
            await pilot.press("g")
            await until(pilot, lambda: isinstance(app.screen, CalibrationResultScreen) and not app.screen.busy
                        and not app.screen.query_one("#accept", Button).disabled)
            await stop(pilot)
            await press_button(pilot, "#accept")
            await opened_stopped_then_f(pilot, SamplingScreen)
    asyncio.run(run())


def test_the_check_opened_while_stopped_leaves_freedrive_off_until_f(tmp_path, calibrated):  # noqa: F811
    context, path = wizard_with_a_report(tmp_path, calibrated)

    async def run():
        app = FixwizardApp(context)
        async with app.run_test(size=TMUX_SIZE) as pilot:
            await at_start(pilot)
            app.screen.query_one("#calibration", Select).value = str(path)
            await pilot.pause()
            assert isinstance(app.screen, StartScreen)
            await stop(pilot)
            await press_button(pilot, "#check")
            await until(pilot, lambda: isinstance(app.screen, CheckScreen) and app.screen.fixture is not None)
            await opened_stopped_then_f(pilot, CheckScreen)
            assert str(app.screen.query_one("#check-note", Static).render()) == ""
    asyncio.run(run())


@pytest.mark.parametrize("where", ["pivot", "sampling"])
def test_a_stop_on_an_open_screen_that_said_freedrive_is_on_says_it_is_off_until_f(tmp_path, where):
    """The pivot and sampling say "Freedrive is on" in their text; after a STOP (which ends freedrive) they still said
    so. Now they say it is off and how to turn it on, and f turns it on and says so again."""
    async def run():
        if where == "pivot":
            app, screen_type = FixwizardApp(wizard(tmp_path)), PivotScreen
        else:
            context = wizard_context(tmp_path)
            app, screen_type = FixwizardApp(context.cell, sampling=context.sampling), SamplingScreen
        async with app.run_test(size=TMUX_SIZE) as pilot:
            if where == "pivot":
                await at_start(pilot)
                await press_button(pilot, "#continue")
            await until(pilot, lambda: isinstance(app.screen, screen_type) and not app.screen.busy
                        and app.cell.robot.status().mode == "freedrive")
            assert "Freedrive is on" in screen_text(app)
            await stop(pilot)
            assert OFF_WHILE_STOPPED in screen_text(app) and "Freedrive is on" not in screen_text(app)
            await press_when_ready(pilot, "f")
            await until(pilot, lambda: app.cell.robot.status().mode == "freedrive"
                        and "Freedrive is on" in screen_text(app))
            assert OFF_WHILE_STOPPED not in screen_text(app)
    asyncio.run(run())


def test_re_arm_on_the_table_points_turns_freedrive_on_only_while_points_are_left(tmp_path):
    """Once C is tapped the arm holds still (the screen opened so leaves freedrive off too); a STOP and re-arm there
    turned freedrive on all the same. Now it stays off, and the re-arm's note says nothing of freedrive."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=TMUX_SIZE) as pilot:
            await at_start(pilot)
            await press_button(pilot, "#continue")
            await until(pilot, lambda: isinstance(app.screen, PivotScreen) and not app.screen.busy)
            for _ in range(app.cell.hands.pivot_count):
                await press_when_ready(pilot, "m")
            await pilot.press("n")
            await until(pilot, lambda: isinstance(app.screen, TablePointsScreen) and not app.screen.busy)
            for _ in range(3):
                await press_when_ready(pilot, "m")
            await until(pilot, lambda: len(app.screen.workflow.poses("table_coarse")) == 3 and not app.screen.busy)
            await stop(pilot)
            await rearm(pilot)
            await pilot.pause(0.3)  # a freedrive the re-arm turned on would be on by now
            assert app.cell.robot.status().mode == "idle"
            assert "Re-armed: the robot keys work again." in [str(note.message) for note in app._notifications]
    asyncio.run(run())
