"""The solve screen: the full solve of the session's taps in the fixture's solver process, with the candidate poses
left, elapsed time and how far the search has got (its grid levels and cell budget on ``o``), then each phase of the
estimates in words; Esc cancels (the process is stopped and a fresh one started), and a key of another step (``t``,
``g``...) is answered with why it does nothing. Dismisses with the ``Solution``, or None when cancelled or after an
input problem."""

import time
from collections.abc import Callable

import numpy as np
from textual import events
from textual.app import ComposeResult
from textual.screen import Screen
from textual.widgets import ProgressBar, Static

from fixwizard.solver.search import SearchProgress, search_budget
from fixwizard.solver.solve import Solution, SolveStage
from fixwizard.tui import keys
from fixwizard.tui.cell import Cell, Sampling
from fixwizard.tui.dismiss import dismiss_when_on_top
from fixwizard.tui.widgets.key_footer import KeyFooter
from fixwizard.tui.workers import run_in_solver
from fixwizard.workflow.solver_process import Event, Failed, Progress, Solved, SolveRequest, SolverProcess
from fixwizard.workflow.stage_words import stage_words

TICK_S = 0.25


def budget_used(progress: SearchProgress, max_cells: float) -> float:
    """How far (0-1, log scale) the surviving cells are towards ending the search: it usually stops once the
    next level would pass the search's part of the budget (8 children per cell) or nothing survives."""
    if progress.survivors == 0:
        return 1.0
    if progress.final:
        return 1.0
    return float(np.clip(np.log(8.0 * progress.survivors) / np.log(search_budget(max_cells)), 0.0, 1.0))


class SolveScreen(Screen[Solution | None]):
    """Runs the full solve of ``sampling``'s taps in ``solver`` (the fixture's solver process)."""

    BINDINGS = [keys.binding(keys.BACK, "Cancel"), keys.binding(keys.DETAILS)]
    HELP_TITLE = "solving"
    HELP_ABOUT = ("The full solve searches every fixture pose that explains the taps; the bar shows how far it is. "
                  "Wait for the result, or press Esc to cancel and go back to sampling (the taps are kept).")
    clock: Callable[[], float] = staticmethod(time.monotonic)

    def __init__(self, cell: Cell, sampling: Sampling, solver: SolverProcess) -> None:
        super().__init__()
        self.cell = cell
        self.sampling = sampling
        self.solver = solver
        self.progress: SearchProgress | None = None
        self.stage: SolveStage | None = None
        self.running = False
        self._started = 0.0
        self._budget_shown = 0.0
        self._details = False

    def compose(self) -> ComposeResult:
        sampling = self.sampling
        yield Static(f"Solving{' (SIMULATED)' if self.cell.simulated else ''}: every pose of "
                     f"{sampling.fixture.path.name} that fits your {len(sampling.session.taps)} taps", id="title",
                     markup=False)
        yield Static("The search keeps every pose that fits the taps and looks closer at each pass. The bar shows "
                     "how far it has got; o shows the search's own figures.", id="about", markup=False)
        yield ProgressBar(total=1.0, show_eta=False, id="budget")
        yield Static("", id="figures", markup=False)
        yield Static("", id="problem", classes="-empty", markup=False)
        yield KeyFooter(compact=True)

    def on_mount(self) -> None:
        self._started = self.clock()
        self._show()
        self.set_interval(TICK_S, self._show)
        sampling, calibration = self.sampling, self.sampling.calibration
        self.running = True
        run_in_solver(self, self.solver, SolveRequest(sampling.session.base_p_taps, calibration.ball_diameter_m,
                                                      calibration.sample_bound_m, self.cell.max_cells), self._event)

    def on_unmount(self) -> None:
        if self.running:  # nobody is left to show the result
            self.solver.stop()

    def on_key(self, event: events.Key) -> None:
        """A key of another step (t, u, g, s...) does nothing here: while the solve runs, say so and what does."""
        step_key = next((key for key in keys.SCREEN_KEYS if event.key in key.keys.split(",")), None)
        if self.running and step_key is not None and event.key not in self.active_bindings:
            self.notify(f"The solve is running, so {keys.name(step_key)} ({step_key.label}) does nothing now: wait for "
                        f"the result, or press {keys.name(keys.BACK)} to cancel it and go back to sampling (the taps "
                        "are kept).", severity="warning")

    def action_details(self) -> None:
        self._details = not self._details
        self._show()

    def action_back(self) -> None:
        if self.running:
            self.running = False
            self.solver.stop()
        self.dismiss(None)

    def _event(self, event: Event) -> None:
        """One answer of the solver: progress (the timer shows it), the solution, or a problem."""
        if isinstance(event, Progress):
            self.progress = event.search or self.progress
            self.stage = event.stage or self.stage
        elif isinstance(event, Solved):
            self.running = False
            dismiss_when_on_top(self, event.solution)
        elif isinstance(event, Failed):
            self.running = False
            problem = self.query_one("#problem", Static)
            problem.update(f"{event.message}\nPress Esc to go back to sampling.")
            problem.remove_class("-empty")

    def _show(self) -> None:
        elapsed_s = self.clock() - self._started
        progress, max_cells = self.progress, self.cell.max_cells
        if progress is None:
            lines = ["Preparing the fixture's distance map...", "Candidate poses left: -"]
        else:
            self._budget_shown = max(self._budget_shown, budget_used(progress, max_cells))
            lines = [f"Looking closer: pass {progress.rotation_level + progress.position_level}",
                     f"Candidate poses left: {progress.survivors:,} of {progress.evaluated:,} checked"]
            if self._details:
                lines.append(f"Details: rotation level {progress.rotation_level}, position level "
                             f"{progress.position_level}; {progress.survivors:,} cells of a budget of {max_cells:,.0f}")
            if progress.final and self.stage is not None:
                lines.append(f"Search done: {stage_words(self.stage)}...")
            elif progress.final:
                lines.append("No pose fits all taps: looking for the tap that does not fit..."
                             if progress.survivors == 0 else "Search done: computing bounds and estimates...")
        lines.insert(0, f"Elapsed: {elapsed_s:.0f} s")
        self.query_one("#budget", ProgressBar).update(progress=self._budget_shown)
        self.query_one("#figures", Static).update("\n".join(lines))
