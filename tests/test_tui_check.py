"""The wizard's "Check a calibrated fixture" on the simulated cell: from the start screen, pick the fixture of a
report, tap the suggested points with the simulated hands, check: untouched it is consistent, pushed by 4 mm it
has moved; every tap is journaled; a changed mesh and a missing report are explained."""

import asyncio
import datetime as dt
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from textual.widgets import DataTable, Footer, Select, Static

from fixwizard import report
from fixwizard.demo import demo_cell, demo_fixture
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.solver.solve import solve
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.cell import Cell, SavedCalibration
from fixwizard.tui.check.screen import CheckScreen, checkable_reports
from fixwizard.tui.launch import simulated_cell
from fixwizard.tui.start.screen import StartScreen
from fixwizard.tui.tapping import FREEDRIVE_STAYS_OFF
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import error_message
from pilot_wait import dialog_shown, until
from tui_cell import SAMPLE_BOUND_M, ScreenHost, spread_taps, start_fixture, truth_calibration

SIZE = (80, 24)
SEED = 3
EXAMPLE_CALIBRATION = Path(__file__).resolve().parents[1] / "calibrations" / "example_matlab_logo.yaml"


@pytest.fixture(scope="module")
def calibrated():
    """The demo cell of SEED calibrated: its report (as the wizard writes it, SIMULATED) and the cell."""
    cell = demo_cell(SEED)
    cell.connect()
    taps = spread_taps(cell, 14)
    fixture = demo_fixture()
    solution = solve(fixture, taps, cell.truth.ball_diameter_m, SAMPLE_BOUND_M, max_cells=2e6, max_samples=2000)
    assert solution.status == "unique"
    return report.report_dict(solution, fixture, taps, cell.truth.ball_diameter_m, SAMPLE_BOUND_M,
                              SAMPLE_BOUND_M / 3, simulated=True), cell


def context_for(tmp_path, calibrated, push_m: float = 0.0, **report_changes) -> tuple[Cell, SavedCalibration]:
    """The calibrated cell (its fixture pushed along x by ``push_m``), its report (with ``report_changes``) in
    reports/, the true tip."""
    data, cell = calibrated
    (tmp_path / "reports").mkdir(exist_ok=True)
    report.write(tmp_path / "reports" / "demo_bracket-1.yaml", {**data, **report_changes})
    base_T_cad = cell.truth.base_T_cad.copy()
    base_T_cad[0, 3] += push_m
    checked = SimulatedCell.with_fixture(cell.fixture, seed=5, base_T_cad=base_T_cad,
                                         tcp_p_tip_m=cell.truth.tcp_p_tip_m)
    checked.connect()
    return (Cell(robot=checked, robot_name="simulated cell", simulated=True, hands=SimulatedHands(checked, seed=2),
                 reports_dir=tmp_path / "reports", sessions_dir=tmp_path / "sessions"),
            SavedCalibration(truth_calibration(cell), tmp_path / "calibrations" / "truth.yaml"))


class CheckHost(ScreenHost):
    """The screen alone, with the app services its workers use: the status refresh and the error modal
    (``ScreenHost`` keeps the errors)."""

    def refresh_robot_status(self) -> None:
        pass


def check_host(cell: Cell, tip: SavedCalibration) -> CheckHost:
    """The check screen of ``cell``'s reports, alone."""
    return CheckHost(lambda: CheckScreen(cell, tip, checkable_reports(cell.reports_dir)))


def text_of(screen, selector: str) -> str:
    return str(screen.query_one(selector, Static).content)


async def tap_suggested(pilot, screen: CheckScreen, count: int) -> None:
    await until(pilot, lambda: screen.fixture is not None and not screen.busy)
    for _ in range(count):
        for key in "mt":
            await pilot.press(key)
            await until(pilot, lambda: not screen.busy)


async def check(pilot, screen: CheckScreen) -> str:
    await pilot.press("c")
    await until(pilot, lambda: screen.result is not None)
    return text_of(screen, "#check-verdict")


def stop_as_the_tap_ends(app: CheckHost, robot: SimulatedCell) -> None:
    """Make the next taps end with STOP pressed as they end (the robot's stop finds no motion to halt)."""
    tap = robot.tap

    def stopped(*args, **kwargs):
        result = tap(*args, **kwargs)
        for cancel in app.motion_cancels:
            cancel.set()
        robot.stop()
        return result

    robot.tap = stopped


@pytest.mark.parametrize("fault, freedrive_after", [("no_surface", True), ("protective_stop_during_tap", False),
                                                    ("stop_as_the_tap_ends", False)])
def test_freedrive_comes_back_after_a_check_tap_only_when_it_ended_as_planned(tmp_path, calibrated, fault,
                                                                             freedrive_after):
    """As on the sampling screen: after a tap that touched nothing freedrive is on again; after a protective stop
    it stays off (before, it came back on by itself after the error), and the error says how to turn it on. STOP
    pressed as a tap ended let freedrive come back on by itself: now the tap is kept and the note says freedrive
    stays off."""
    cell, tip = context_for(tmp_path, calibrated)

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=SIZE) as pilot:
            screen = app.screen
            await until(pilot, lambda: screen.fixture is not None and not screen.busy
                        and cell.robot.status().mode == "freedrive")
            await pilot.press("m")  # above a suggested point: the tap touches
            await until(pilot, lambda: not screen.busy and cell.robot.status().mode == "freedrive")
            if fault == "stop_as_the_tap_ends":
                stop_as_the_tap_ends(app, cell.robot)
            else:
                cell.robot.inject_fault(fault)
            await pilot.press("t")
            await until(pilot, lambda: not screen.busy and (app.errors or "STOP was pressed" in
                                                            text_of(screen, "#check-note")))
            await pilot.pause(0.1)
            if fault == "protective_stop_during_tap":
                cell.robot.unlock()
            assert (cell.robot.status().mode == "freedrive") is freedrive_after and not app.motion_cancels
            said = text_of(screen, "#check-note") if fault == "stop_as_the_tap_ends" else error_message(app.errors[0])
            assert (FREEDRIVE_STAYS_OFF in said) is not freedrive_after
            assert len(screen._taps()) == (1 if fault == "stop_as_the_tap_ends" else 0)

    asyncio.run(run())


@pytest.mark.slow
@pytest.mark.parametrize("push_m, verdict, advice", [
    (0.0, "consistent with the report: poses the report allows explain the 7 taps, and to first order (small moves) "
     "they put every point of the fixture within ", "Keep using the report's pose."),
    (0.004, "MOVED: no pose the report allows explains the 7 taps", "Calibrate it again.")],
    ids=["consistent", "moved"])
def test_the_suggested_taps_tell_whether_the_fixture_moved_and_what_to_do_next(tmp_path, calibrated, push_m, verdict,
                                                                                advice):
    """The seven suggested taps, spread over the faces and the directions they face, see every move: consistent, they
    say to keep using the report's pose (four, as suggested before, always left a move unseen)."""
    cell, tip = context_for(tmp_path, calibrated, push_m)

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=SIZE) as pilot:
            screen = app.screen
            await until(pilot, lambda: "Tap 6-8 points spread over the fixture" in text_of(screen, "#check-suggest"))
            assert "SIMULATED" in text_of(screen, "#check-title")
            assert "demo_bracket-1.yaml: unique" in text_of(screen, "#check-report")
            assert cell.robot.status().mode == "freedrive"
            await tap_suggested(pilot, screen, 7)
            assert screen.query_one(DataTable).row_count == 7
            shown = await check(pilot, screen)
            assert shown.startswith(verdict) and advice in shown
            assert screen.query_one("#check-verdict").has_class("-moved") is (push_m > 0)
            await pilot.press("u")
            assert screen.result is None and screen.query_one(DataTable).row_count == 6
            await until(pilot, lambda: not screen.busy)
            await pilot.press("t")  # the ball is still above the last point
            await until(pilot, lambda: not screen.busy and screen.query_one(DataTable).row_count == 7)
            assert (await check(pilot, screen)).startswith(verdict)
            journal = screen.journal.path
            await pilot.press("escape")
            await until(pilot, lambda: app.results == [None])
        assert app.errors == []
        return journal

    journal = asyncio.run(run())
    assert journal.parent == tmp_path / "sessions" / "checks"
    records = [json.loads(line) for line in journal.read_text().splitlines()]
    assert [record.get("kind") for record in records[1:]] == ["tap"] * 7 + ["undo", "tap", "closed"]
    assert records[-1]["verify"] == ("moved" if push_m else "consistent")
    assert records[0]["fixture"]["report"].endswith("demo_bracket-1.yaml")


@pytest.mark.slow
def test_at_80x23_the_verdict_and_every_tap_are_in_view(tmp_path, calibrated):
    """A MOVED verdict under the suggestions left the taps table its header alone at 80x23; once checked, the
    suggestions make room (back with the next tap), and the verdict's mark is a bar at its side, not a box, so
    that all eight taps show."""
    cell, tip = context_for(tmp_path, calibrated, push_m=0.01)

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=(80, 23)) as pilot:
            screen = app.screen
            await tap_suggested(pilot, screen, 8)
            assert (await check(pilot, screen)).startswith("MOVED")
            await pilot.pause()
            table, verdict = screen.query_one(DataTable), screen.query_one("#check-verdict", Static)
            assert not screen.query_one("#check-suggest").display
            assert table.size.height >= 9  # the header and 8 taps (the most suggested)
            assert verdict.region.bottom <= screen.query_one(Footer).region.y
            await tap_suggested(pilot, screen, 1)
            assert screen.query_one("#check-suggest").display
    asyncio.run(run())


def test_two_taps_that_fit_are_too_few_and_the_verdict_says_to_tap_more(tmp_path, calibrated):
    cell, tip = context_for(tmp_path, calibrated)

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=SIZE) as pilot:
            screen = app.screen
            await tap_suggested(pilot, screen, 2)
            assert (await check(pilot, screen)).startswith(
                "consistent with the report: poses the report allows explain the 2 taps, too few to see a small move: "
                "tap 6-8 points spread over the fixture, then check again.\n")
        assert app.errors == []

    asyncio.run(run())


def wizard_with_a_report(tmp_path, calibrated) -> tuple[Cell, Path]:
    """The wizard's simulated cell of SEED in ``tmp_path`` with the calibrated report in reports/, and a stored tip
    calibration (its path) in calibrations/."""
    context = simulated_cell(SEED, pace_s=0.0, folder=tmp_path)
    context_for(tmp_path, calibrated)
    path = tmp_path / "calibrations" / "example.yaml"
    path.parent.mkdir()
    shutil.copy(EXAMPLE_CALIBRATION, path)
    return context, path


def test_the_start_screen_opens_the_check_with_a_stored_tip_calibration(tmp_path, calibrated):
    context, path = wizard_with_a_report(tmp_path, calibrated)

    async def run():
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None)
            app.screen.query_one("#calibration", Select).value = "new"
            await pilot.pause()
            app.screen.query_one("#check").focus()
            notified = []
            app.screen.notify = lambda message, **_: notified.append(message)
            await pilot.press("enter")
            await pilot.pause()
            assert isinstance(app.screen, StartScreen) and "needs a stored tip calibration" in notified[0]
            app.screen.query_one("#calibration", Select).value = str(path)
            button = app.screen.query_one("#check")
            await until(pilot, lambda: not button.has_class("-active"))  # a button ignores a second press at once
            button.focus()
            await pilot.press("enter")
            await until(pilot, lambda: isinstance(app.screen, CheckScreen) and app.screen.fixture is not None)
            assert app.screen.tip.calibration.name == "example_matlab_logo"
            assert "demo_bracket" in str(app.screen.query_one("#check-fixture", Select).value)
            await pilot.press("escape")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            await pilot.press("ctrl+q")

    asyncio.run(run())


def test_esc_asks_before_leaving_taps_that_are_not_checked(tmp_path, calibrated):
    """Esc left a check with taps not checked yet without a word (a check is never resumed: they were to tap again);
    it asks now, Stay keeps the taps, and once checked Esc leaves at once (the other tests)."""
    cell, tip = context_for(tmp_path, calibrated)

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=SIZE) as pilot:
            screen = app.screen
            await tap_suggested(pilot, screen, 1)
            await pilot.press("escape")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            assert text_of(app.screen, "#dialog-message").startswith("The 1 tap of this check is not checked yet")
            await pilot.press("n")
            await until(pilot, lambda: app.screen is screen)
            assert len(screen._taps()) == 1 and app.results == []
            await pilot.press("escape")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("y")
            await until(pilot, lambda: app.results == [None])

    asyncio.run(run())


def test_without_reports_the_check_says_to_calibrate_first(tmp_path, calibrated):
    cell, tip = context_for(tmp_path, calibrated)
    (tmp_path / "reports" / "demo_bracket-1.yaml").unlink()

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=SIZE) as pilot:
            screen = app.screen
            await pilot.pause()
            assert "No report with a pose" in text_of(screen, "#check-note")
            await pilot.press("t")
            assert "Choose a fixture" in text_of(screen, "#check-note")
            await pilot.press("c")
            assert "Tap at least one point first" in text_of(screen, "#check-note")
            await pilot.press("escape")
            await until(pilot, lambda: app.results == [None])

    asyncio.run(run())


def test_a_report_whose_mesh_changed_is_explained_and_nothing_is_tapped(tmp_path, calibrated):
    mesh = tmp_path / "bracket.stl"
    mesh.write_bytes(demo_fixture().path.read_bytes() + b"\0")
    cell, tip = context_for(tmp_path, calibrated, fixture={**calibrated[0]["fixture"], "mesh": str(mesh)})

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=SIZE) as pilot:
            screen = app.screen
            await until(pilot, lambda: "not the one the report" in text_of(screen, "#check-suggest"))
            await pilot.press("t")
            assert "Choose a fixture whose mesh loads" in text_of(screen, "#check-note")
            assert screen.journal is None and not (tmp_path / "sessions").exists()

    asyncio.run(run())
    assert np.isfinite(calibrated[0]["bounds"]["position_m"])


def test_a_report_dated_in_the_future_is_said_so_not_given_a_negative_age(tmp_path, calibrated):
    """A clock gone backwards (or another PC's clock ahead): the check said the report was '-3.0 days old'."""
    in_3_days = dt.datetime.now(dt.UTC) + dt.timedelta(days=3)
    cell, tip = context_for(tmp_path, calibrated, created=in_3_days.isoformat(timespec="seconds"))

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=SIZE) as pilot:
            screen = app.screen
            await until(pilot, lambda: "in the future" in text_of(screen, "#check-report"))
            assert "dated 3.0 days in the future (check the clocks of the PCs)" in text_of(screen, "#check-report")
            assert "-3.0" not in text_of(screen, "#check-report")

    asyncio.run(run())


def test_the_reports_guaranteed_bounds_are_said_rounded_up(tmp_path, calibrated):
    """The report's 1.2345 mm and 1.2345 deg were said as "within 1.2 mm and 1.2 deg", less than the report
    guarantees."""
    bounds = {**calibrated[0]["bounds"], "position_m": 0.0012345, "rotation_deg": 1.2345}
    cell, tip = context_for(tmp_path, calibrated, bounds=bounds)

    async def run():
        app = check_host(cell, tip)
        async with app.run_test(size=SIZE) as pilot:
            screen = app.screen
            await until(pilot, lambda: "demo_bracket-1.yaml: unique" in text_of(screen, "#check-report"))
            assert "the fixture is within 1.3 mm and 1.3 deg of its pose" in text_of(screen, "#check-report")

    asyncio.run(run())
