"""Snapshots at 80x24 of the sampling, solve and results screens on the simulated demo cell (fixed seeds; the
clock, the report folder and the solve time are pinned so that only the screens can change)."""

import asyncio
import dataclasses
import datetime as dt
from pathlib import Path

import numpy as np
import pytest
from textual.widgets._footer import FooterKey

from fixwizard.solver.solve import solve
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.results.screen import ResultsScreen
from fixwizard.tui.solve.screen import SolveScreen
from pilot_wait import until
from tui_cell import (
    PausedSolver,
    ScreenHost,
    point_above_fixture_m,
    record_spread_taps,
    symmetric_cell,
    wizard_context,
)

pytestmark = pytest.mark.slow  # solves behind the screens (20 s to set up), 15-30 s each

SIZE = (80, 24)
NOW = dt.datetime(2026, 11, 24, 10, 15, 0)
SOLVE_S = 4.2


@pytest.fixture(autouse=True)
def pinned_clocks(monkeypatch):
    monkeypatch.setattr(ResultsScreen, "now", staticmethod(lambda: NOW))
    monkeypatch.setattr(SolveScreen, "clock", staticmethod(lambda: 100.0))


def demo_context(folder: Path, taps: int, max_cells: float, in_the_air: bool = False, solved: bool = True,
                 symmetric: bool = False):
    """A demo-cell context (or a brick's, ``symmetric``) with ``taps`` spread taps (and one 5 cm above the
    fixture), solved at ``max_cells`` with the solve time pinned; reports go to ./reports (shown, never written
    here)."""
    context = wizard_context(folder, max_cells=max_cells, cell=symmetric_cell() if symmetric else None)
    context.with_cell(reports_dir=Path("reports"))
    record_spread_taps(context, taps)
    if in_the_air:
        context.session.record_tap(np.eye(4), base_p_ball_m=point_above_fixture_m(context, 0.05))
    if solved:
        calibration = context.calibration
        solution = solve(context.fixture, context.session.base_p_taps, calibration.ball_diameter_m,
                         calibration.sample_bound_m, max_cells=max_cells)
        context.solution = dataclasses.replace(solution, stats=dataclasses.replace(solution.stats, elapsed_s=SOLVE_S))
    return context


@pytest.fixture(scope="module")
def unique(tmp_path_factory):
    context = demo_context(tmp_path_factory.mktemp("unique"), 12, 8e6)
    yield context
    context.session.release()


def test_sampling_screen_after_eight_taps(snap_compare, tmp_path):
    context = demo_context(tmp_path, 8, 8e6, solved=False)

    async def live_check_done(pilot) -> None:
        screen = pilot.app.screen
        await until(pilot, lambda: not screen.busy and screen.live is not None and screen.live.tap_count == 8
                    and screen.advice is not None and screen.live.refined)
        await pilot.app.workers.wait_for_complete()  # the way above the suggestion may follow the refinement
        await pilot.pause()

    assert snap_compare(ScreenHost(lambda: context.sampling_screen()), terminal_size=SIZE, run_before=live_check_done)
    context.session.release()


def test_solve_screen_during_the_search(snap_compare, tmp_path):
    context = demo_context(tmp_path, 3, 1e7, solved=False)

    async def progress_shown(pilot) -> None:
        await until(pilot, lambda: pilot.app.screen.progress is not None)
        await pilot.pause(0.5)

    assert snap_compare(ScreenHost(lambda: context.solve_screen(PausedSolver())), terminal_size=SIZE,
                        run_before=progress_shown)
    context.session.release()


@pytest.mark.parametrize("view", ["summary", "rotations", "taps"])
def test_results_screen_of_a_unique_pose(snap_compare, unique, view):
    async def show_view(pilot) -> None:
        for _ in range(("summary", "rotations", "taps").index(view)):
            await pilot.press("v")
        await pilot.pause(0.2)

    assert snap_compare(ScreenHost(lambda: unique.results_screen()), terminal_size=SIZE, run_before=show_view)


def test_results_screen_of_an_inconsistent_result(snap_compare, tmp_path):
    context = demo_context(tmp_path, 12, 2.4e6, in_the_air=True)
    assert context.solution.status == "inconsistent"
    assert snap_compare(ScreenHost(lambda: context.results_screen()), terminal_size=SIZE)
    context.session.release()


class WizardKeysHost(ScreenHost):
    """The host with the wizard's keys of every screen, Re-arm among them as when STOPPED (its action answers
    anything here)."""

    BINDINGS = FixwizardApp.BINDINGS


def test_the_footer_of_an_inconsistent_result_keeps_help_in_view_when_stopped(tmp_path):
    """Drop tap and Re-arm (STOPPED) pushed ? Help and part of Re-arm off the footer at 80 columns; Resample is in
    the help, Esc (in the footer) does the same."""
    context = demo_context(tmp_path, 12, 2.4e6, in_the_air=True)
    assert context.solution.status == "inconsistent"

    async def run():
        app = WizardKeysHost(lambda: context.results_screen())
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, ResultsScreen) and bool(app.screen.query(FooterKey)))
            await pilot.pause()
            shown = {key.key: key.region for key in app.screen.query(FooterKey)}
            assert {"f12", "escape", "w", "v", "d", "q", "ctrl+q", "ctrl+r", "question_mark"} <= set(shown)
            assert all(region.width > 0 and region.right <= SIZE[0] for region in shown.values()), shown

    asyncio.run(run())
    context.session.release()


def test_results_screen_of_an_ambiguous_result(snap_compare, tmp_path):
    context = demo_context(tmp_path, 12, 8e6, symmetric=True)
    assert context.solution.status == "ambiguous"
    assert snap_compare(ScreenHost(lambda: context.results_screen()), terminal_size=SIZE)
    context.session.release()
