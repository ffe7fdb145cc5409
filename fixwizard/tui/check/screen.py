"""The "Check a calibrated fixture" screen: pick a fixture that has a report, tap the 6-8 suggested points spread
over it, and learn whether it is still where the report says (``workflow.verify``: moved is a proof).

The fixtures are the newest report of each name in the reports folder (``workflow.cell_reports``). Freedrive is
on; ``t`` taps and journals the tap (fsynced) in ``sessions/checks/`` before it is shown, ``u`` undoes the last,
``c`` checks the taps against the report, ``m`` (simulated cell) brings the ball above the next suggested point
(keys from ``tui.keys``).
Robot calls, loading the mesh and the check run in worker threads. Dismisses with None.
"""

import datetime as dt
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import BindingType
from textual.screen import Screen
from textual.widgets import Select, Static

from fixwizard import report
from fixwizard.errors import FixwizardError
from fixwizard.fixture import Fixture
from fixwizard.robot.base import TapResult
from fixwizard.solver.search import SearchCancelled
from fixwizard.tui import keys
from fixwizard.tui.cell import Cell, SavedCalibration
from fixwizard.tui.dismiss import dismiss_when_on_top
from fixwizard.tui.freedrive import freedrive_on, freedrive_unless_stopped
from fixwizard.tui.tapping import FREEDRIVE_STAYS_OFF, tap_and_record
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import error_message
from fixwizard.tui.widgets.key_footer import KeyFooter
from fixwizard.tui.widgets.taps_table import TapsTable
from fixwizard.tui.workers import ShownError, in_thread, services
from fixwizard.workflow.cell_reports import scan
from fixwizard.workflow.live import tap_surface_distances_m
from fixwizard.workflow.session import SUFFIX, SamplingSession
from fixwizard.workflow.verify import (
    SUGGESTED_TAPS,
    CheckPoint,
    VerifyResult,
    age_words,
    fixture_of,
    suggest_check_points,
    verdict_lines,
    verify,
)

T = TypeVar("T")
ROBOT_ACTIONS = {key.method for key in (keys.TAP, keys.UNDO, keys.CHECK, keys.HANDS, keys.BACK)}
COLUMNS = ("#", "x mm", "y mm", "z mm", "off surface mm")
CHECKS_FOLDER = "checks"


def checkable_reports(reports_dir: Path) -> dict[str, report.Report]:
    """The newest report with a pose of each fixture in ``reports_dir``, by fixture name. Reads every report (about
    10 ms each): call from a worker thread."""
    return {name: loaded for name, loaded in scan(reports_dir).newest.items() if loaded.pose_to_use() is not None}


class CheckScreen(Screen[None]):
    """Check a calibrated fixture with a few new taps, on the cell's robot with the stored tip calibration ``tip``."""

    BINDINGS: ClassVar[list[BindingType]] = [
        keys.binding(keys.BACK),
        keys.binding(keys.TAP),
        keys.binding(keys.UNDO),
        keys.binding(keys.CHECK),
        keys.binding(keys.HANDS),
        keys.binding(keys.FREEDRIVE, show=False),
    ]
    HELP_TITLE = "check a calibrated fixture"
    HELP_ABOUT = ("Choose the fixture, then tap 6-8 of the suggested points spread over it (freedrive is on; the "
                  "ball 5-10 mm above the surface, then tap) and check: the taps either fit the report's pose, or "
                  "prove the fixture has moved. Esc goes back to the start screen.")

    def __init__(self, cell: Cell, tip: SavedCalibration, reports: dict[str, report.Report]) -> None:
        super().__init__()
        self.cell = cell
        self.tip = tip
        self.calibration = tip.calibration
        self.reports = reports  # checkable_reports of the cell's folder
        self.busy = False
        self.loaded: report.Report | None = None
        self.fixture: Fixture | None = None
        self.points: list[CheckPoint] = []
        self.result: VerifyResult | None = None
        self.journal: SamplingSession | None = None
        self._next_point = 0
        self._cancel = threading.Event()
        self._off_said = False  # the note says freedrive is off while STOPPED

    def compose(self) -> ComposeResult:
        simulated = " (SIMULATED)" if self.cell.simulated else ""
        yield Static(f"Check a calibrated fixture{simulated}: is it still where its report says?", id="check-title",
                     markup=False)
        options = [(f"{name}: {loaded.status}{' SIMULATED' if loaded.simulated else ''}, {loaded.path.name}", name)
                   for name, loaded in self.reports.items()]
        first: dict[str, Any] = {"value": options[0][1]} if options else {}
        yield Select(options, id="check-fixture", prompt="No fixture has a report yet", allow_blank=not options,
                     compact=True, **first)
        yield Static("", id="check-report", markup=False)
        yield Static("", id="check-suggest", markup=False)
        yield TapsTable(id="check-taps")
        yield Static("", id="check-note", markup=False)
        yield Static("", id="check-verdict", classes="-empty", markup=False)
        yield KeyFooter(compact=True)

    def on_mount(self) -> None:
        table = self.query_one(TapsTable)
        for column in COLUMNS:
            table.add_column(column, key=column)
        if not self.reports:
            self._say(f"No report with a pose in {self.cell.reports_dir}: calibrate a fixture first (Esc goes "
                      "back).")
            return
        self._choose(str(self.query_one("#check-fixture", Select).value))
        freedrive_unless_stopped(self, self.action_freedrive, self._say_off)

    def action_freedrive(self) -> None:
        """Freedrive on (a STOP ends it; re-arming calls this)."""
        def on(_: None) -> None:
            if self._off_said:  # it is on now
                self._say("")

        self._run(freedrive_on(self.cell.robot), on)

    def _say_off(self, off: str) -> None:
        """Say that freedrive is off (``off``: how to turn it on), until it is on or the note says more."""
        self._say(off)
        self._off_said = True

    def on_unmount(self) -> None:
        self._cancel.set()
        self._finish_journal()

    # --- choosing the fixture ---

    def on_select_changed(self, event: Select.Changed) -> None:
        if event.select.id == "check-fixture" and event.value in self.reports and self.reports[
                str(event.value)] is not self.loaded:
            self._choose(str(event.value))

    def _choose(self, name: str) -> None:
        """Load the report's mesh (checked against its sha256) and suggest where to tap; earlier taps are of another
        fixture, so they start over."""
        self._cancel.set()
        self._finish_journal()
        self.loaded, self.fixture, self.points, self.result, self._next_point = self.reports[name], None, [], None, 0
        loaded = self.reports[name]
        base_T_cad = loaded.base_T_cad
        assert base_T_cad is not None and loaded.position_bound_m is not None  # only reports with a pose are offered
        age = (dt.datetime.now(dt.UTC) - loaded.created).total_seconds()
        self.query_one("#check-report", Static).update(
            f"Report {loaded.path.name}: {loaded.status}, {age_words(age)}; the fixture is within "
            f"{report.rounded_up_text(loaded.position_bound_m * 1e3, 1)} mm and "
            f"{report.rounded_up_text(loaded.rotation_bound_deg or 0.0, 1)} deg of its pose.")
        self.query_one("#check-suggest", Static).update("Loading the fixture's mesh...")
        self._show_taps()
        self._show_verdict()
        ball_m = self.calibration.ball_diameter_m

        def load() -> tuple[Fixture, list[CheckPoint]]:
            fixture = fixture_of(loaded)
            return fixture, suggest_check_points(fixture, base_T_cad, ball_m)

        def loaded_mesh(found: tuple[Fixture, list[CheckPoint]]) -> None:
            if self.loaded is loaded:
                self.fixture, self.points = found
                self._show_suggestions()

        def failed(error: ShownError) -> None:
            if self.loaded is loaded:
                self.query_one("#check-suggest", Static).update(f"{error_message(error)}")

        in_thread(self, load, loaded_mesh, failed, modal=False)

    def _show_suggestions(self) -> None:
        lines = [f"Tap {SUGGESTED_TAPS[0]}-{SUGGESTED_TAPS[1]} points spread over the fixture, e.g.:"]
        lines += [f"  {number}. {point.where}" for number, point in enumerate(self.points, start=1)]
        lines.append("Then press c to check.")
        self.query_one("#check-suggest", Static).update("\n".join(lines))

    # --- keys ---

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in keys.SIMULATED_ACTIONS and self.cell.hands is None:
            return False
        if action in ROBOT_ACTIONS and self.busy:
            return None
        return True

    def action_tap(self) -> None:
        if self.fixture is None:
            self._say("Choose a fixture whose mesh loads first.")
            return
        cancel = threading.Event()  # STOP sets it: no freedrive after the tap then
        self._run(lambda: self._tap_and_record(cancel), lambda _: self._tapped(cancel.is_set()), cancel=cancel)

    def action_undo(self) -> None:
        if self.journal is None or not self.journal.taps:
            self._say("There is no tap to undo.")
            return
        try:
            self.journal.undo()
        except (FixwizardError, OSError) as error:  # a journal that cannot be written
            self._say(error_message(error))
            return
        self.result = None
        self._say(f"Tap {len(self.journal.taps) + 1} undone.")
        self._show_taps()
        self._show_verdict()

    def action_check(self) -> None:
        taps = self._taps()
        if self.fixture is None or self.loaded is None or not len(taps):
            self._say("Tap at least one point first (6-8 spread over the fixture are best).")
            return
        self._cancel.set()
        cancel = self._cancel = threading.Event()
        loaded, fixture, calibration = self.loaded, self.fixture, self.calibration
        self._say(f"Checking {len(taps)} taps against the report...")

        def work() -> VerifyResult | None:
            try:
                return verify(loaded, fixture, taps, calibration.ball_diameter_m, calibration.sample_bound_m, cancel)
            except SearchCancelled:
                return None

        def done(result: VerifyResult | None) -> None:
            if result is not None and not cancel.is_set() and self.loaded is loaded:
                self.result = result
                self._say("")
                self._show_verdict()

        in_thread(self, work, done, modal=True)

    def action_simulated_hands(self) -> None:
        hands = self.cell.hands
        if not self.points or hands is None:
            self._say("No suggested point yet.")
            return
        point = self.points[self._next_point % len(self.points)]
        self._next_point += 1
        self._run(lambda: hands.near_fixture(point.base_p_ball_m),
                  lambda _: self._say(f"SIMULATED: the operator's hands brought the ball above {point.where}; press "
                                      "t to tap."))

    def action_back(self) -> None:
        """Back to the start screen; asks first while taps are not checked (a check is never resumed)."""
        count = len(self._taps())
        if count and self.result is None:
            def answered(leave: bool | None) -> None:
                if leave:
                    self._back()

            one = count == 1
            taps = f"{count} tap{'' if one else 's'} of this check {'is' if one else 'are'}"
            them = "it" if one else "them"
            self.app.push_screen(Confirm("Leave the check?", f"The {taps} not checked yet, and a check is not "
                                         f"resumed: you would tap again. Stay and press {keys.name(keys.CHECK)} to "
                                         f"check {them} first.", "Leave", "Stay"), answered)
            return
        self._back()

    def _back(self) -> None:
        self._cancel.set()
        self._run(lambda: self.cell.robot.freedrive(False), lambda _: self._leave(),
                  on_failed=lambda _: self._leave())

    def _leave(self) -> None:
        dismiss_when_on_top(self, None)

    # --- robot work and the journal ---

    def _run(self, call: Callable[[], T], on_done: Callable[[T], None],
             on_failed: Callable[[ShownError], None] | None = None, cancel: threading.Event | None = None) -> None:
        """A robot call in a thread with the robot keys disabled meanwhile; errors shown as the app shows them.
        ``cancel``: set by STOP while the call runs."""
        self.busy = True
        self.refresh_bindings()
        if cancel is not None:
            services(self).cancel_on_stop(cancel)

        def finish(callback: Callable, value) -> None:
            if cancel is not None:
                services(self).forget_cancel(cancel)
            self.busy = False
            self.refresh_bindings()
            if callback is not None:
                callback(value)

        in_thread(self, call, lambda value: finish(on_done, value),
                  lambda error: finish(on_failed or (lambda _: self._show_taps()), error), modal=on_failed is None)

    def _tap_and_record(self, cancel: threading.Event) -> None:
        tap_and_record(self.cell.robot, self._record, lambda: len(self._taps()), cancel)

    def _record(self, result: TapResult) -> None:
        self._journal().record_tap(result.base_T_tcp_contact, force={
            "peak_n": result.peak_force_n, "travel_m": result.travel_m, "settle_s": result.settle_s})

    def _journal(self) -> SamplingSession:
        """The check's journal in ``sessions/checks/`` (made at the first tap; not offered for resume)."""
        if self.journal is None:
            loaded, fixture, calibration = self.loaded, self.fixture, self.calibration
            assert loaded is not None and fixture is not None  # taps wait for the mesh
            folder = self.cell.sessions_dir / CHECKS_FOLDER
            path = folder / f"{loaded.name}-{dt.datetime.now():%Y%m%d-%H%M%S-%f}{SUFFIX}"
            self.journal = SamplingSession.create(
                path, {"name": loaded.name, "path": str(fixture.path.resolve()), "units": fixture.units,
                       "sha256": fixture.sha256, "report": str(loaded.path.resolve())},
                {"name": calibration.name, "calibration": str(self.tip.path),
                 "tcp_p_tip_m": calibration.tcp_p_tip_m.tolist(), "ball_diameter_m": calibration.ball_diameter_m,
                 "sample_bound_m": calibration.sample_bound_m}, robot=self.cell.robot_name)
        return self.journal

    def _finish_journal(self) -> None:
        """Close the check's journal with the last verdict (or release it without one)."""
        journal, self.journal = self.journal, None
        if journal is None:
            return
        try:
            if self.result is not None:
                journal.close(verify="moved" if self.result.moved else "consistent",
                              report=str(self.result.report.path))
            else:
                journal.release()
        except (FixwizardError, OSError):  # the taps are saved; only the verdict is not journaled
            journal.release()

    def _tapped(self, stopped: bool) -> None:
        """``stopped``: STOP was pressed as the tap ended (freedrive stayed off)."""
        self.result = None
        if stopped:
            self._say(f"Tap {len(self._taps())} recorded and saved; STOP was pressed as it ended. "
                      f"{FREEDRIVE_STAYS_OFF}")
        else:
            self._say(f"Tap {len(self._taps())} recorded and saved. Tap the next point, or press c to check.")
        self._show_taps()
        self._show_verdict()

    # --- display ---

    def _taps(self) -> np.ndarray:
        return self.journal.base_p_taps if self.journal is not None else np.zeros((0, 3))

    def _show_taps(self) -> None:
        taps = self._taps()
        table = self.query_one(TapsTable)
        table.clear()
        pose = None if self.loaded is None else self.loaded.base_T_cad
        if self.fixture is not None and pose is not None and len(taps):
            distances_mm = 1e3 * tap_surface_distances_m(self.fixture, taps, self.calibration.ball_diameter_m, pose)
        else:
            distances_mm = np.full(len(taps), np.nan)
        for number, (base_p_mm, distance_mm) in enumerate(zip(taps * 1e3, distances_mm, strict=True), start=1):
            table.add_row(Text(str(number), justify="right"),
                          *(Text(f"{value:.1f}", justify="right") for value in base_p_mm),
                          Text("-" if np.isnan(distance_mm) else f"{distance_mm:+.1f}", justify="right"))
        if len(taps):
            table.move_cursor(row=len(taps) - 1)

    def _show_verdict(self) -> None:
        verdict = self.query_one("#check-verdict", Static)
        result = self.result
        verdict.update("" if result is None else "\n".join(verdict_lines(result)))
        verdict.set_class(result is None, "-empty")
        verdict.set_class(result is not None and result.moved, "-moved")
        self.set_class(result is not None, "-checked")  # the suggestions make room for the verdict and the taps

    def _say(self, text: str) -> None:
        self._off_said = False
        self.query_one("#check-note", Static).update(text)
