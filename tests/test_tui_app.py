"""The wizard as an operator drives it with the keyboard, on the simulated demo cell (fixed seeds, tmp
folders): the start screen, a whole new tip calibration, cancel, protective stop, STOP and resume."""

import asyncio
import contextlib
import dataclasses
import datetime
import shutil
import threading
from collections.abc import AsyncIterator
from pathlib import Path

import numpy as np
import pytest
from textual.pilot import Pilot
from textual.widgets import Button, Input, OptionList, Select, Static

from fixwizard.calibration.store import load_calibration, save_calibration
from fixwizard.demo import DEMO_MESH, demo_fixture
from fixwizard.errors import InputError
from fixwizard.robot.base import ConnectionLost
from fixwizard.tui import keys
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.cell import Cell, SavedCalibration
from fixwizard.tui.launch import robot_host, simulated_cell, ur_cell
from fixwizard.tui.start import sessions as start_sessions
from fixwizard.tui.start.screen import NEW, StartScreen
from fixwizard.tui.start.sessions import start_session
from fixwizard.tui.tapping import FREEDRIVE_STAYS_OFF
from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.tui.widgets.status import StatusBar
from pilot_wait import dialog_shown, until
from tui_cell import sampling_of, start_fixture

SEED = 3
SIZE = (80, 24)
REPO = Path(__file__).resolve().parents[1]


def text_of(app: FixwizardApp, selector: str) -> str:
    return str(app.screen.query_one(selector, Static).render())


def status_of(app: FixwizardApp) -> str:
    return str(app.screen.query_one(StatusBar).render())


def screen_text(app: FixwizardApp) -> str:
    return "\n".join(str(widget.render()) for widget in app.screen.query(Static))


def wizard(tmp_path: Path, pace_s: float = 0.0) -> Cell:
    return simulated_cell(SEED, pace_s=pace_s, folder=tmp_path)


async def at_start(pilot: Pilot) -> None:
    app = pilot.app
    await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None
                and app.robot_status is not None and app.robot_status.connected)


async def choose(pilot: Pilot, selector: str, value: str) -> None:
    """Pick ``value`` in a Select, as Enter, arrows and Enter would."""
    pilot.app.screen.query_one(selector, Select).value = value
    await pilot.pause()


async def press_button(pilot: Pilot, selector: str) -> None:
    """Tab to the button (once it is mounted) and press Enter once it has the focus (a dialog just closed gives the
    focus back to the widget it had a moment later: an Enter pressed before went there)."""
    await until(pilot, lambda: bool(pilot.app.screen.query(selector)))
    button = pilot.app.screen.query_one(selector, Button)
    button.focus()
    await until(pilot, lambda: button.has_focus)
    await pilot.pause()
    if not button.has_focus:
        button.focus()
        await until(pilot, lambda: button.has_focus)
    await pilot.press("enter")


async def pivot_by_hand(pilot: Pilot) -> None:
    """From the start screen with a new calibration to the table points: the pivot with the SIMULATED hands."""
    app = pilot.app
    await press_button(pilot, "#continue")
    await until(pilot, lambda: isinstance(app.screen, PivotScreen) and not app.screen.busy)
    for _ in range(app.cell.hands.pivot_count):
        await pilot.press(keys.HANDS.keys)
        await until(pilot, lambda: not app.screen.busy)
    await pilot.press("n")
    await until(pilot, lambda: isinstance(app.screen, TablePointsScreen) and not app.screen.busy)


async def calibrate_by_hand(pilot: Pilot) -> None:
    """From the start screen with a new calibration: the pivot and table points with the SIMULATED hands."""
    app = pilot.app
    await pivot_by_hand(pilot)
    for _ in range(3):
        await pilot.press(keys.HANDS.keys)
        await until(pilot, lambda: not app.screen.busy)
    await pilot.press("n")
    await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))


@contextlib.asynccontextmanager
async def at_the_automatic_taps(tmp_path: Path, pace_s: float = 0.0) -> AsyncIterator[tuple[Cell, FixwizardApp, Pilot]]:
    """The wizard on the simulated cell at its automatic calibration taps (pivot and table points by the SIMULATED
    hands); ``pace_s``: the simulated cell's time per motion."""
    context = wizard(tmp_path, pace_s)
    app = FixwizardApp(context)
    async with app.run_test(size=SIZE) as pilot:
        await at_start(pilot)
        await calibrate_by_hand(pilot)
        yield context, app, pilot


async def rearm(pilot: Pilot) -> None:
    """Re-arm after a STOP: the key, then yes in its confirmation."""
    await pilot.press(keys.REARM.keys)
    await until(pilot, lambda: dialog_shown(pilot.app, Confirm))
    await pilot.press("y")
    await until(pilot, lambda: not pilot.app.stopped)


async def stop_and_rearm(pilot: Pilot) -> None:
    """STOP, and once the robot stands still (every automatic step ended, a tap it cut short shown as an error) a
    confirmed re-arm, with the robot call it started on the step's screen (if any) done."""
    app = pilot.app
    await pilot.press("f12")
    await until(pilot, lambda: app.stopped and not app.motion_running() and app.cell.robot.status().mode == "idle")
    await rearm(pilot)
    await until(pilot, lambda: not app.step_screen().busy)


def test_launch_shows_the_start_screen_marked_simulated(tmp_path):
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            status = str(app.screen.query_one(StatusBar).render())
            assert status.startswith(" SIMULATED ") and "connected | idle" in status and "F12 STOP" in status
            assert "SIMULATED demo cell (seed 3) (no real arm moves)" in text_of(app, "#robot")
            assert start_fixture(app).path == DEMO_MESH
            assert "160.0 x 90.0 x 60.0 mm (file units: mm)" in text_of(app, "#fixture-info")
            assert app.screen.query_one("#calibration", Select).value == "new"
    asyncio.run(run())


def test_tab_on_the_start_screen_goes_from_field_to_field_and_round(tmp_path):
    """Every Tab lands on a field or a button, whose focus mark shows: none on the screen's scroll area, which shows
    none (one Tab seemed to do nothing)."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            first, seen = app.focused, []
            for _ in range(20):
                await pilot.press("tab")
                seen.append(app.focused)
                assert isinstance(app.focused, (Input, Select, Button)), app.focused
                if app.focused is first:
                    break
            assert app.focused is first and len(seen) >= 6
    asyncio.run(run())


def test_a_fixture_in_the_wrong_units_is_explained_and_switching_units_loads_it(tmp_path):
    bracket_m = demo_fixture().mesh.copy()
    (tmp_path / "fixtures").mkdir()
    bracket_m.export(tmp_path / "fixtures" / "bracket_in_metres.stl")

    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await choose(pilot, "#fixture", str(tmp_path / "fixtures" / "bracket_in_metres.stl"))
            await until(pilot, lambda: "implausible" in text_of(app, "#fixture-info"))
            message = text_of(app, "#fixture-info")
            assert "0.16 mm small fixture with units 'mm'" in message and "Switch Units to m" in message
            assert "--mesh-units" not in message  # the wizard has no command-line flags to offer
            assert start_fixture(app) is None
            await press_button(pilot, "#continue")
            assert isinstance(app.screen, StartScreen)
            await choose(pilot, "#units", "m")
            await until(pilot, lambda: start_fixture(app) is not None)
            assert start_fixture(app).units == "m"
            assert "160.0 x 90.0 x 60.0 mm (file units: m)" in text_of(app, "#fixture-info")
            assert "SIMULATED: the simulated cell holds the demo bracket" in text_of(app, "#fixture-info")
    asyncio.run(run())


def test_a_typed_path_that_is_no_mesh_is_refused_with_the_reason(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("notes.txt").write_text("not a mesh")

    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await pilot.press("tab", "tab", *"notes.txt", "enter")
            await until(pilot, lambda: "notes.txt is not a mesh file fixwizard reads" in text_of(app, "#fixture-info"))
            assert start_fixture(app) is None
    asyncio.run(run())


@pytest.mark.parametrize("typed", ["bracket.stl", "~no-such-user-fixwizard/bracket.stl"])
def test_a_typed_mesh_path_that_does_not_exist_is_refused_and_the_fixture_stays(tmp_path, monkeypatch, typed):
    """It was added to the list of meshes, and stayed there (a ~user that does not exist was a traceback)."""
    monkeypatch.chdir(tmp_path)

    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            meshes = app.screen.query_one("#fixture", Select).query_one(OptionList)
            listed = meshes.option_count
            await pilot.press("tab", "tab", *typed, "enter")
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            assert text_of(app, "#dialog-message") == (f"There is no file '{typed}': check the path and type it "
                                                       "again, or choose a mesh in the list")
            await press_button(pilot, "#ok")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            assert meshes.option_count == listed and start_fixture(app).path == DEMO_MESH
            assert app.screen.query_one("#fixture-path", Input).value == typed  # to correct it
    asyncio.run(run())


@pytest.mark.slow
def test_a_new_tip_calibration_through_the_screens_is_saved_and_finds_the_hidden_tip(tmp_path):
    async def run():
        context = wizard(tmp_path)
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await at_start(pilot)
            await calibrate_by_hand(pilot)
            await pilot.press("g")
            await until(pilot, lambda: isinstance(app.screen, CalibrationResultScreen) and not app.screen.busy)
            figures = text_of(app, "#result-figures")
            assert figures.startswith("GOOD: use this calibration.") and "Each tap will be trusted to" in figures
            assert "condition number" not in figures and "scatter" not in figures  # those are on Details
            await pilot.press("shift+tab", "shift+tab", "end", "ctrl+u", *"sim-tip", "tab", "tab", "enter")
            await until(pilot, lambda: sampling_of(app) is not None and sampling_of(app).is_mounted)
            session_name = sampling_of(app).session.path.name
            # said on the note line, which no toast covers at 80x24
            assert text_of(app, "#note") == (f"Tip calibration saved to {tmp_path / 'calibrations' / 'sim-tip.yaml'}. "
                                             f"New session {session_name}: every tap is saved there as you go.")
            assert not app._notifications
            return context, sampling_of(app).sampling

    context, sampling = asyncio.run(run())
    session = sampling.session
    saved = load_calibration(tmp_path / "calibrations" / "sim-tip.yaml")
    assert saved.robot == "SIMULATED demo cell (seed 3)" and saved.ball_diameter_m == 0.003
    assert sampling.tip.path == tmp_path / "calibrations" / "sim-tip.yaml"
    assert np.linalg.norm(saved.tcp_p_tip_m - context.robot.truth.tcp_p_tip_m) < 0.0005
    assert saved.sample_bound_m >= context.robot.truth.fk_error_bound_m
    assert session.path.parent == tmp_path / "sessions"
    assert session.header["tip"]["calibration"] == str(tmp_path / "calibrations" / "sim-tip.yaml")


@pytest.mark.slow
def test_redo_from_the_pivot_asks_before_dropping_the_calibration_taps(tmp_path):
    """The result's Redo dropped the pivot poses, the table points and the 56 automatic taps without a word (Esc on
    the pivot asks before dropping 3 poses); it asks first now, and Stay keeps everything."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await calibrate_by_hand(pilot)
            await pilot.press("g")
            await until(pilot, lambda: isinstance(app.screen, CalibrationResultScreen) and not app.screen.busy)
            result = app.screen
            await press_button(pilot, "#redo")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            message = text_of(app, "#dialog-message")
            assert message.startswith(f"Redo drops the {app.cell.hands.pivot_count} pivot poses, the 3 table points "
                                      "and the 56 automatic taps")
            await pilot.press("n")
            await until(pilot, lambda: app.screen is result)
            assert recorded(result.workflow) == {"table": 16, "tilted": 40}
            await press_button(pilot, "#redo")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("y")
            await until(pilot, lambda: isinstance(app.screen, PivotScreen))
            assert len(app.screen.workflow.poses("pivot")) == 0
    asyncio.run(run())


def recorded(workflow) -> dict[str, int]:
    return {step: len(workflow.poses(step)) for step in ("table", "tilted")}


@pytest.mark.slow
def test_cancel_during_the_automatic_taps_keeps_the_taps_and_going_on_continues(tmp_path):
    async def run():
        context = wizard(tmp_path, pace_s=0.02)
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await calibrate_by_hand(pilot)
            screen = app.screen
            await pilot.press("g")
            await until(pilot, lambda: recorded(screen.workflow)["table"] >= 2)
            await pilot.press("escape")
            await until(pilot, lambda: not screen.busy)
            kept = recorded(screen.workflow)
            assert kept["table"] >= 2 and sum(kept.values()) < 56
            step, done, total = ("table taps", kept["table"], 16) if kept["table"] < 16 else \
                ("tilted taps", kept["tilted"], 40)
            assert f"the {step} were cancelled after {done} of {total} taps; the recorded taps are kept" in \
                text_of(app, "#auto-state")
            await pilot.press("g")
            await until(pilot, lambda: isinstance(app.screen, CalibrationResultScreen), timeout_s=20)
            assert recorded(screen.workflow) == {"table": 16, "tilted": 40}
    asyncio.run(run())


@pytest.mark.slow
def test_a_protective_stop_during_a_tap_is_explained_and_unlocking_recovers(tmp_path):
    async def run():
        context = wizard(tmp_path)
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await press_button(pilot, "#continue")
            await until(pilot, lambda: isinstance(app.screen, PivotScreen) and not app.screen.busy)
            for _ in range(3):
                await pilot.press("m")
                await until(pilot, lambda: not app.screen.busy)
            await pilot.press("n")
            await until(pilot, lambda: isinstance(app.screen, TablePointsScreen) and not app.screen.busy)
            context.robot.inject_fault("protective_stop_during_tap")
            await pilot.press("m")
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            message = text_of(app, "#dialog-message")
            assert message.startswith("Table point A: the robot made a protective stop during the tap: unlock")
            assert "Traceback" not in screen_text(app)
            await until(pilot, lambda: app.robot_status.protective_stop)
            await press_button(pilot, "#unlock")
            await until(pilot, lambda: isinstance(app.screen, TablePointsScreen)
                        and not app.robot_status.protective_stop)
            assert "press f and place the ball again" in text_of(app, "#points-state")
            assert app.stopped  # unlocked on the pendant, but the wizard waits for a deliberate re-arm
            await pilot.press("m")
            await pilot.pause()
            assert "A: next" in text_of(app, "#points-state")
            await rearm(pilot)
            await pilot.press("m")
            await until(pilot, lambda: "A: tapped   B: next" in text_of(app, "#points-state"))
    asyncio.run(run())


def test_a_stop_as_a_table_point_tap_ends_leaves_freedrive_off_until_re_armed(tmp_path):
    """STOP pressed as the tap of table point A ended (the robot's stop found no motion to halt) let freedrive come
    back on by itself for B, with the wizard STOPPED; now the arm holds still, the point is kept and the screen says
    how freedrive comes back (re-arming turns it on)."""
    async def run():
        context = wizard(tmp_path)
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await pivot_by_hand(pilot)
            robot, tap = context.robot, context.robot.tap

            def stopped_as_it_ends(*args, **kwargs):
                result = tap(*args, **kwargs)
                app.call_from_thread(app.action_stop_robot)  # F12 as the tap ends
                return result

            robot.tap = stopped_as_it_ends
            await pilot.press("m")
            await until(pilot, lambda: not app.screen.busy and "STOP was pressed" in text_of(app, "#points-state"))
            await pilot.pause(0.1)
            assert app.stopped and robot.status().mode == "idle"
            assert "A: tapped   B: next" in text_of(app, "#points-state")
            assert FREEDRIVE_STAYS_OFF in text_of(app, "#points-state")
            await rearm(pilot)
            await until(pilot, lambda: robot.status().mode == "freedrive")
    asyncio.run(run())


def test_a_protective_stop_during_the_automatic_taps_says_to_re_arm_before_going_on(tmp_path):
    """The step said 'Press g to continue' after a stop, and g is refused until the wizard is re-armed."""
    async def run():
        async with at_the_automatic_taps(tmp_path) as (context, app, pilot):
            screen = app.screen
            context.robot.inject_fault("protective_stop_during_tap")
            await pilot.press("g")
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            state = str(screen.query_one("#auto-state", Static).render())
            assert state.startswith("Stopped: ") and state.endswith(
                "Once the cell is checked and clear, re-arm (Ctrl+R), then press g to continue.")
    asyncio.run(run())


def test_stop_during_the_automatic_taps_says_to_re_arm_before_going_on(tmp_path):
    """STOP cancels the taps between two of them, and the step said 'Press g to continue' while g was refused."""
    async def run():
        async with at_the_automatic_taps(tmp_path, pace_s=0.05) as (_, app, pilot):
            screen = app.screen
            await pilot.press("g")
            await until(pilot, lambda: app.motion_running())
            await pilot.press("f12")
            await until(pilot, lambda: not app.motion_running())
            state = str(screen.query_one("#auto-state", Static).render())
            assert state.startswith("Stopped: ") and state.endswith(
                "Once the cell is checked and clear, re-arm (Ctrl+R), then press g to continue.")
    asyncio.run(run())


def test_re_arming_at_the_automatic_taps_leaves_freedrive_off(tmp_path):
    """Re-arming after a STOP turned freedrive on at the automatic taps as on the steps where the operator guides the
    arm by hand, though here the arm stands where the table point C or the taps left it and f is not offered: now
    freedrive stays off, before the taps and after a STOP cut them short."""
    async def run():
        async with at_the_automatic_taps(tmp_path, pace_s=0.05) as (context, app, pilot):
            await stop_and_rearm(pilot)
            assert context.robot.status().mode == "idle"
            await pilot.press("g")
            await until(pilot, lambda: app.motion_running())
            await stop_and_rearm(pilot)
            assert context.robot.status().mode == "idle"
    asyncio.run(run())


def test_the_note_after_a_reconnect_at_the_automatic_taps_offers_no_freedrive(tmp_path):
    """After Reconnect at the automatic taps the note said 'freedrive is off, press f to guide the arm by hand', as on
    the steps guided by hand, where f is not offered: it says only that the robot is connected again."""
    async def run():
        async with at_the_automatic_taps(tmp_path) as (context, app, pilot):
            context.robot.inject_fault("connection_loss")
            await pilot.press("g")
            await until(pilot, lambda: dialog_shown(app, ErrorModal) and bool(app.screen.query("#reconnect")))
            await press_button(pilot, "#reconnect")
            await until(pilot, lambda: any("Connected to the robot again" in str(note.message)
                                           for note in app._notifications))
            assert "Connected to the robot again." in [str(note.message) for note in app._notifications]
            assert context.robot.status().mode == "idle"
    asyncio.run(run())


def test_a_lost_link_the_status_saw_before_the_operator_reconnected_is_not_reported_again(tmp_path):
    """The status poll saw the link go and asked for the pose to say why; on a busy machine that answer came after the
    operator had pressed Reconnect on the failed motion's error, and a second error ('not connected', or a UR link's
    'still connecting') came up over the robot being connected again."""
    async def run():
        async with at_the_automatic_taps(tmp_path) as (context, app, pilot):
            robot = context.robot
            asked, answer = threading.Event(), threading.Event()
            pose_of = robot.base_T_tcp

            def answered_late_when_lost():
                try:
                    return pose_of()
                except ConnectionLost:
                    asked.set()
                    answer.wait(30.0)
                    raise
            robot.base_T_tcp = answered_late_when_lost
            robot.inject_fault("connection_loss")
            await pilot.press("g")
            await until(pilot, lambda: dialog_shown(app, ErrorModal) and bool(app.screen.query("#reconnect")))
            await until(pilot, asked.is_set)  # the status saw the link go: its question is on its way
            await press_button(pilot, "#reconnect")
            await until(pilot, lambda: any("Connected to the robot again" in str(note.message)
                                           for note in app._notifications))
            answer.set()
            await until(pilot, lambda: not any(worker.group == "link" and worker.is_running for worker in app.workers))
            await pilot.pause()
            assert not isinstance(app.screen, ErrorModal), screen_text(app)
            assert robot.status().connected
    asyncio.run(run())


class StopCounter:
    """The simulated cell, counting ``stop`` calls."""

    def __init__(self, cell) -> None:
        self.cell = cell
        self.stops = 0

    def stop(self) -> None:
        self.stops += 1
        self.cell.stop()

    def __getattr__(self, name: str):
        return getattr(self.cell, name)


@pytest.mark.slow
def test_the_stop_key_halts_the_robot_from_any_screen_and_keeps_the_taps(tmp_path):
    async def run():
        context = wizard(tmp_path, pace_s=0.03)
        context = dataclasses.replace(context, robot=StopCounter(context.robot))
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await pilot.press("f12")
            await until(pilot, lambda: context.robot.stops == 1)
            await rearm(pilot)
            await calibrate_by_hand(pilot)
            screen = app.screen
            await pilot.press("g")
            await until(pilot, lambda: len(screen.workflow.poses("table")) >= 1)
            await pilot.press("ctrl+x")
            await until(pilot, lambda: not screen.busy)
            assert context.robot.stops == 2
            kept = recorded(screen.workflow)
            assert kept["table"] >= 1 and sum(kept.values()) < 56
            state = str(screen.query_one("#auto-state", Static).render())
            assert "was stopped on request; nothing was recorded from it" in state or "were cancelled after" in state
    asyncio.run(run())


def test_the_status_line_says_moving_while_the_simulated_arm_moves_and_only_then(tmp_path):
    """On the simulated cell it said idle through the automatic taps (a UR arm says moving)."""
    async def run():
        async with at_the_automatic_taps(tmp_path) as (context, app, pilot):
            screen = app.screen
            await until(pilot, lambda: " | connected | idle | " in status_of(app))
            context.robot.pace_s = 0.3
            await pilot.press("g")
            await until(pilot, lambda: " | connected | moving | " in status_of(app))
            await pilot.press("escape")  # cancels after the current tap
            await until(pilot, lambda: not screen.busy)
            await until(pilot, lambda: " | connected | idle | " in status_of(app))
    asyncio.run(run())


@pytest.mark.slow
def test_quitting_during_the_automatic_taps_stops_them_after_the_current_tap(tmp_path):
    async def run():
        app = FixwizardApp(wizard(tmp_path, pace_s=0.2))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await calibrate_by_hand(pilot)
            screen = app.screen
            await pilot.press("g")
            await until(pilot, lambda: recorded(screen.workflow)["table"] >= 1)
            await pilot.press("ctrl+q")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("y")
        return screen.workflow

    assert 1 <= sum(recorded(asyncio.run(run())).values()) < 56


def unfinished_session(tmp_path: Path) -> Path:
    """A session with one tap on the demo bracket, calibrated with the stored example calibration."""
    context = wizard(tmp_path)
    shutil.copytree(REPO / "calibrations", tmp_path / "calibrations")
    calibration_path = tmp_path / "calibrations" / "example_matlab_logo.yaml"
    session = start_session(context, demo_fixture(), SavedCalibration(load_calibration(calibration_path),
                                                                      calibration_path))
    session.record_tap(np.eye(4))
    session.release()
    return session.path


def test_the_start_screen_describes_stored_calibrations_and_resumes_an_unfinished_session(tmp_path):
    path = unfinished_session(tmp_path)

    async def run():
        context = wizard(tmp_path)
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await choose(pilot, "#calibration", str(tmp_path / "calibrations" / "example_matlab_logo.yaml"))
            details = text_of(app, "#calibration-info")
            assert "calibrated 2026-11-24 03:09 on Universal Robots arm of the matlab-logo data set (Haugaard, Kim, " \
                "Iversen, ICRA 2024)\nNot calibrated on this robot (SIMULATED demo cell (seed 3)): use it only if " \
                "this very tool, untouched since, is on its flange; otherwise calibrate the tip anew" in details
            assert "each tap is trusted to 0.8 mm" in details
            await choose(pilot, "#session", str(path))
            await press_button(pilot, "#continue")
            await until(pilot, lambda: type(app.screen).__name__ == "SamplingScreen" and app.screen.is_mounted)
            sampling = app.screen.sampling
            assert sampling.session.path == path and len(sampling.session.taps) == 1
            assert sampling.calibration.name == "example_matlab_logo"
            assert text_of(app, "#note") == (f"Resumed the session {path}: 1 tap recorded, fixture "
                                             f"{DEMO_MESH.name}, tip calibration example_matlab_logo.yaml.")
    asyncio.run(run())


def test_the_start_screen_preselects_the_newest_calibration_of_this_robot_only(tmp_path):
    shutil.copytree(REPO / "calibrations", tmp_path / "calibrations")  # made on another robot
    context = wizard(tmp_path)
    example = load_calibration(tmp_path / "calibrations" / "example_matlab_logo.yaml")
    for name, created in (("older", "2026-11-20T08:00:00+00:00"), ("newer", "2026-11-21T08:00:00+00:00")):
        save_calibration(dataclasses.replace(example, name=name, created=created, robot=context.robot_name),
                         tmp_path / "calibrations" / f"{name}.yaml")

    async def preselected(context: Cell) -> tuple[str, str, str]:
        async with FixwizardApp(context).run_test(size=SIZE) as pilot:
            await at_start(pilot)
            select = pilot.app.screen.query_one("#calibration", Select)
            return (str(select.value), str(select.query_one("SelectCurrent #label", Static).render()),
                    text_of(pilot.app, "#calibration-info"))

    value, label, info = asyncio.run(preselected(context))
    assert value == str(tmp_path / "calibrations" / "newer.yaml")
    assert label == "newer.yaml (3.0 mm ball, 2026-11-21)"
    assert info.startswith("Ball diameter 3.0 mm (check it is the ball on the tool), calibrated 2026-11-21 08:00 on "
                           "SIMULATED demo cell (seed 3)\nGood: the ball centre is known to about 0.28 mm")
    for name in ("older", "newer"):
        (tmp_path / "calibrations" / f"{name}.yaml").unlink()
    assert asyncio.run(preselected(wizard(tmp_path)))[0] == NEW


def test_resume_opens_the_session_with_its_fixture_and_calibration(tmp_path):
    path = unfinished_session(tmp_path)

    async def run():
        resumed = wizard(tmp_path)
        app = FixwizardApp(resumed, "")
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: type(app.screen).__name__ == "SamplingScreen" and app.screen.query(StatusBar))
            sampling = app.screen.sampling
            assert sampling.session.path == path and len(sampling.session.taps) == 1
            assert sampling.fixture.path == DEMO_MESH and sampling.fixture.units == "mm"
            assert sampling.calibration.name == "example_matlab_logo"
            assert text_of(app, "#note").startswith(f"Resumed the session {path}: 1 tap recorded")
    asyncio.run(run())


def test_an_unreachable_ur_arm_is_explained_and_nothing_says_simulated(tmp_path):
    async def run():
        context = ur_cell("ur-arm.invalid", folder=tmp_path)
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: dialog_shown(app, ErrorModal) and bool(app.screen.query("#reconnect")))
            message = text_of(app, "#dialog-message")
            assert message.startswith("Cannot connect to the robot at ur-arm.invalid: port 29999 does not accept")
            assert app.screen.query("#reconnect") and not app.screen.query("#unlock")
            await press_button(pilot, "#ok")
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None)
            assert "UR arm at ur-arm.invalid | " in str(app.screen.query_one(StatusBar).render())
            assert " DISCONNECTED " in str(app.screen.query_one(StatusBar).render())
            await press_button(pilot, "#continue")
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            await press_button(pilot, "#ok")
            await until(pilot, lambda: isinstance(app.screen, PivotScreen))
            assert "SIMULATED" not in screen_text(app) + str(app.screen.query_one(StatusBar).render())
            assert app.screen.check_action("simulated_hands", ()) is False
    asyncio.run(run())


def test_the_start_screen_switches_to_a_ur_arm_and_back_to_the_simulated_cell(tmp_path):
    shutil.copytree(REPO / "calibrations", tmp_path / "calibrations")  # made on another robot

    async def run():
        context = wizard(tmp_path)
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await choose(pilot, "#calibration", str(tmp_path / "calibrations" / "example_matlab_logo.yaml"))
            app.screen.query_one("#robot-host", Input).focus()
            await pilot.press(*"127.0.0.3", "enter")  # nothing listens there
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            assert text_of(app, "#dialog-message").startswith("Cannot connect to the robot at 127.0.0.3: port 29999")
            await press_button(pilot, "#ok")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            assert app.cell.robot_name == "UR arm at 127.0.0.3" and not app.cell.simulated and app.cell.hands is None
            assert "\nNot calibrated on this robot (UR arm at 127.0.0.3): " in text_of(app, "#calibration-info")
            assert "SIMULATED" not in screen_text(app) + str(app.screen.query_one(StatusBar).render())
            await press_button(pilot, "#use-simulated")
            await until(pilot, lambda: app.cell.simulated and app.robot_status is not None
                        and app.robot_status.connected)
            assert "SIMULATED" in str(app.screen.query_one(StatusBar).render())
            assert app.cell.hands is not None
    asyncio.run(run())


def test_a_calibration_step_says_at_once_what_the_robot_does_and_clears_it_after(tmp_path):
    async def run():
        app = FixwizardApp(wizard(tmp_path, pace_s=1.6))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await pivot_by_hand(pilot)
            await pilot.press(keys.HANDS.keys)
            await pilot.pause()
            doing = app.screen.query_one("#doing", Static)
            assert str(doing.render()) == "SIMULATED: the hands bring the ball above A; then the robot taps it..."
            assert doing.display
            await until(pilot, lambda: str(doing.render()).endswith("taps it... (1.0 s)"), timeout_s=10.0)
            await until(pilot, lambda: not app.screen.busy, timeout_s=30.0)
            assert not doing.display and "A: tapped" in text_of(app, "#points-state")

    asyncio.run(run())


def test_a_session_that_cannot_be_started_is_explained_before_the_start_screen_returns(tmp_path):
    """The start screen came back over the error, hiding it: each Continue stacked another unseen error."""
    shutil.copytree(REPO / "calibrations", tmp_path / "calibrations")
    (tmp_path / "sessions").write_text("a file where the sessions folder goes")

    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await choose(pilot, "#calibration", str(tmp_path / "calibrations" / "example_matlab_logo.yaml"))
            await press_button(pilot, "#continue")
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            message = str(app.screen.query_one("#dialog-message").render())
            assert message.startswith("Cannot start the session ") and "sessions is a file, not a folder" in message
            await pilot.press("enter")
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and app.screen.is_mounted)
            assert [type(screen).__name__ for screen in app.screen_stack[1:]] == ["StartScreen"]
    asyncio.run(run())


def test_table_points_tapped_on_one_spot_are_cleared_with_why_and_tapped_again(tmp_path):
    """A, B and C tapped without moving the ball: the next step would have had no table frame and the points
    could not be tapped again."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await pivot_by_hand(pilot)
            table = app.screen
            await pilot.press(keys.HANDS.keys)  # the hands bring the ball above A
            await until(pilot, lambda: not table.busy)
            for _ in range(2):  # then B and C where A was
                await pilot.press(keys.TAP.keys)
                await until(pilot, lambda: not table.busy)
            assert len(table.workflow.poses("table_coarse")) == 3
            await pilot.press("n")
            await until(pilot, lambda: "The points were cleared: tap A, B and C again" in text_of(app, "#points-state"))
            assert "must be at least 10 mm from the corner B" in text_of(app, "#points-state")
            assert app.screen is table and len(table.workflow.poses("table_coarse")) == 0
            for _ in range(3):  # tapped again where they belong, the automatic taps come next
                await pilot.press(keys.HANDS.keys)
                await until(pilot, lambda: not table.busy)
            await pilot.press("n")
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))
    asyncio.run(run())


@pytest.mark.parametrize("typed", ["999.999.1.1; rm -rf ~", "192.168.0", "ur arm", "-robot"])
def test_a_typed_robot_address_that_is_none_is_refused_and_the_robot_stays(tmp_path, typed):
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            before = app.cell.robot_name
            app.screen.query_one("#robot-host", Input).focus()
            await pilot.press(*typed, "enter")
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            assert "is not the address of a robot: type its IP address (e.g. 192.168.0.10)" in \
                text_of(app, "#dialog-message")
            await press_button(pilot, "#ok")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            assert app.cell.robot_name == before and app.cell.simulated and app.robot_status.connected
    asyncio.run(run())


@pytest.mark.parametrize("typed, host", [("192.168.0.10", "192.168.0.10"), (" ur5e-cell2.local ", "ur5e-cell2.local"),
                                         ("fe80::1", "fe80::1"), ("10.0.0.07", None)])
def test_robot_addresses_are_ip_addresses_or_host_names(typed, host):
    if host is None:
        with pytest.raises(InputError, match="is not the address of a robot"):
            robot_host(typed)
    else:
        assert robot_host(typed) == host


def test_two_wizards_starting_a_session_of_one_fixture_in_the_same_second_get_one_each(tmp_path, monkeypatch):
    """The name holds the time to the second: the second wizard was told its session 'exists already; resume it',
    though the first one held it."""
    class Frozen(datetime.datetime):
        @classmethod
        def now(cls, tz=None):
            return cls(2026, 12, 6, 16, 30, 0)

    monkeypatch.setattr(start_sessions, "datetime", Frozen)
    context = wizard(tmp_path)
    calibration_path = REPO / "calibrations" / "example_matlab_logo.yaml"
    tip = SavedCalibration(load_calibration(calibration_path), calibration_path)
    first, second = (start_session(context, demo_fixture(), tip) for _ in range(2))
    assert [first.path.name, second.path.name] == ["demo_bracket-20261206-163000.jsonl",
                                                   "demo_bracket-20261206-163000-2.jsonl"]
    first.release()
    second.release()


def test_a_session_name_another_wizard_takes_between_the_look_and_the_creation_goes_to_the_next_name(
        tmp_path, monkeypatch):
    """Two wizards at the very same moment: both saw the name free, the second to create it was told to 'choose
    another name' (it cannot: the name is the time). Here the other wizard creates it just before this one does."""
    class Frozen(datetime.datetime):
        @classmethod
        def now(cls, tz=None):
            return cls(2026, 12, 6, 16, 30, 0)

    monkeypatch.setattr(start_sessions, "datetime", Frozen)
    create = start_sessions.SamplingSession.create
    others = []

    def other_wizard_first(path, *args, **kwargs):
        if not others:
            others.append(create(path, *args, **kwargs))
        return create(path, *args, **kwargs)

    monkeypatch.setattr(start_sessions.SamplingSession, "create", other_wizard_first)
    calibration_path = REPO / "calibrations" / "example_matlab_logo.yaml"
    session = start_session(wizard(tmp_path), demo_fixture(),
                            SavedCalibration(load_calibration(calibration_path), calibration_path))
    assert [others[0].path.name, session.path.name] == ["demo_bracket-20261206-163000.jsonl",
                                                        "demo_bracket-20261206-163000-2.jsonl"]
    others[0].release()
    session.release()
