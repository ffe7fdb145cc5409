"""The solve and results screens on the simulated cell: the solve shows its progress and can be cancelled, the
results show the pose and write a report whose bounds hold the hidden truth, an ambiguous result says where
to tap next, and an inconsistent one names the suspect tap, which can be dropped to solve again."""

import dataclasses
import json

import numpy as np
import pytest
from textual.widgets import DataTable, Input, Static
from textual.widgets._footer import FooterKey

from fixwizard import report
from fixwizard.geometry.se3 import format_ur_pose
from fixwizard.solver.solve import Solution, solve
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.results.screen import Done
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.solve.screen import SolveScreen
from fixwizard.tui.start.sessions import drop_to_take_back
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.key_footer import KeyFooter
from fixwizard.tui.widgets.status import StatusBar
from pilot_wait import dialog_shown, until
from tui_cell import (
    PausedSolver,
    ScreenHost,
    bounds_contain,
    cell_of,
    point_above_fixture_m,
    record_spread_taps,
    symmetric_cell,
    wizard_context,
)

pytestmark = pytest.mark.asyncio
SIZE = (80, 24)


def text_of(screen, selector: str) -> str:
    return str(screen.query_one(selector, Static).content)


def solved(context) -> None:
    """Solve the session's taps as the solve screen does and keep the solution for the results screen."""
    calibration = context.calibration
    context.solution = solve(context.fixture, context.session.base_p_taps, calibration.ball_diameter_m,
                             calibration.sample_bound_m, max_cells=context.max_cells)


@pytest.fixture
def tapped(tmp_path):
    """A context with 12 spread taps."""
    context = wizard_context(tmp_path)
    record_spread_taps(context, 12)
    yield context
    context.session.release()


@pytest.mark.slow
async def test_solve_shows_progress_then_results_write_a_report_holding_the_true_pose(tapped):
    app = ScreenHost(lambda: tapped.solve_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: screen.progress is not None)
        await pilot.pause(0.3)
        figures = text_of(screen, "#figures")
        assert "Elapsed:" in figures and "Looking closer: pass" in figures and "Candidate poses left:" in figures
        assert "cells" not in figures and "level" not in figures  # the search's own figures are on o (Details)
        await pilot.press("o")
        if not app.results:  # still solving
            assert "Details: rotation level" in text_of(screen, "#figures")
        await until(pilot, lambda: app.results)
        solution = app.results[0]
        assert isinstance(solution, Solution)
        assert solution.status == "unique"

        tapped.solution = solution
        app.push_screen(tapped.results_screen(), app.results.append)
        await pilot.pause()
        results = app.screen
        assert "UNIQUE: one pose of the fixture explains the 12 taps" in text_of(results, "#headline")
        summary = text_of(results, "#summary-text")
        assert f"UR pose   {format_ur_pose(solution.base_T_cad)}" in summary
        assert "Guaranteed" in summary and "any point of the fixture within" in summary and "99% within" in summary
        default_path = results.query_one("#report-path", Input).value
        assert default_path.startswith(str(tapped.reports_dir / "demo_bracket-")) and default_path.endswith(".yaml")
        await pilot.press("w")
        assert text_of(results, "#written") == f"Report written to {tapped.reports_dir.resolve()}/" \
                                               f"{default_path.rsplit('/', 1)[1]}"
        assert results.written.is_file()
        loaded = report.load(results.written)
        assert loaded.status == "unique"
        assert bounds_contain(loaded, cell_of(tapped), cell_of(tapped).truth.base_T_cad)
        assert loaded.data["simulated"] is True
        assert loaded.data["session"]["journal"] == str(tapped.session.path)
        assert len(loaded.data["inputs"]["points_m"]) == 12
        await pilot.press("q")
        assert app.results[-1] == Done(results.written)


async def test_cancel_stops_the_solve_and_goes_back(tapped):
    app = ScreenHost(lambda: tapped.solve_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: screen.progress is not None)
        solving = screen.solver.pid
        await pilot.press("escape")
        assert app.results == [None] and not screen.running
        assert screen.solver.pid not in (None, solving)  # the solving process ended, a fresh one waits


async def test_a_key_of_another_step_during_the_solve_says_why_it_does_nothing(tapped):
    """t and the other keys of sampling did nothing on the solve screen, and said nothing."""
    app = ScreenHost(lambda: tapped.solve_screen(PausedSolver()))
    async with app.run_test(size=SIZE, notifications=True) as pilot:
        screen = app.screen
        await until(pilot, lambda: screen.progress is not None)
        await pilot.press("t", "g", "o")  # o is the solve screen's own key (Details)
        await until(pilot, lambda: len(app._notifications) >= 2)
        await pilot.pause()
        assert [str(note.message) for note in app._notifications] == [
            f"The solve is running, so {key} does nothing now: wait for the result, or press Esc to cancel it and go "
            "back to sampling (the taps are kept)." for key in ("t (Tap)", "g (Go)")]
        assert screen.running and app.results == [] and "Details: rotation level" in text_of(screen, "#figures")


async def test_the_solve_screen_keeps_the_status_line_and_the_footer_whole(tapped):
    """The solve screen's padding indented the wizard's status line and footer by a column and cut their last one."""
    app = FixwizardApp(tapped.cell, sampling=tapped.sampling)
    async with app.run_test(size=SIZE) as pilot:
        await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
        app.screen.dismiss(True)
        await until(pilot, lambda: isinstance(app.screen, SolveScreen) and bool(app.screen.query(StatusBar))
                    and bool(app.screen.query(FooterKey)))
        await pilot.pause()
        for bar in (app.screen.query_one(StatusBar), app.screen.query_one(KeyFooter)):
            assert (bar.region.x, bar.region.width) == (0, SIZE[0]), type(bar).__name__
        assert app.screen.query_one("#title").region.x == 1  # the screen's own text stays indented
        await pilot.press("escape")
        await until(pilot, lambda: isinstance(app.screen, SamplingScreen))


async def test_a_solve_input_problem_is_explained_and_esc_goes_back(tapped):
    tapped.calibration = dataclasses.replace(tapped.calibration, sample_bound_m=0.05)  # 50 mm: a unit mistake
    app = ScreenHost(lambda: tapped.solve_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: not screen.query_one("#problem").has_class("-empty"))
        problem = text_of(screen, "#problem")
        assert "A sample bound of 50 mm is implausible for a robot tap" in problem
        assert problem.endswith("Press Esc to go back to sampling.")
        await pilot.press("escape")
        assert app.results == [None]


@pytest.mark.slow
async def test_the_report_path_can_be_edited_and_a_bad_one_is_explained(tapped, tmp_path):
    tapped.with_cell(max_cells=1e5)  # a coarse result is enough to write
    solved(tapped)
    app = ScreenHost(lambda: tapped.results_screen())
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    async with app.run_test(size=SIZE) as pilot:
        results = app.screen
        await pilot.press("e")
        path_input = results.query_one("#report-path", Input)
        assert path_input.has_focus
        path_input.value = ""
        await pilot.press(*str(blocked / "report.yaml"), "enter")
        assert results.query_one("#written").has_class("-problem")
        assert text_of(results, "#written").startswith(
            f"The report was not written: {blocked} is a file, not a folder: choose another report path")
        await pilot.press("q")
        assert "not written yet" in text_of(results, "#written") and app.results == []
        await pilot.press("e")
        path_input.value = str(tmp_path / "elsewhere" / "pose.yaml")
        await pilot.press("enter")
        assert report.load(tmp_path / "elsewhere" / "pose.yaml").status == tapped.solution.status
        await pilot.press("q")
        assert app.results == [Done(results.written)]


@pytest.mark.slow
async def test_a_report_path_naming_a_file_asks_before_replacing_it(tapped, tmp_path):
    """A file already at the typed path was replaced without a word (another fixture's report, say); now the
    screen asks first, and keeping the file says what to do next. The report it wrote itself is written again
    without asking."""
    tapped.with_cell(max_cells=1e5)  # a coarse result is enough to write
    solved(tapped)
    other = tmp_path / "other-fixture.yaml"
    other.write_text("another fixture's report")
    app = ScreenHost(lambda: tapped.results_screen())
    async with app.run_test(size=SIZE) as pilot:
        results = app.screen
        path_input = results.query_one("#report-path", Input)

        async def write_to(typed: str) -> None:
            await pilot.press("e")
            await until(pilot, lambda: path_input.has_focus)
            path_input.value = typed
            await pilot.press("enter")

        await write_to(str(other))
        await until(pilot, lambda: dialog_shown(app, Confirm))
        await pilot.press("n")
        await until(pilot, lambda: app.screen is results)
        assert other.read_text() == "another fixture's report" and results.written is None
        assert f"{other} is kept. Type another path (e), then press w" in text_of(results, "#written")
        assert results.query_one("#written").has_class("-problem")
        await write_to(str(tmp_path / "pose.yaml"))
        assert results.written == tmp_path / "pose.yaml"
        await pilot.press("w")
        assert app.screen is results and text_of(results, "#written").startswith("Report written to")
        await write_to(str(other))
        await until(pilot, lambda: dialog_shown(app, Confirm))
        await pilot.press("y")
        await until(pilot, lambda: app.screen is results and results.written == other)
        assert report.load(other).status == tapped.solution.status


@pytest.mark.slow
async def test_a_report_path_naming_an_input_is_refused_without_asking_to_replace_it(tapped):
    """The session journal or the mesh typed as the report's path: the screen asked "Replace the file? What it holds
    now is lost" about the operator's journal, and refused only once told to replace it. Now it refuses at once."""
    tapped.with_cell(max_cells=1e5)  # a coarse result is enough to write
    solved(tapped)
    journal = tapped.session.path.read_bytes()
    app = ScreenHost(lambda: tapped.results_screen())
    async with app.run_test(size=SIZE) as pilot:
        results = app.screen
        path_input = results.query_one("#report-path", Input)
        for typed, what in ((tapped.session.path, "the session journal"), (tapped.fixture.path, "the fixture mesh")):
            await pilot.press("e")
            await until(pilot, lambda: path_input.has_focus)
            path_input.value = str(typed)
            await pilot.press("enter")
            await pilot.pause()
            assert app.screen is results, f"{what}: asked {type(app.screen).__name__}"
            assert text_of(results, "#written").startswith(f"The report was not written: {typed} is {what} ")
            assert "choose another report path" in text_of(results, "#written") and results.written is None
    assert tapped.session.path.read_bytes() == journal


@pytest.mark.slow
async def test_an_inconsistent_result_names_the_suspect_and_dropping_it_solves(tapped):
    tapped.session.record_tap(np.eye(4), base_p_ball_m=point_above_fixture_m(tapped, 0.05))
    solved(tapped)
    app = ScreenHost(lambda: tapped.results_screen())
    async with app.run_test(size=SIZE) as pilot:
        results = app.screen
        assert "INCONSISTENT: no pose of the fixture explains all 13 taps" in text_of(results, "#headline")
        summary = text_of(results, "#summary-text")
        assert "Tap 13 lies" in summary and "Press d to drop tap 13" in summary
        await pilot.press("d")
        assert app.results == ["resample"]
        assert len(tapped.session.taps) == 12
        kinds = [json.loads(line)["kind"] for line in tapped.session.path.read_text().splitlines()[1:]]
        assert kinds == ["tap"] * 13 + ["drop"]

        app.push_screen(tapped.solve_screen(), app.results.append)
        await until(pilot, lambda: len(app.results) == 2)
        again = app.results[1]
        assert again.status == "unique" and again.contains(cell_of(tapped).truth.base_T_cad)


async def test_after_a_drop_sampling_says_so_and_u_takes_the_drop_back_with_the_tap_in_its_place(tapped):
    """A drop pressed by mistake (or regretted once the taps were looked at) is undone like a tap: the tap counts
    again where it was; the next u undoes the last tap as before."""
    session = tapped.session
    ids = [tap.id for tap in session.taps]
    session.drop(ids[4])  # the solver's suspect can be any tap
    app = ScreenHost(lambda: tapped.sampling_screen(drop_to_take_back(session)))  # as the app opens it after d
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        await until(pilot, lambda: "Tap 5 was dropped" in text_of(screen, "#note"))
        assert text_of(screen, "#note") == ("Tap 5 was dropped last: it does not count (the journal keeps it, marked "
                                            "dropped). Press u to take the drop back.")
        await pilot.press("u")
        assert [tap.id for tap in session.taps] == ids
        assert screen.query_one(DataTable).row_count == 12
        assert text_of(screen, "#note") == "Tap 5 counts again: its drop is undone (the journal keeps both)."
        await pilot.press("u")
        assert [tap.id for tap in session.taps] == ids[:-1]
        assert text_of(screen, "#note") == "Tap 12 undone; the journal keeps it, marked undone."
    kinds = [json.loads(line)["kind"] for line in session.path.read_text().splitlines()[1:]]
    assert kinds == ["tap"] * 12 + ["drop", "restore", "undo"]


@pytest.mark.slow
async def test_a_wrong_ball_diameter_is_said_plainly_instead_of_blaming_a_tap(tapped):
    tapped.calibration = dataclasses.replace(tapped.calibration, ball_diameter_m=0.006)  # the ball is 3 mm
    solved(tapped)
    app = ScreenHost(lambda: tapped.results_screen())
    async with app.run_test(size=SIZE) as pilot:
        results = app.screen
        assert "INCONSISTENT" in text_of(results, "#headline")
        summary = text_of(results, "#summary-text")
        fitted_mm = tapped.solution.diagnosis.ball_diameter_m * 1e3
        assert abs(fitted_mm - 3.0) < 0.5
        assert summary.startswith(f"The taps fit a ball of about {fitted_mm:.1f} mm, the tip calibration says 6.0 mm: "
                                  "check the ball (measure it) and calibrate the tip again")
        assert "Press d to drop tap" not in summary
        await pilot.press("v", "v", "v")
        details = text_of(results, "#details-text")
        assert f"Ball diameter fitted with the pose: {fitted_mm:.2f} mm." in details and "cells survive" in details


@pytest.mark.slow
async def test_a_tip_calibrated_on_another_robot_is_named_first_when_no_pose_explains_the_taps(tapped):
    """The operator chose a calibration made on another robot (the example's, on the demo cell): its ball and tip
    are not this tool's; the result says so before any cause the taps' figures suggest."""
    tapped.calibration = dataclasses.replace(tapped.calibration, robot="UR arm at 10.0.0.7", ball_diameter_m=0.006)
    solved(tapped)
    app = ScreenHost(lambda: tapped.results_screen())
    async with app.run_test(size=SIZE):
        assert "INCONSISTENT" in text_of(app.screen, "#headline")
        assert text_of(app.screen, "#summary-text").startswith(
            "The tip calibration truth was made on UR arm at 10.0.0.7, not on this robot (simulated cell): unless "
            "this very tool is on its flange, untouched since, every tap misses. Calibrate the tip on this robot "
            "and tap again.\nThe taps fit a ball of about ")


@pytest.mark.slow
async def test_an_ambiguous_result_lists_the_modes_and_says_where_to_tap_next(tmp_path):
    context = wizard_context(tmp_path, cell=symmetric_cell())
    record_spread_taps(context, 12)
    solved(context)
    assert context.solution.status == "ambiguous"
    app = ScreenHost(lambda: context.results_screen())
    async with app.run_test(size=SIZE) as pilot:
        summary = text_of(app.screen, "#summary-text")
        assert "AMBIGUOUS: the 12 taps leave 4 distinct poses" in text_of(app.screen, "#headline")
        assert "Candidate poses that fit the taps (probability, pose, guaranteed bounds):" in summary
        assert "  1. " in summary and "  2. " in summary
        assert "Next: Tap the " in summary and "mm apart there" in summary
        scroll = app.screen.query_one("#summary VerticalScroll")
        assert scroll.max_scroll_y > 0  # longer than the screen: the arrow keys scroll it
        await pilot.press("pagedown")
        assert scroll.scroll_y == scroll.max_scroll_y
        assert not app.screen.check_action("drop_suspect", ())
        await pilot.press("r")
        assert app.results == ["resample"]
    context.session.release()
