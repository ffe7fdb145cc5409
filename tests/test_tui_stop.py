"""STOP pressed between a tap's key and the tap itself (the worker still turning freedrive off, as a slow robot link
or a busy computer holds it): the tap does not start after the STOP. The robot's own stop halts only a motion that
has started, so the wizard looks at STOP's cancel just before each robot motion it asked for, and hands the robot
the STOP count it read before that look: a STOP landing between the look and the call is refused by the robot."""

import asyncio
import contextlib
import threading
import time
from collections.abc import AsyncIterator

import pytest
from textual.pilot import Pilot
from textual.widgets import Static

from fixwizard.robot import MotionStopped
from fixwizard.robot.sim import SimulatedCell
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.cell import Cell
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.tapping import FREEDRIVE_STAYS_OFF
from fixwizard.tui.widgets.errors import ErrorModal
from pilot_wait import dialog_shown, until
from test_tui_app import SIZE, at_start, pivot_by_hand, wizard
from tui_cell import wizard_context


class HeldFreedriveOff:
    """The robot's first ``freedrive(False)`` (a tap turns freedrive off before it taps) held until ``release``, as
    a slow robot or a busy computer holds it; counts the taps that start."""

    def __init__(self, robot: SimulatedCell) -> None:
        self.holding = threading.Event()
        self.released = threading.Event()
        self.taps_started = 0
        freedrive, tap = robot.freedrive, robot.tap

        def held(on: bool, stop_mark: int | None = None) -> None:
            if not on and not self.released.is_set():
                self.holding.set()
                self.released.wait(timeout=60)
            freedrive(on, stop_mark)

        def counted(*args, **kwargs):
            self.taps_started += 1
            return tap(*args, **kwargs)

        robot.freedrive, robot.tap = held, counted


async def stop_as_freedrive_turns_off(pilot: Pilot, key: str, robot: SimulatedCell) -> HeldFreedriveOff:
    """Press ``key`` (a tap), then F12 while the tap turns freedrive off, then let it go on; the taps it started."""
    held = HeldFreedriveOff(robot)
    await pilot.press(key)
    await until(pilot, held.holding.is_set)
    await pilot.press("f12")
    await until(pilot, lambda: pilot.app.stopped)
    held.released.set()
    await until(pilot, lambda: not pilot.app.motion_running())
    return held


def test_a_sampling_tap_asked_for_before_a_stop_does_not_start_after_it(tmp_path):
    """t then F12 while the tap turned freedrive off: the tap started after the STOP (STOPPED on the status line) and
    was recorded; the robot's stop halts only a motion that has started. Now it does not start, and says why."""
    async def run():
        context = wizard_context(tmp_path)
        app = FixwizardApp(context.cell, sampling=context.sampling)
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
            await pilot.press("m")
            await until(pilot, lambda: not app.screen.busy)
            held = await stop_as_freedrive_turns_off(pilot, "t", context.robot)
            assert held.taps_started == 0 and context.session.taps == []
            problem = str(app.screen.query_one("#problem", Static).render())
            assert problem.startswith("The tap was stopped on request; nothing was recorded from it")
            assert FREEDRIVE_STAYS_OFF in problem
    asyncio.run(run())


@contextlib.asynccontextmanager
async def at_table_points(tmp_path) -> AsyncIterator[tuple[Cell, Pilot]]:
    """The wizard on the simulated cell, calibrating the tip by hand, at the table points after the pivot."""
    context = wizard(tmp_path)
    app = FixwizardApp(context)
    async with app.run_test(size=SIZE) as pilot:
        await at_start(pilot)
        await pivot_by_hand(pilot)
        yield context, pilot


@pytest.mark.parametrize("key", ["t", "m"])  # the tap key, or the simulated hands and then the tap
def test_a_table_point_tap_asked_for_before_a_stop_does_not_start_after_it(tmp_path, key):
    async def run():
        async with at_table_points(tmp_path) as (context, pilot):
            app, table = pilot.app, pilot.app.screen
            held = await stop_as_freedrive_turns_off(pilot, key, context.robot)
            assert held.taps_started == 0 and len(table.workflow.poses("table_coarse")) == 0
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            assert str(app.screen.query_one("#dialog-message", Static).render()).startswith(
                "The tap was stopped on request; nothing was recorded from it")
    asyncio.run(run())


def stop_pressed_as_the_tap_leaves(app: FixwizardApp, robot: SimulatedCell) -> list[BaseException]:
    """Make the robot's next tap press STOP as the wizard does (on its event loop) just before the call reaches the
    robot, as when the GIL switches to the key's handler right after the worker looked whether STOP was pressed; what
    the tap raised is kept."""
    tap, raised = robot.tap, []

    def stop_first(*args, **kwargs):
        count = robot.stop_count()
        app.call_from_thread(app.action_stop_robot)
        deadline = time.monotonic() + 10.0
        while robot.stop_count() == count and time.monotonic() < deadline:  # the wizard stops the robot in a thread
            time.sleep(0.001)
        try:
            return tap(*args, **kwargs)
        except BaseException as error:
            raised.append(error)
            raise

    robot.tap = stop_first
    return raised


def test_a_stop_landing_between_the_look_at_stop_and_the_table_tap_keeps_the_tap_from_starting(tmp_path):
    """The tap's worker looked whether STOP was pressed, then STOP came before its call reached the robot: the tap
    started after the STOP and was recorded. The robot now gets the STOP count read before the look, and refuses."""
    async def run():
        async with at_table_points(tmp_path) as (context, pilot):
            app, table = pilot.app, pilot.app.screen
            raised = stop_pressed_as_the_tap_leaves(app, context.robot)
            await pilot.press("t")
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            assert app.stopped and len(table.workflow.poses("table_coarse")) == 0
            assert [type(error) for error in raised] == [MotionStopped]
            assert str(app.screen.query_one("#dialog-message", Static).render()).startswith(
                "Table point A: the tap was stopped on request; nothing was recorded from it")
    asyncio.run(run())
