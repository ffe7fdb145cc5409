"""The results screen: the solution in words and numbers, pictures of the rotation set and of the taps on
the fixture, the solver's own figures (Details), the report (default path shown, editable) and what to do next.
Dismisses with "resample" (back to sampling, also after dropping the suspect tap of an inconsistent result) or
``Done`` (with the report written, if any)."""

import datetime as dt
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.screen import Screen
from textual.widgets import Input, Label, Static, TabbedContent, TabPane, Tabs

from fixwizard.errors import FixwizardError
from fixwizard.plots import rotation_map_for_solution, taps_view_for_solution
from fixwizard.solver.solve import Solution
from fixwizard.tui import keys
from fixwizard.tui.cell import Cell, Sampling
from fixwizard.tui.results.text import (
    headline,
    modes_lines,
    summary_lines,
    suspect_lines,
    warning_lines,
)
from fixwizard.tui.tip_origin import other_robot_cause
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import error_message
from fixwizard.tui.widgets.key_footer import KeyFooter
from fixwizard.tui.widgets.picture_view import PictureView
from fixwizard.workflow.advice import distinguishing_tap
from fixwizard.workflow.details import details_lines
from fixwizard.workflow.wizard_report import default_report_path, report_target, write_session_report


@dataclass(frozen=True)
class Done:
    """The operator is done with this session; ``report_path`` is the report written for its taps, if any."""

    report_path: Path | None


Outcome = Literal["resample"] | Done
TABS = ("summary", "rotations", "taps", "details")


class ResultsScreen(Screen[Outcome]):
    """Shows ``solution`` for the taps of ``sampling`` and writes the report."""

    BINDINGS = [
        keys.binding(keys.BACK),
        keys.binding(keys.WRITE),
        keys.binding(keys.EDIT_PATH, show=False),
        keys.binding(keys.VIEW),
        keys.binding(keys.DROP),
        keys.binding(keys.RESAMPLE, show=False),  # Esc (Back) does the same, and is in the footer
        keys.binding(keys.DONE),
        keys.binding(keys.SCROLL_DOWN, show=False),
        keys.binding(keys.SCROLL_UP, show=False),
        keys.binding(keys.PAGE_DOWN, show=False),
        keys.binding(keys.PAGE_UP, show=False),
    ]
    HELP_TITLE = "results"
    HELP_ABOUT = ("The headline says whether one pose explains the taps. Read the pose and its guaranteed bounds in "
                  "the summary, look at the pictures (View), then write the report (Write; Edit path first to put "
                  "it elsewhere) and finish (Done). Resample, or Esc, goes back to sampling to add taps.")
    now: Callable[[], dt.datetime] = staticmethod(dt.datetime.now)

    def __init__(self, cell: Cell, sampling: Sampling, solution: Solution) -> None:
        super().__init__()
        self.cell = cell
        self.sampling = sampling
        self.solution = solution
        self.written: Path | None = None
        self._warned_unwritten = False

    def compose(self) -> ComposeResult:
        cell, sampling, solution = self.cell, self.sampling, self.solution
        simulated = "SIMULATED: " if cell.simulated else ""
        yield Static(f"{simulated}{headline(solution, len(sampling.session.taps))}", id="headline", markup=False)
        with TabbedContent(id="views"):
            with TabPane("Summary", id="summary"):
                yield VerticalScroll(Static("\n".join(self._summary()), id="summary-text", markup=False))
            with TabPane("Rotation set", id="rotations"):
                yield self._rotations_view()
            with TabPane("Taps on fixture", id="taps"):
                yield PictureView(lambda width, height: taps_view_for_solution(
                    solution, sampling.fixture, sampling.session.base_p_taps, width, height), id="taps-view")
            with TabPane("Details", id="details"):
                yield VerticalScroll(Static("\n".join(details_lines(solution)), id="details-text", markup=False))
        with Horizontal(id="report-row"):
            yield Label("Report:")
            path = default_report_path(cell.reports_dir, sampling.fixture, self.now())
            yield Input(str(path), id="report-path", compact=True)
        yield Static("Press w to write the report there (e to edit the path first).", id="written", markup=False)
        yield KeyFooter(compact=True)

    def on_mount(self) -> None:
        self.action_leave_path()

    def _summary(self) -> list[str]:
        solution = self.solution
        if solution.status == "inconsistent":
            elsewhere = other_robot_cause(self.sampling.calibration, self.cell.robot_name)
            lines = ([elsewhere] if elsewhere else []) + suspect_lines(solution)
        else:
            lines = summary_lines(solution)
            if solution.status == "ambiguous":
                first, second = solution.modes[0].base_T_cad, solution.modes[1].base_T_cad
                lines += modes_lines(solution, distinguishing_tap(self.sampling.fixture, first, second))
        return [*lines, *warning_lines(solution), "The solver's own figures: View (v) > Details."]

    def _rotations_view(self) -> PictureView | Static:
        if self.solution.status == "inconsistent":
            return Static("No orientation of the fixture explains the taps, so there is no rotation set to draw.",
                          markup=False)
        return PictureView(lambda width, height: rotation_map_for_solution(self.solution, width, height),
                           id="rotations-view")

    # --- keys ---

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action == "drop_suspect":
            return self.solution.suspect_tap is not None
        return True

    def action_next_view(self) -> None:
        views = self.query_one("#views", TabbedContent)
        views.active = TABS[(TABS.index(views.active) + 1) % len(TABS)]

    def action_scroll_summary(self, lines: int) -> None:
        """Arrow keys scroll the summary while the tabs have the focus (the summary can be longer than the screen)."""
        self.query_one("#summary", TabPane).query_one(VerticalScroll).scroll_relative(y=lines, animate=False)

    def action_edit_path(self) -> None:
        self.query_one("#report-path", Input).focus()

    def action_back(self) -> None:
        """Leave the report path when editing it; else back to sampling (the taps stay)."""
        if self.query_one("#report-path", Input).has_focus:
            self.action_leave_path()
        else:
            self.action_resample()

    def action_leave_path(self) -> None:
        """Focus the view tabs, where the screen's letter keys work."""
        self.query_one("#views", TabbedContent).query_one(Tabs).focus()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.action_write()
        self.action_leave_path()

    def action_write(self) -> None:
        """Write the report to the path typed; asks before replacing a file this screen did not write (another
        fixture's report, say), after refusing one of the inputs (the journal, the mesh) without asking."""
        typed = self.query_one("#report-path", Input).value.strip()
        if not typed:
            self._say("Type where the report should go (e), then press w.", problem=True)
            return
        try:
            target = report_target(typed, self.sampling.fixture, self.sampling.session)
        except (FixwizardError, OSError) as error:
            self._say(f"The report was not written: {error_message(error)}", problem=True)
            return
        if target != self.written and os.path.isfile(target):
            def answered(replace: bool | None) -> None:
                if replace:
                    self._write(target)
                else:
                    self._say(f"The report was not written; {target} is kept. Type another path "
                              f"({keys.name(keys.EDIT_PATH)}), then press {keys.name(keys.WRITE)}.", problem=True)

            self.app.push_screen(Confirm("Replace the file?", f"{target} already exists. Replace it with this "
                                         "report? What it holds now is lost.", "Replace", "Keep it"), answered)
            return
        self._write(target)

    def _write(self, target: Path) -> None:
        sampling = self.sampling
        try:
            self.written = write_session_report(target, self.solution, sampling.fixture, sampling.session,
                                                sampling.calibration, self.cell.simulated)
        except (FixwizardError, OSError) as error:
            self._say(f"The report was not written: {error_message(error)}", problem=True)
            return
        self._say(f"Report written to {self.written}")

    def action_drop_suspect(self) -> None:
        session, suspect = self.sampling.session, self.solution.suspect_tap
        if suspect is None:  # the key is disabled then
            return
        try:
            session.drop(session.taps[suspect.index].id)
        except (FixwizardError, OSError) as error:
            self._say(error_message(error), problem=True)
            return
        self.dismiss("resample")  # sampling says which tap was dropped (the session's last change)

    def action_resample(self) -> None:
        self.dismiss("resample")

    def action_done(self) -> None:
        if self.written is None and not self._warned_unwritten:
            self._warned_unwritten = True
            self._say("The report is not written yet: press w to write it, or q again to finish without it.",
                      problem=True)
            return
        self.dismiss(Done(self.written))

    def _say(self, text: str, problem: bool = False) -> None:
        written = self.query_one("#written", Static)
        written.update(text)
        written.set_class(problem, "-problem")
