"""The whole wizard as an operator drives it with the keyboard on the simulated demo cell: launch, a new tip
calibration, 12 taps, solve, the report written; the report loads and its guaranteed bounds hold the
simulator's hidden pose of the fixture."""

import asyncio
import dataclasses

import pytest
from textual.widgets import Button, Static

from fixwizard import report
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.launch import simulated_cell
from fixwizard.tui.results.screen import ResultsScreen
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.start.screen import StartScreen
from pilot_wait import until
from tui_cell import bounds_contain, start_fixture
from tui_tip_steps import press_when_ready, to_result

pytestmark = pytest.mark.slow  # the whole wizard from launch to a report, about a minute

SEED = 5
SIZE = (80, 24)
TAPS = 12
MAX_CELLS = 8e6


def test_launch_calibrate_tap_solve_and_write_a_report_holding_the_hidden_pose(tmp_path):
    context = dataclasses.replace(simulated_cell(SEED, pace_s=0.0, folder=tmp_path), max_cells=MAX_CELLS)
    cell = context.hands.cell

    async def run() -> None:
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None
                        and app.robot_status is not None and app.robot_status.connected)
            app.screen.query_one("#continue", Button).focus()
            await pilot.press("enter")  # a new tip calibration is the default

            await to_result(pilot, context.hands.pivot_count)
            app.screen.query_one("#accept", Button).focus()
            await pilot.press("enter")

            await until(pilot, lambda: isinstance(app.screen, SamplingScreen))
            sampling = app.screen
            for _ in range(TAPS):
                await press_when_ready(pilot, "m")
                await press_when_ready(pilot, "t")
            assert len(sampling.session.taps) == TAPS
            await pilot.press("s")

            await until(pilot, lambda: isinstance(app.screen, ResultsScreen)  # through the solve screen
                        and bool(app.screen.query("#headline")))
            assert sampling.is_attached is False
            assert "UNIQUE" in str(app.screen.query_one("#headline", Static).content)
            await pilot.press("w")
            written = app.screen.written
            assert str(app.screen.query_one("#written", Static).content) == f"Report written to {written}"
            await pilot.press("q")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            return written

    written = asyncio.run(run())
    assert written.parent == (tmp_path / "reports").resolve()
    loaded = report.load(written)
    assert loaded.status == "unique" and loaded.data["simulated"] is True
    assert len(loaded.data["inputs"]["points_m"]) == TAPS
    assert bounds_contain(loaded, cell, cell.truth.base_T_cad)
    journal = (tmp_path / "sessions").glob("*.jsonl")
    assert any(f'"report":"{written}"' in path.read_text() for path in journal)  # the session is closed
