"""Each screen of the start and the tip calibration at 80x24, as the operator sees it on the simulated cell
(fixed seed). Regenerate after a deliberate change with `pytest tests/test_tui_snapshots.py --snapshot-update`
and look at the SVGs in tests/__snapshots__/."""

from pathlib import Path

import pytest
from textual.pilot import Pilot
from textual.widgets import Input

from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.tui.widgets.help import HelpScreen
from pilot_wait import dialog_shown, until
from test_tui_app import SIZE, at_start, calibrate_by_hand, press_button, wizard

pytestmark = pytest.mark.slow  # screens driven to a state and rendered, 5-10 s each


async def settled(pilot: Pilot) -> None:
    """No robot call running and the status bar showing the robot's current state."""
    app = pilot.app
    await until(pilot, lambda: not getattr(app.screen, "busy", False))
    app.refresh_robot_status()
    await until(pilot, lambda: app.robot_status == app.cell.robot.status())
    await pilot.pause()


async def pivot_with_three_poses(pilot: Pilot) -> None:
    await at_start(pilot)
    await press_button(pilot, "#continue")
    await until(pilot, lambda: isinstance(pilot.app.screen, PivotScreen) and not pilot.app.screen.busy)
    for _ in range(3):
        await pilot.press("m")
        await until(pilot, lambda: not pilot.app.screen.busy)
    await settled(pilot)


def snapshot_app(tmp_path: Path) -> FixwizardApp:
    return FixwizardApp(wizard(tmp_path))


def test_start_screen(snap_compare, tmp_path):
    async def run_before(pilot: Pilot) -> None:
        await at_start(pilot)
        await settled(pilot)

    assert snap_compare(snapshot_app(tmp_path), terminal_size=SIZE, run_before=run_before)


def test_pivot_screen_with_a_live_residual(snap_compare, tmp_path):
    assert snap_compare(snapshot_app(tmp_path), terminal_size=SIZE, run_before=pivot_with_three_poses)


def test_table_points_screen_after_point_a(snap_compare, tmp_path):
    async def run_before(pilot: Pilot) -> None:
        await pivot_with_three_poses(pilot)
        await pilot.press("n")
        await until(pilot, lambda: isinstance(pilot.app.screen, TablePointsScreen) and not pilot.app.screen.busy)
        await pilot.press("m")
        await settled(pilot)

    assert snap_compare(snapshot_app(tmp_path), terminal_size=SIZE, run_before=run_before)


def test_automatic_taps_screen_before_starting(snap_compare, tmp_path):
    async def run_before(pilot: Pilot) -> None:
        await at_start(pilot)
        await calibrate_by_hand(pilot)
        await settled(pilot)

    assert snap_compare(snapshot_app(tmp_path), terminal_size=SIZE, run_before=run_before)


def test_calibration_result_screen(snap_compare, tmp_path):
    async def run_before(pilot: Pilot) -> None:
        await at_start(pilot)
        await calibrate_by_hand(pilot)
        await pilot.press("g")
        await until(pilot, lambda: isinstance(pilot.app.screen, CalibrationResultScreen))
        await settled(pilot)
        pilot.app.screen.query_one("#name", Input).value = "simulated-tip-example"
        await pilot.pause()

    assert snap_compare(snapshot_app(tmp_path), terminal_size=SIZE, run_before=run_before)


def test_protective_stop_message(snap_compare, tmp_path):
    async def run_before(pilot: Pilot) -> None:
        await pivot_with_three_poses(pilot)
        await pilot.press("n")
        await until(pilot, lambda: isinstance(pilot.app.screen, TablePointsScreen) and not pilot.app.screen.busy)
        pilot.app.cell.robot.inject_fault("protective_stop_during_tap")
        await pilot.press("m")
        await until(pilot, lambda: dialog_shown(pilot.app, ErrorModal))
        await until(pilot, lambda: pilot.app.robot_status.protective_stop)
        await pilot.pause()

    assert snap_compare(snapshot_app(tmp_path), terminal_size=SIZE, run_before=run_before)


def test_help_on_the_pivot_screen(snap_compare, tmp_path):
    async def run_before(pilot: Pilot) -> None:
        await pivot_with_three_poses(pilot)
        await pilot.press("question_mark")
        await until(pilot, lambda: isinstance(pilot.app.screen, HelpScreen))
        await pilot.pause()

    assert snap_compare(snapshot_app(tmp_path), terminal_size=SIZE, run_before=run_before)


def test_stopped_pivot_screen(snap_compare, tmp_path):
    async def run_before(pilot: Pilot) -> None:
        await pivot_with_three_poses(pilot)
        await pilot.press("f12")
        await until(pilot, lambda: pilot.app.stopped)
        await settled(pilot)

    assert snap_compare(snapshot_app(tmp_path), terminal_size=SIZE, run_before=run_before)
