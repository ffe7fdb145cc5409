"""How long the wizard's event loop is late while the solver works: a 10 ms timer on the real app (Pilot, simulated
cell) records how late each of its ticks runs during a live check and a full solve, and how long a key press takes
to show its effect. Used by tests/test_tui_responsiveness.py (generous bounds) and benchmarks/responsiveness.py
(the real numbers, with busy processes beside it)."""

import gc
import time
from dataclasses import dataclass, field
from pathlib import Path

from textual.widgets import Static

from fixwizard.tui.heap import freeze_long_lived_objects
from pilot_wait import until
from tui_cell import ScreenHost, record_spread_taps, wizard_context

TICK_S = 0.01
SIZE = (80, 24)
WAIT_S = 600.0


@dataclass
class LoopLag:
    """Lateness (s) of each tick of a ``TICK_S`` timer, per phase ("live", "solve")."""

    lags_s: dict[str, list[float]] = field(default_factory=dict)
    phase: str | None = None
    _last: float | None = None

    def tick(self) -> None:
        now = time.monotonic()
        if self.phase is not None and self._last is not None:
            self.lags_s.setdefault(self.phase, []).append(max(now - self._last - TICK_S, 0.0))
        self._last = now

    def start(self, phase: str | None) -> None:
        self.phase, self._last = phase, None


@dataclass(frozen=True)
class Measured:
    lags_s: dict[str, list[float]]
    key_s: float  # from a key press during the live check to its note on the screen
    live_s: float  # the live check's wall time
    solve_s: float


async def measure_wizard(folder: Path, taps: int, max_cells: float) -> Measured:
    """Open sampling with ``taps`` spread taps (its live check starts), press g while it runs, then solve."""
    context = wizard_context(folder, max_cells=max_cells)
    record_spread_taps(context, taps)
    app = ScreenHost(lambda: context.sampling_screen())
    lag = LoopLag()
    freeze_long_lived_objects()  # as the wizard process does (the test process's heap is larger still)
    try:
        async with app.run_test(size=SIZE) as pilot:
            app.set_interval(TICK_S, lag.tick)
            screen = app.screen
            started = time.monotonic()
            lag.start("live")
            await until(pilot, lambda: screen.live_running and screen._live_progress is not None, WAIT_S)
            pressed = time.monotonic()
            await pilot.press("g")
            await until(pilot, lambda: "No suggestion yet" in str(screen.query_one("#note", Static).content)
                        or screen.advice is not None, WAIT_S)
            key_s = time.monotonic() - pressed
            await until(pilot, lambda: not screen.live_running, WAIT_S)
            live_s = time.monotonic() - started
            lag.start("solve")
            started = time.monotonic()
            solved = []
            app.push_screen(context.solve_screen(), solved.append)
            await until(pilot, lambda: bool(solved), WAIT_S)
            solve_s = time.monotonic() - started
            lag.start(None)
    finally:
        gc.unfreeze()
        context.session.release()
    return Measured(lag.lags_s, key_s, live_s, solve_s)
