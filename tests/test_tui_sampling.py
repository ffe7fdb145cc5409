"""The sampling screen on the simulated cell: the simulated hands and the tap key fill the table and the
journal, undo is journaled, the live check follows the taps, robot problems are explained and lose nothing,
the next tap is suggested (and reached on confirmation when the way there is safe), and the taps are checked
against every fixture."""

import asyncio
import dataclasses
import json

import numpy as np
import pytest
from textual.widgets import Button, DataTable, Static
from textual.widgets._footer import FooterKey

from fixwizard.demo import disc_fixture
from fixwizard.geometry.se3 import rotation_angle_rad
from fixwizard.tui import keys
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.sampling.text import live_text
from fixwizard.tui.tapping import FREEDRIVE_STAYS_OFF
from fixwizard.tui.widgets.confirm import Confirm, ConfirmMove
from fixwizard.tui.widgets.dialog import Dialog
from fixwizard.tui.widgets.doing import seconds_text
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.workflow.advice import TapAdvice
from fixwizard.workflow.hover import HoverPlan
from fixwizard.workflow.live import LiveView, quick_check
from fixwizard.workflow.solver_process import NextTap
from pilot_wait import dialog_shown, until
from tui_cell import ScreenHost, cell_of, record_spread_taps, wizard_context

pytestmark = pytest.mark.asyncio
SIZE = (80, 24)


@pytest.fixture
def context(tmp_path):
    context = wizard_context(tmp_path)
    yield context
    context.session.release()


async def tap(pilot, screen: SamplingScreen, keys: str = "mt") -> None:
    """Press each key once the screen is ready for robot keys again."""
    for key in keys:
        await until(pilot, lambda: not screen.busy)
        await pilot.press(key)
    await until(pilot, lambda: not screen.busy)


def text_of(screen, selector: str) -> str:
    return str(screen.query_one(selector, Static).content)


def bounds_hold(bounds, base_T_cad: np.ndarray) -> bool:
    """Whether guaranteed bounds hold a pose: CAD origin and rotation within them of their centre."""
    centre = bounds.base_T_cad_center
    return bool(np.linalg.norm(base_T_cad[:3, 3] - centre[:3, 3]) <= bounds.position_m
                and rotation_angle_rad(centre[:3, :3].T @ base_T_cad[:3, :3]) <= bounds.rotation_rad)


def journal_kinds(context) -> list[str]:
    return [json.loads(line)["kind"] for line in context.session.path.read_text().splitlines()[1:]]


@pytest.mark.slow
async def test_twelve_taps_fill_the_table_and_the_journal_and_the_live_check_finds_the_pose(context):
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy)
        assert cell.status().mode == "freedrive"
        assert "starts at 3 taps (3 to go)" in text_of(screen, "#live")
        for _ in range(12):
            await tap(pilot, screen)
        table = screen.query_one(DataTable)
        assert table.row_count == 12 and len(context.session.taps) == 12
        assert journal_kinds(context) == ["tap"] * 12
        first_row = table.get_row_at(0)
        np.testing.assert_allclose([float(value.plain) for value in first_row[1:4]],
                                   context.session.base_p_taps[0] * 1e3, atol=0.05)
        assert cell.status().mode == "freedrive"
        # the first look may still be coarse (a loaded machine: undetermined); the quick check after it is unique
        await until(pilot, lambda: screen.live is not None and screen.live.tap_count == 12
                    and screen.live.verdict == "unique")
        assert bounds_hold(screen.live.bounds, cell.truth.base_T_cad)
        assert text_of(screen, "#live").startswith("Live check of 12 taps")
        assert "unique so far. Guaranteed now: origin within" in text_of(screen, "#live")
        quick_bounds = screen.live.bounds
        await until(pilot, lambda: screen.live.refined)
        assert screen.live.bounds.position_m <= quick_bounds.position_m
        assert bounds_hold(screen.live.bounds, cell.truth.base_T_cad)
        assert "as tight as the full solve's" in text_of(screen, "#live")
        distances_mm = [float(table.get_row_at(row)[4].plain) for row in range(12)]
        assert max(abs(distance) for distance in distances_mm) < 5.0
        await pilot.press("s")
        await until(pilot, lambda: app.results == [True])
        assert cell.status().mode == "idle"  # freedrive off while solving


@pytest.mark.slow
async def test_undo_removes_the_last_tap_and_journals_it(context):
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        for _ in range(4):
            await tap(pilot, screen)
        ids = [tap.id for tap in context.session.taps]
        await pilot.press("u")
        assert [tap.id for tap in context.session.taps] == ids[:3]
        assert screen.query_one(DataTable).row_count == 3
        assert journal_kinds(context) == ["tap"] * 4 + ["undo"]
        assert "Tap 4 undone" in text_of(screen, "#note")


@pytest.mark.slow
async def test_protective_stop_during_a_tap_is_explained_and_loses_nothing(context):
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        for _ in range(3):
            await tap(pilot, screen)
        await tap(pilot, screen, "m")
        cell.inject_fault("protective_stop_during_tap")
        await tap(pilot, screen, "t")
        problem = text_of(screen, "#problem")
        assert "protective stop during the tap: unlock the protective stop on the teach pendant" in problem
        assert f"Nothing recorded is lost: 3 taps are saved in {context.session.path}" in problem
        assert len(context.session.taps) == 3 and screen.query_one(DataTable).row_count == 3
        await tap(pilot, screen, "t")  # still locked
        assert "still locked" in text_of(screen, "#problem")
        assert app.screen.active_bindings["k"].enabled
        await tap(pilot, screen, "k")  # SIMULATED unlock, as on the teach pendant
        assert not cell.status().protective_stop
        await tap(pilot, screen, "t")
        assert len(context.session.taps) == 4 and screen.query_one("#problem").has_class("-empty")
        assert journal_kinds(context) == ["tap"] * 4


@pytest.mark.parametrize("fault, shown", [("connection_loss", "check that the robot is powered on"),
                                          ("no_surface", "found no surface within 20 mm: move the tool closer")])
async def test_other_robot_problems_say_what_to_do_next(context, fault, shown):
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await tap(pilot, screen)
        cell.inject_fault(fault)
        await tap(pilot, screen, "mt")
        assert shown in text_of(screen, "#problem")
        assert "Nothing recorded is lost: 1 tap is saved" in text_of(screen, "#problem")
        assert len(context.session.taps) == 1


async def test_a_tap_that_finds_the_link_down_offers_reconnect_also_after_its_dialog_was_closed(context):
    """The lost link's dialog closed with OK (its focused button): every tap after said "then reconnect" under the
    table, with no way to (no key, no button; the status bar said DISCONNECTED until the wizard was restarted). The
    dialog with Reconnect comes back with the tap, and reconnecting lets the next tap record."""
    app = FixwizardApp(context.cell, sampling=context.sampling)
    async with app.run_test(size=SIZE) as pilot:
        await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
        screen = app.screen
        cell_of(context).inject_fault("connection_loss")
        for _ in range(2):  # the first tap loses the link, the second finds it lost
            await tap(pilot, screen, "mt")
            await until(pilot, lambda: dialog_shown(app, ErrorModal) and bool(app.screen.query("#reconnect")),
                        timeout_s=10)
            await pilot.press("enter")  # OK
            await until(pilot, lambda: app.screen is screen)
        await tap(pilot, screen, "t")
        await until(pilot, lambda: dialog_shown(app, ErrorModal) and bool(app.screen.query("#reconnect")),
                    timeout_s=10)
        app.screen.query_one("#reconnect", Button).focus()
        await pilot.press("enter")
        await until(pilot, lambda: app.screen is screen and app.robot_status is not None and app.robot_status.connected)
        await tap(pilot, screen, "mt")
        assert len(context.session.taps) == 1

async def test_solving_needs_three_taps(context):
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await tap(pilot, screen)
        await pilot.press("s")
        await asyncio.sleep(0.1)
        assert app.results == []
        assert "Tap at least 3 points before solving" in text_of(screen, "#problem")


async def test_a_real_cell_has_no_simulated_keys(context):
    context.with_cell(hands=None, simulated=False)
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        await until(pilot, lambda: not app.screen.busy)
        assert app.screen.check_action("simulated_hands", ()) is False
        assert app.screen.check_action("simulated_unlock", ()) is False
        assert app.screen.check_action("tap", ()) is True


async def test_leaving_turns_freedrive_off_and_keeps_the_session_open(context):
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        await tap(pilot, app.screen)
        await pilot.press("escape")
        await until(pilot, lambda: dialog_shown(app, Confirm))
        assert "stays saved; it is selected there to resume" in str(app.screen.query_one("#dialog-message").render())
        await pilot.press("y")
        await until(pilot, lambda: app.results == [False])
        assert cell_of(context).status().mode == "idle"
        assert not context.session.closed and len(context.session.taps) == 1


@pytest.mark.slow
async def test_once_the_pose_is_pinned_down_the_screen_suggests_a_tap_and_moves_above_it_after_confirmation(context):
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await tap(pilot, screen, "g")
        assert "No suggestion yet" in text_of(screen, "#note")
        for _ in range(10):
            await tap(pilot, screen)
        await until(pilot, lambda: screen.live is not None and screen.live.tap_count == 10
                    and screen.advice is not None)
        assert screen.live.verdict == "unique"
        assert text_of(screen, "#guide").startswith("Next (* in the view): Tap the ")
        assert not screen.query_one("#top-view").has_class("-empty")
        while screen.hover_plan is None:  # a set too wide for a safe way down: the operator guides the ball
            assert "by hand" in text_of(screen, "#guide") and len(context.session.taps) < 20
            context.hands.near_fixture(screen.advice.base_p_point_m)
            await tap(pilot, screen, "t")
            count = len(context.session.taps)
            await until(pilot, lambda count=count: screen.live is not None and screen.live.tap_count == count
                        and screen.live.refined and not screen.live_running)
        assert "Press g to go above it" in text_of(screen, "#guide")
        before = cell.base_T_tcp()
        await pilot.press("g")
        await until(pilot, lambda: dialog_shown(app, ConfirmMove))
        await pilot.press("enter")  # the focused button is Cancel
        await until(pilot, lambda: app.screen is screen)
        assert text_of(screen, "#note").startswith("Not moved. Press g to move above the suggested point")
        np.testing.assert_allclose(cell.base_T_tcp()[:3, 3], before[:3, 3], atol=1e-3)  # cancelled: no motion
        target = screen.advice.base_p_point_m
        await pilot.press("g")
        await until(pilot, lambda: dialog_shown(app, ConfirmMove))
        await pilot.press("y")
        await until(pilot, lambda: app.screen is screen and not screen.busy)
        assert "hovers above the suggested point" in text_of(screen, "#note")
        assert cell.status().mode == "freedrive"
        taps_before = len(context.session.taps)
        await tap(pilot, screen, "t")
        assert len(context.session.taps) == taps_before + 1
        contact = context.session.base_p_taps[-1]
        assert np.linalg.norm(contact - target) < 0.006  # the ball touched the fixture at the suggested point


async def test_a_stop_between_the_moves_above_a_point_lets_no_further_move_start_and_freedrive_stays_off(context):
    """The way above a suggested point is three moves; STOP as the first one ends (it set the screen's cancel, as
    the wizard's STOP does, and the robot's stop found no motion to halt) let the other two start, and freedrive
    came back on after the error."""
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy and cell.status().mode == "freedrive")
        base_p_ball = cell.base_T_tcp()[:3, 3] + cell.base_T_tcp()[:3, :3] @ context.calibration.tcp_p_tip_m
        point = base_p_ball + [0.03, 0.0, -0.01]
        advice = TapAdvice(point, point, np.array([0.0, 0.0, 1.0]), 0.002)
        screen.advice, screen.hover_plan = advice, HoverPlan(advice, 0.01, point + [0.0, 0.0, 0.01], point[2] + 0.02)
        moves, move_linear = [], cell.move_linear

        def stopped_after_the_first(base_T_tcp, speed_m_s, stop_mark=None):
            move_linear(base_T_tcp, speed_m_s, stop_mark)
            moves.append(base_T_tcp)
            for cancel in app.motion_cancels:  # STOP pressed as the move ends
                cancel.set()
            cell.stop()

        cell.move_linear = stopped_after_the_first
        await pilot.press("g")
        await until(pilot, lambda: dialog_shown(app, ConfirmMove))
        await pilot.press("y")
        await until(pilot, lambda: app.screen is screen and not screen.busy and "stopped on request"
                    in text_of(screen, "#problem"))
        assert len(moves) == 1 and not app.motion_cancels
        assert cell.status().mode == "idle"
        assert FREEDRIVE_STAYS_OFF in text_of(screen, "#problem")
        await pilot.press("f")
        await until(pilot, lambda: cell.status().mode == "freedrive")


async def test_a_dialog_shown_as_the_screen_finishes_its_work_stays_until_closed(context):
    """Textual's dismiss pops the top screen: when sampling went on to the solve (after turning freedrive off) with
    an error or the help over it, that dialog vanished unread and the sampling screen stayed under the next one.
    Now the screen goes once the dialog is closed."""
    record_spread_taps(context, 3)
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy)
        released, freedrive = asyncio.Event(), cell.freedrive
        loop = asyncio.get_running_loop()

        def held_freedrive(on: bool, stop_mark: int | None = None) -> None:
            asyncio.run_coroutine_threadsafe(released.wait(), loop).result(timeout=30)
            freedrive(on, stop_mark)

        cell.freedrive = held_freedrive
        await pilot.press("s")
        await until(pilot, lambda: screen.busy)
        error = Dialog("Robot problem", "the link to the robot is down")
        app.push_screen(error)
        await until(pilot, lambda: app.screen is error and error.is_mounted)
        released.set()
        await until(pilot, lambda: not screen.busy)
        await pilot.pause(0.2)
        assert app.screen is error and app.results == []  # the message stays, and so does the screen under it
        await pilot.press("escape")
        await until(pilot, lambda: app.results == [True])
        assert screen not in app.screen_stack


async def tap_or_move_above_a_point(pilot, context, motion: str) -> None:
    """On the sampling screen (freedrive on): ``motion`` "tap" places the ball with the simulated hands and taps;
    "move_linear" asks for the three moves above a suggested point 3 cm away and confirms them."""
    app, cell = pilot.app, cell_of(context)
    screen = app.screen
    if motion == "tap":
        await pilot.press("m")
        await until(pilot, lambda: not screen.busy and cell.status().mode == "freedrive")
        await pilot.press("t")
        return
    base_p_ball = cell.base_T_tcp()[:3, 3] + cell.base_T_tcp()[:3, :3] @ context.calibration.tcp_p_tip_m
    point = base_p_ball + [0.03, 0.0, -0.01]
    advice = TapAdvice(point, point, np.array([0.0, 0.0, 1.0]), 0.002)
    screen.advice = advice
    screen.hover_plan = HoverPlan(advice, 0.01, point + [0.0, 0.0, 0.01], point[2] + 0.02)
    await pilot.press("g")
    await until(pilot, lambda: dialog_shown(app, ConfirmMove))
    await pilot.press("y")


@pytest.mark.parametrize("motion", ["tap", "move_linear"])
async def test_a_stop_as_a_tap_or_the_last_move_above_a_point_ends_leaves_freedrive_off(context, motion):
    """STOP pressed as the tap or the last move above a suggested point ended (the robot's stop found no motion to
    halt) no longer lets freedrive come back on by itself: the wizard is STOPPED and the arm holds still. The tap is
    recorded all the same, and the note says freedrive stays off and how to turn it on."""
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy and cell.status().mode == "freedrive")
        motion_call, calls = getattr(cell, motion), []

        def stopped_as_it_ends(*args, **kwargs):
            result = motion_call(*args, **kwargs)
            calls.append(args)
            if motion == "tap" or len(calls) == 3:  # STOP pressed as the tap or the third and last move ends
                for cancel in app.motion_cancels:
                    cancel.set()
                cell.stop()
            return result

        setattr(cell, motion, stopped_as_it_ends)
        await tap_or_move_above_a_point(pilot, context, motion)
        await until(pilot, lambda: app.screen is screen and not screen.busy and "STOP was pressed"
                    in text_of(screen, "#note"))
        await pilot.pause(0.1)
        assert cell.status().mode == "idle" and not app.motion_cancels
        assert FREEDRIVE_STAYS_OFF in text_of(screen, "#note")
        assert (len(context.session.taps), len(calls)) == ((1, 1) if motion == "tap" else (0, 3))


@pytest.mark.parametrize("motion", ["tap", "move_linear"])
async def test_a_stop_just_after_the_look_at_stop_still_keeps_the_motion_from_starting(context, motion):
    """STOP landing after the worker looked whether STOP was pressed and before its call reached the robot (the GIL
    switching just then): the tap, or the second move above a suggested point, started after the STOP (the robot
    counted STOPs from the call). The robot now gets the STOP count read before that look, and refuses."""
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy and cell.status().mode == "freedrive")
        motion_call, asked, started = getattr(cell, motion), [], []

        def stop_lands_first(*args, **kwargs):
            asked.append(args)
            if motion == "tap" or len(asked) == 2:  # STOP as the wizard presses it: the cancels, then the robot
                for cancel in app.motion_cancels:
                    cancel.set()
                cell.stop()
            result = motion_call(*args, **kwargs)
            started.append(args)
            return result

        setattr(cell, motion, stop_lands_first)
        await tap_or_move_above_a_point(pilot, context, motion)
        await until(pilot, lambda: app.screen is screen and not screen.busy and "stopped on request"
                    in text_of(screen, "#problem"))
        assert (len(context.session.taps), len(started)) == (0, 0 if motion == "tap" else 1)
        await pilot.pause(0.1)
        assert cell.status().mode == "idle" and not app.motion_cancels


async def test_freedrive_asked_for_before_a_stop_does_not_come_on_after_it(context):
    """f, then STOP before the worker's call reached the robot (a busy computer): freedrive came on after the STOP,
    as the robot counted STOPs from the call. The key's STOP count goes with the call now: the arm holds still."""
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy and cell.status().mode == "freedrive")
        cell.stop()
        freedrive = cell.freedrive

        def stop_lands_first(on: bool, stop_mark: int | None = None) -> None:
            if on:
                cell.stop()
            freedrive(on, stop_mark)

        cell.freedrive = stop_lands_first
        await pilot.press("f")
        await until(pilot, lambda: not screen.busy and "Freedrive did not come on: STOP was pressed"
                    in text_of(screen, "#problem"))
        assert cell.status().mode == "idle"


@pytest.mark.parametrize("fault, freedrive_after", [("no_surface", True), ("protective_stop_during_tap", False),
                                                    ("stop", False)])
async def test_freedrive_comes_back_after_a_tap_only_when_it_ended_as_planned(context, fault, freedrive_after):
    """A tap that touched nothing within its travel ends as planned: freedrive on again, to bring the ball nearer.
    After a stop (STOP, a protective stop) freedrive stays off until the operator turns it on: before, it came
    back on by itself after the error."""
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy and cell.status().mode == "freedrive")
        if fault == "stop":
            cell.pace_s = 5.0
        else:
            cell.inject_fault(fault)
        await pilot.press("t")
        if fault == "stop":
            await until(pilot, lambda: cell.status().mode == "moving")
            cell.stop()
        await until(pilot, lambda: not screen.busy and text_of(screen, "#problem"))
        if fault == "protective_stop_during_tap":
            cell.unlock()
        assert (cell.status().mode == "freedrive") is freedrive_after
        assert (FREEDRIVE_STAYS_OFF in text_of(screen, "#problem")) is not freedrive_after


@pytest.mark.slow
async def test_when_the_possible_poses_leave_no_safe_way_down_the_screen_asks_to_guide_the_ball_by_hand(context):
    app = ScreenHost(lambda: context.sampling_screen())
    cell = cell_of(context)
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        for _ in range(10):
            await tap(pilot, screen)
        await until(pilot, lambda: screen.live is not None and screen.live.tap_count == 10
                    and screen.advice is not None and not screen.live_running)
        screen._live_event(NextTap(screen.advice, None))  # as the solver says for a set still too wide
        assert "guide the ball above the point by hand" in text_of(screen, "#guide")
        before = cell.base_T_tcp()
        await pilot.press("g")
        await pilot.pause()
        assert app.screen is screen and "guide the ball above the point by hand" in text_of(screen, "#note")
        np.testing.assert_allclose(cell.base_T_tcp()[:3, 3], before[:3, 3], atol=1e-3)


@pytest.mark.slow
@pytest.mark.parametrize("chosen, conclusion", [
    ("bracket", "Only the chosen fixture fits these taps"),
    ("plate", "The taps do not fit the chosen fixture; they fit Demo bracket (bundled). Leave (Esc), choose it")])
async def test_which_fixture_checks_the_taps_against_every_offered_mesh(context, tmp_path, chosen, conclusion):
    context.with_cell(fixtures_dir=tmp_path / "no-fixtures-here")
    if chosen == "plate":
        context.fixture = disc_fixture()  # the cell holds the bracket: the operator picked the wrong mesh
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await tap(pilot, screen)
        await pilot.press("i")
        assert "Tap at least 3 points before asking which fixture this is" in text_of(screen, "#problem")
        for _ in range(11):
            await tap(pilot, screen)
        await until(pilot, lambda: not screen.live_running, timeout_s=120)  # identify has its time limit alone
        await pilot.press("i")
        await until(pilot, lambda: dialog_shown(app, Dialog),
                    timeout_s=120)
        text = str(app.screen.query_one("#dialog-message", Static).content)
        bracket_mark = " (the chosen one)" if chosen == "bracket" else ""
        plate_mark = " (the chosen one)" if chosen == "plate" else ""
        assert f"fits         Demo bracket (bundled){bracket_mark}: taps" in text
        assert f"ruled out    Round plate (bundled){plate_mark}" in text
        assert conclusion in text
        await pilot.press("enter")
        await until(pilot, lambda: app.screen is screen)


async def test_the_live_check_says_the_ball_diameter_is_wrong_when_the_taps_fit_another_ball(context):
    context.calibration = dataclasses.replace(context.calibration, ball_diameter_m=0.006)  # the ball is 3 mm
    record_spread_taps(context, 12)
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: screen.live is not None and screen.live.ball_mismatch is not None
                    and not screen.live_running, timeout_s=120)  # the check has ended: no "looking closer"
        live = text_of(screen, "#live")
        fitted_mm = screen.live.ball_mismatch.fitted_diameter_m * 1e3
        assert abs(fitted_mm - 3.0) < 0.5
        assert live == (f"Live check of 12 taps: NO POSE FITS these taps with this ball. The taps fit a ball of about "
                        f"{fitted_mm:.1f} mm, the tip calibration says 6.0 mm: check the ball (measure it) and "
                        "calibrate the tip again with its diameter. The taps themselves are probably fine.")
        await pilot.press("o")
        await until(pilot, lambda: dialog_shown(app, Dialog))
        details = str(app.screen.query_one("#dialog-message", Static).content)
        assert details.startswith("12 taps; bounds from a quick hull refinement.\nSolver status: inconsistent.")
        assert f"Ball diameter fitted with the pose: {fitted_mm:.2f} mm." in details


async def test_the_live_check_names_a_tip_calibrated_on_another_robot_first_when_no_pose_fits(context):
    """The example calibration (another robot's tool) chosen on the demo cell: the live line says so before what
    the taps' figures suggest, and says nothing of it while a pose fits."""
    context.calibration = dataclasses.replace(context.calibration, robot="UR arm at 10.0.0.7", ball_diameter_m=0.006)
    record_spread_taps(context, 12)
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: screen.live is not None and screen.live.ball_mismatch is not None
                    and not screen.live_running, timeout_s=120)
        assert text_of(screen, "#live").startswith(
            "Live check of 12 taps: NO POSE FITS these taps with this ball. The tip calibration truth was made on UR "
            "arm at 10.0.0.7, not on this robot (simulated cell): unless this very tool is on its flange, untouched "
            "since, every tap misses. Calibrate the tip on this robot and tap again. The taps fit a ball of about ")
    elsewhere = "The tip calibration x was made on y, not on this robot (z): ... tap again."
    fits = LiveView.of(quick_check(context.fixture, context.session.base_p_taps, 0.003,
                                   context.calibration.sample_bound_m), context.fixture)
    assert fits.verdict == "unique" and live_text(fits, 12, None, elsewhere) == live_text(fits, 12, None)
    for verdict, cause, said in (("inconsistent", "tap 3 is off", "INCONSISTENT, no pose explains the taps. "
                                  f"{elsewhere} Most likely: tap 3 is off"),
                                 ("undetermined", "none found", "NO POSE FOUND that explains every tap within the "
                                  f"sample bound. {elsewhere} Check the tip calibration's bound")):
        view = dataclasses.replace(fits, verdict=verdict, cause=cause)
        assert live_text(view, 12, None, elsewhere).startswith(f"Live check of 12 taps: {said}")


async def test_a_tap_says_at_once_what_the_robot_does_and_counts_its_seconds(context):
    """A real tap takes seconds: the note says so the moment the key is pressed, and the count goes on."""
    cell_of(context).pace_s = 1.6  # each simulated motion takes this long
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy)
        await pilot.press("m")  # the simulated hands place the ball: no motion of the arm, no pace
        await until(pilot, lambda: not screen.busy)
        await pilot.press("t")
        await pilot.pause()
        assert text_of(screen, "#note") == ("Tapping: the robot moves the ball along the tool axis until it "
                                            "touches...")
        await until(pilot, lambda: text_of(screen, "#note").endswith("touches... (1.0 s)"), timeout_s=10.0)
        await until(pilot, lambda: not screen.busy, timeout_s=30.0)
        assert text_of(screen, "#note").startswith("Tap 1 recorded and saved.")


async def test_the_live_line_says_what_the_running_check_does_for_newer_taps_and_while_looking_closer(context):
    record_spread_taps(context, 10)
    calibration = context.calibration
    check = quick_check(context.fixture, context.session.base_p_taps, calibration.ball_diameter_m,
                        calibration.sample_bound_m)
    view = LiveView.of(check, context.fixture)
    assert view.verdict == "unique" and not view.refined
    tightening = live_text(view, 10, "computing the guaranteed bounds, round 2 (3 s)")
    assert tightening.startswith("Live check of 10 taps (looking closer: computing the guaranteed bounds, round 2 "
                                 "(3 s)...): unique so far.")
    assert tightening.endswith("; tightening them...")
    newer = live_text(view, 11, "narrowing the poses, pass 4: 1,234 groups of possible poses left (1 s)")
    assert newer.startswith("Live check of 10 taps (checking 11: narrowing the poses, pass 4: 1,234 groups of "
                            "possible poses left (1 s)...): unique so far.")
    assert newer.endswith("; tightening them...")
    assert live_text(view, 10, None).startswith("Live check of 10 taps: unique so far.")
    undetermined = dataclasses.replace(view, verdict="undetermined")
    assert live_text(undetermined, 10, "narrowing the poses, pass 9: 4,321 groups of possible poses left").startswith(
        "Live check of 10 taps (looking closer: narrowing the poses, pass 9: 4,321 groups of possible poses left...): "
        "the pose is not pinned down yet")


@pytest.mark.parametrize(("elapsed_s", "shown"), [(0.0, ""), (0.49, ""), (0.5, " (0.5 s)"), (0.99, " (0.5 s)"),
                                                  (1.0, " (1.0 s)"), (1.5, " (1.5 s)"), (12.7, " (12.5 s)")])
async def test_a_long_step_counts_in_half_seconds_from_its_first_half_second(elapsed_s, shown):
    assert seconds_text(elapsed_s) == shown


async def test_the_footer_dims_the_robot_keys_in_place_while_a_robot_call_runs(context):
    """Its keys stay the same widgets (composing them anew held the event loop at every robot call)."""
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.busy and bool(screen.query(FooterKey)))
        await pilot.pause()
        shown = list(screen.query(FooterKey))
        tap_key = next(key for key in shown if key.action == keys.TAP.action)
        assert not tap_key.has_class("-disabled")
        for busy in (True, False):
            screen.busy = busy
            screen.refresh_bindings()
            await pilot.pause()
            assert tap_key.has_class("-disabled") == busy and list(screen.query(FooterKey)) == shown


@pytest.mark.slow
async def test_after_an_undo_the_screen_shows_no_check_that_counted_the_undone_tap(context):
    """A check that counted a tap now gone may be narrower than the taps left allow: the live line, the estimate in
    the top view and the taps' distances under it go at once, not when the check of the taps left arrives (the line
    said "Live check of 10 taps (checking 9...): unique so far. Guaranteed now: ..." meanwhile, and after an undo and
    a new tap "Live check of 10 taps (looking closer...)" of taps that were no longer the ones tapped)."""
    record_spread_taps(context, 10)
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: screen.live is not None and screen.live.tap_count == 10
                    and screen.live.estimate_base_T_cad is not None)
        await until(pilot, lambda: not screen.busy)
        await pilot.press("u")
        assert text_of(screen, "#live").startswith("Checking 9 taps: ")
        assert screen.query_one("#top-view").has_class("-empty")
        table = screen.query_one(DataTable)
        assert [table.get_row_at(row)[4].plain for row in range(9)] == ["-"] * 9
        await until(pilot, lambda: screen.live is not None)
        assert screen.live.tap_count == 9
        assert text_of(screen, "#live").startswith("Live check of 9 taps")
