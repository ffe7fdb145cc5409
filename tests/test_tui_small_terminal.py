"""The wizard in a terminal smaller than it is made for (80x24): every field, button and footer key of a screen is in
view from 80x23 (tmux's status line takes a row of 80x24) on; smaller, the step's screen is covered by a notice
that says so, with STOP in view, and comes back as it was, its work gone on meanwhile."""

import asyncio

from textual.widgets import Button, Footer, Input, Select, Static

from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.tui.widgets.too_small import TooSmall
from pilot_wait import until
from test_tui_app import SIZE, at_start, at_the_automatic_taps, rearm, wizard
from test_tui_keys import assert_in_view, at_pivot
from tui_cell import record_spread_taps, wizard_context

TMUX_SIZE = (80, 23)


def notice(app) -> str:
    return str(app.screen.query_one("#too-small", Static).render())


def test_at_60x20_the_start_screen_says_the_terminal_is_too_small_instead_of_cutting_the_units_off(tmp_path):
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=(60, 20)) as pilot:
            await until(pilot, lambda: isinstance(app.screen, TooSmall) and bool(app.screen.query("#too-small")))
            assert notice(app).startswith("Terminal too small: 60x20, the wizard needs 80x23.")
            assert "this step (start) comes back as it was" in notice(app)
            await assert_in_view(pilot, "f12", "ctrl+q", "question_mark")
            await pilot.resize_terminal(70, 30)  # wide enough is needed too
            await until(pilot, lambda: notice(app).startswith("Terminal too small: 70x30"))
            for size in (TMUX_SIZE, SIZE):
                await pilot.resize_terminal(*size)
                await at_start(pilot)
                await pilot.pause()
                assert not any(isinstance(screen, TooSmall) for screen in app.screen_stack)
                fields = [*app.screen.query(Select), *app.screen.query(Input), *app.screen.query(Button)]
                assert {"units", "fixture", "calibration", "continue", "check"} <= {field.id for field in fields}
                cut = [field.id for field in fields if field.display and field.region.right > size[0]]
                assert not cut
                await assert_in_view(pilot, "f12", "ctrl+q", "question_mark")
    asyncio.run(run())


def test_resized_below_80x23_mid_step_the_automatic_taps_go_on_under_the_notice_and_come_back(tmp_path):
    """The taps run on while the notice covers their screen, STOP works from it, and the result screen the taps end
    in waits for a terminal that fits it."""
    async def run():
        async with at_the_automatic_taps(tmp_path, pace_s=0.05) as (_, app, pilot):
            taps = app.screen
            await pilot.press("g")
            await until(pilot, lambda: app.motion_running())
            await pilot.resize_terminal(80, 22)
            await until(pilot, lambda: isinstance(app.screen, TooSmall))
            assert "(tip calibration, step 3 of 4: automatic taps)" in notice(app)
            await pilot.press("t", "escape", "n")  # the covered screen's keys do nothing
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped and not app.motion_running())
            await pilot.resize_terminal(*SIZE)
            await until(pilot, lambda: app.screen is taps or isinstance(app.screen, ErrorModal))
            if isinstance(app.screen, ErrorModal):  # STOP came during a tap: its error, over the notice
                await pilot.press("escape")
            await until(pilot, lambda: app.screen is taps)
            assert "re-arm (Ctrl+R), then press g to continue" in str(taps.query_one("#auto-state", Static).render())
            await rearm(pilot)
            await pilot.press("g")
            await until(pilot, lambda: app.motion_running())
            await pilot.resize_terminal(60, 20)
            await until(pilot, lambda: isinstance(app.screen, TooSmall))
            await until(pilot, lambda: not app.motion_running(), timeout_s=120)
            await pilot.pause(0.3)
            assert isinstance(app.screen, TooSmall)  # the result waits under the notice, not over it
            await pilot.resize_terminal(*TMUX_SIZE)
            await until(pilot, lambda: isinstance(app.screen, CalibrationResultScreen))
    asyncio.run(run())


def test_at_80x23_a_robot_problem_on_sampling_stays_above_the_footer_next_to_the_advice(tmp_path):
    """With the live check and the next-tap advice shown, a robot problem of five lines ran under the footer (the
    screen grew a scroll bar no key reaches). The advice makes room while the problem is shown."""
    context = wizard_context(tmp_path)
    record_spread_taps(context, 14)

    async def run():
        app = FixwizardApp(context.cell, sampling=context.sampling)
        async with app.run_test(size=TMUX_SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
            screen = app.screen
            guide = screen.query_one("#guide", Static)
            await until(pilot, lambda: not screen.live_running and not guide.has_class("-empty"), timeout_s=120)
            screen._problem(" ".join(["The link to the robot is down: the network dropped."] * 6))
            await pilot.pause()
            problem, footer = screen.query_one("#problem", Static), screen.query_one(Footer)
            assert problem.region.height >= 7 and problem.region.bottom <= footer.region.y
            assert not guide.display and screen.query_one("#title").region.width == TMUX_SIZE[0]  # no scroll bar
            screen._say("Tap 15 recorded and saved.")
            await until(pilot, lambda: guide.display)
    asyncio.run(run())
    context.session.release()


def test_re_armed_under_the_notice_the_pivot_has_its_freedrive_back(tmp_path):
    """STOP ends freedrive and re-arming turns it on again on a step that guides the arm by hand: under the notice
    the re-arm looked for that step on top of the screens, found the notice and left freedrive off."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_pivot(pilot)
            await pilot.resize_terminal(60, 20)
            await until(pilot, lambda: isinstance(app.screen, TooSmall))
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped and app.cell.robot.status().mode == "idle")
            await rearm(pilot)
            await until(pilot, lambda: app.cell.robot.status().mode == "freedrive")
            assert isinstance(app.screen, TooSmall)
    asyncio.run(run())
