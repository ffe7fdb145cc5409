"""Pilot helpers that take the wizard's tip-calibration screens on the simulated cell as an operator does."""

from textual.pilot import Pilot

from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from pilot_wait import until


async def press_when_ready(pilot: Pilot, key: str) -> None:
    """Press ``key`` once the current screen has finished its robot call, and wait for the next one to end."""
    await until(pilot, lambda: not pilot.app.screen.busy)
    await pilot.press(key)
    await until(pilot, lambda: not pilot.app.screen.busy)


async def to_automatic_taps(pilot: Pilot, pivot_count: int) -> None:
    """From the pivot screen: the simulated hands' pivot poses and table points, on to the automatic taps."""
    app = pilot.app
    await until(pilot, lambda: isinstance(app.screen, PivotScreen))
    for _ in range(pivot_count):
        await press_when_ready(pilot, "m")
    await pilot.press("n")
    await until(pilot, lambda: isinstance(app.screen, TablePointsScreen))
    for _ in range(3):
        await press_when_ready(pilot, "m")
    await pilot.press("n")
    await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))


async def to_result(pilot: Pilot, pivot_count: int) -> None:
    """From the pivot screen through every step to the result, computed."""
    await to_automatic_taps(pilot, pivot_count)
    await pilot.press("g")
    await until(pilot, lambda: isinstance(pilot.app.screen, CalibrationResultScreen) and not pilot.app.screen.busy)
