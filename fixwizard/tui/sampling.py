"""The sampling screen: freedrive on, one key taps, the taps in a table with their distance from the surface
under the current estimate, undo, and a live quick solve after each tap. Once the pose is pinned down it
suggests where to tap next (in words and in a top view) and, on request and after confirmation, moves the
robot to hover above that point. Dismisses with True to solve.

Robot calls and the quick solve run in thread workers; every tap is journaled (fsynced) by the session
before the table shows it, so an error never loses a recorded tap.
"""

import threading
from collections.abc import Callable
from typing import TypeVar

import numpy as np
from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal
from textual.screen import Screen
from textual.widgets import DataTable, Footer, Static

from fixwizard.errors import FixwizardError
from fixwizard.plots.taps_view import taps_view
from fixwizard.robot.base import NoContact, ProtectiveStop, RobotError, TapResult
from fixwizard.solver.search import SearchCancelled
from fixwizard.solver.solve import MIN_TAPS
from fixwizard.tui import keys
from fixwizard.tui.choices import fixture_choices
from fixwizard.tui.confirm import Confirm, ConfirmMove
from fixwizard.tui.context import WizardContext
from fixwizard.tui.dialog import Dialog
from fixwizard.tui.errors import error_message
from fixwizard.tui.picture_view import PictureView
from fixwizard.tui.sampling_text import (
    NO_SAFE_HOVER,
    guide_text,
    hover_question,
    identify_text,
    live_details,
    live_text,
    robot_problem_text,
)
from fixwizard.workflow.advice import TapAdvice
from fixwizard.workflow.hover import (
    HoverPlan,
    hover_path,
    next_tap_and_plan,
    plan_hover,
)
from fixwizard.workflow.identify import identify
from fixwizard.workflow.live import (
    LiveCheck,
    quick_check,
    refine_check,
    tap_surface_distances_m,
)
from fixwizard.workflow.session import Tap

ROBOT_ACTIONS = {key.method for key in (keys.TAP, keys.UNDO, keys.SOLVE, keys.BACK, keys.GO, keys.HANDS, keys.UNLOCK)}
HOVER_SPEED_M_S = 0.1
COLUMNS = ("#", "x mm", "y mm", "z mm", "off surface mm")
T = TypeVar("T")
ShownError = FixwizardError | OSError


class SamplingScreen(Screen[bool]):
    """Tap the fixture; dismisses with True to solve, False to leave (asks; the session stays resumable)."""

    BINDINGS = [
        keys.binding(keys.BACK),
        keys.binding(keys.TAP),
        keys.binding(keys.UNDO),
        keys.binding(keys.GO),
        keys.binding(keys.SOLVE),
        keys.binding(keys.HANDS),
        keys.binding(keys.UNLOCK),
        keys.binding(keys.IDENTIFY, show=False),
        keys.binding(keys.DETAILS, show=False),
    ]
    HELP_TITLE = "sampling"
    HELP_ABOUT = ("Freedrive is on: guide the ball 5-10 mm above the fixture, the tool pointing at the surface, and "
                  "tap; every tap is saved at once. Spread 10-20 taps over several faces. After 3 taps a live check "
                  "says how well the pose is pinned down and suggests where to tap next (the robot can go above it "
                  "for you). Solve when the check says unique. Esc goes back to the start screen; the session "
                  "stays there to resume.")

    def __init__(self, context: WizardContext) -> None:
        super().__init__()
        self.context = context
        self.busy = False
        self.live: LiveCheck | None = None
        self.advice: TapAdvice | None = None
        self.hover_plan: HoverPlan | None = None  # the robot's safe way above the advised point, if there is one
        self._live_cancel = threading.Event()
        self._identify_cancel = threading.Event()
        self._spread_index = len(context.session.taps)
        self._stopped = False

    def compose(self) -> ComposeResult:
        yield Static("", id="title", markup=False)
        yield Static("Freedrive is on: guide the ball 5-10 mm above the fixture, tool pointing at the surface, "
                     "then press t. Spread 10-20 taps over several faces.", id="help", markup=False)
        with Horizontal(id="middle"):
            yield DataTable(id="taps", cursor_type="row", zebra_stripes=True)
            yield PictureView(self._draw_top_view, id="top-view")
        yield Static("", id="live", markup=False)
        yield Static("", id="guide", classes="-empty", markup=False)
        yield Static("", id="note", classes="-empty", markup=False)
        yield Static("", id="problem", classes="-empty", markup=False)
        yield Footer(compact=True)

    def on_mount(self) -> None:
        self.query_one("#top-view").add_class("-empty")
        table = self.query_one(DataTable)
        for column in COLUMNS:
            table.add_column(column, key=column)
        self._show_taps()
        self._start_live_check()
        self._run_robot(lambda: self.context.robot.freedrive(True), lambda _: None)

    def on_unmount(self) -> None:
        self._live_cancel.set()  # nobody is left to show them
        self._identify_cancel.set()

    # --- keys ---

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in keys.SIMULATED_ACTIONS and self.context.hands is None:
            return False
        if action == keys.UNLOCK.action and not self._stopped:
            return False
        if action in ROBOT_ACTIONS and self.busy:
            return None
        return True

    def action_tap(self) -> None:
        self._run_robot(self._tap_and_record, self._tap_recorded)

    def action_undo(self) -> None:
        try:
            tap = self.context.session.undo()
        except (FixwizardError, OSError) as error:
            self._problem(error_message(error))
            return
        if tap is None:
            self._say("There is no tap to undo.")
            return
        self._say(f"Tap {len(self.context.session.taps) + 1} undone; the journal keeps it, marked undone.")
        self._taps_changed()

    def action_solve(self) -> None:
        if len(self.context.session.taps) < MIN_TAPS:
            self._problem(f"Tap at least {MIN_TAPS} points before solving; 10-20 over several faces give tight "
                          "bounds.")
            return
        self._live_cancel.set()
        self._run_robot(lambda: self.context.robot.freedrive(False), lambda _: self.dismiss(True),
                        on_failed=lambda _: self.dismiss(True))

    def action_back(self) -> None:
        """Back to the start screen, after asking: the session stays resumable there (and is selected)."""
        count = len(self.context.session.taps)

        def answered(yes: bool | None) -> None:
            if yes:
                self._live_cancel.set()
                self._run_robot(lambda: self.context.robot.freedrive(False), lambda _: self.dismiss(False),
                                on_failed=lambda _: self.dismiss(False))

        self.app.push_screen(Confirm("Leave sampling?", f"Back to the start screen. The session "
                                     f"{self.context.session.path.name} with its {count} tap"
                                     f"{'' if count == 1 else 's'} stays saved; it is selected there to resume.",
                                     "Leave", "Stay"), answered)

    def action_go(self) -> None:
        advice, plan = self.advice, self.hover_plan
        if advice is None:
            self._say("No suggestion yet: once the live check pins the pose down, it suggests where to tap next.")
            return
        if plan is None:
            self._say(NO_SAFE_HOVER)
            return

        def answered(move: bool | None) -> None:
            if move and getattr(self.app, "stopped", False):
                self.app.refuse_motion()
            elif move:
                self._run_robot(lambda: self._move_above(plan), lambda _: self._say(
                    "The ball hovers above the suggested point (freedrive is on again): press "
                    f"{keys.name(keys.TAP)} to tap it."))

        self.app.push_screen(ConfirmMove("Move the robot?", hover_question(plan, self.context.simulated)), answered)

    def action_identify(self) -> None:
        """Check the taps against every fixture the wizard offers (in a worker) and show which fit."""
        base_p_taps = self.context.session.base_p_taps
        if len(base_p_taps) < MIN_TAPS:
            self._problem(f"Tap at least {MIN_TAPS} points before asking which fixture this is.")
            return
        self._identify_cancel.set()
        cancel = self._identify_cancel = threading.Event()
        choices = fixture_choices(self.context.fixtures_dir)
        calibration, chosen = self.context.calibration, self.context.fixture.path
        self._say(f"Checking the {len(base_p_taps)} taps against {len(choices)} fixtures...")

        def work() -> None:
            try:
                verdicts = identify(base_p_taps, [(choice.path, choice.units) for choice in choices],
                                    calibration.ball_diameter_m, calibration.sample_bound_m, cancel=cancel)
            except SearchCancelled:
                return
            except FixwizardError as error:
                self.app.call_from_thread(self._problem, error_message(error))
                return
            self.app.call_from_thread(self._identified, cancel, identify_text(choices, verdicts, chosen))

        self.run_worker(work, thread=True, group="identify", exclusive=True)

    def _identified(self, cancel: threading.Event, text: str) -> None:
        if not cancel.is_set() and self.is_attached:
            self._say("")
            self.app.push_screen(Dialog("Which fixture is this?", text))

    def action_details(self) -> None:
        """The live check's technical figures in a dialog."""
        self.app.push_screen(Dialog("Live check: details", live_details(self.live)))

    def action_simulated_hands(self) -> None:
        index = self._spread_index
        self._spread_index += 1
        self._run_robot(lambda: self.context.hands.near_spread_point(index),
                        lambda _: self._say("SIMULATED: the operator's hands brought the ball above the fixture; "
                                            f"press {keys.name(keys.TAP)} to tap."))

    def action_simulated_unlock(self) -> None:
        self.context.hands.cell.unlock()
        self._stopped = False
        self.refresh_bindings()
        self._say("SIMULATED: the protective stop is unlocked, as on the teach pendant. Check the cell and re-arm "
                  f"({keys.name(keys.REARM)}), then press {keys.name(keys.TAP)} to tap again.")

    # --- robot work in a thread ---

    def _run_robot(self, call: Callable[[], T], on_done: Callable[[T], None],
                   on_failed: Callable[[ShownError], None] | None = None) -> None:
        """Run a robot call in a thread worker with the robot keys disabled; errors are shown on this screen
        unless ``on_failed`` takes them."""
        self.busy = True
        self.refresh_bindings()

        def finish(callback: Callable, result) -> None:
            self.busy = False
            if self.is_attached:
                self.refresh_bindings()
                callback(result)

        def work() -> None:
            try:
                result = call()
            except (FixwizardError, OSError) as error:
                self.app.call_from_thread(finish, on_failed or self._robot_failed, error)
            else:
                self.app.call_from_thread(finish, on_done, result)

        self.run_worker(work, thread=True, group="robot")

    def _tap_and_record(self) -> Tap:
        """Freedrive off, tap, journal the tap, freedrive on again (also after a failed tap)."""
        robot = self.context.robot
        try:
            robot.freedrive(False)
            try:
                result: TapResult = robot.tap()
            except RobotError as error:
                recorded = getattr(error, "tap_result", None)
                if recorded is None:
                    raise
                # the contact was recorded before the fault (while retracting, or the link went down): keep it
                tap = self._record(recorded)
                error.add_note(f"The contact was saved as tap {len(self.context.session.taps)}.")
                error.recorded_tap = tap
                raise
            return self._record(result)
        finally:
            try:
                robot.freedrive(True)
            except RobotError:
                pass  # the tap's own error (or the next robot call) tells the operator

    def _record(self, result: TapResult) -> Tap:
        return self.context.session.record_tap(
            result.base_T_tcp_contact,
            force={"peak_n": result.peak_force_n, "travel_m": result.travel_m, "settle_s": result.settle_s})

    def _move_above(self, plan: HoverPlan) -> None:
        """Freedrive off, the three moves of ``hover_path``, freedrive on again (also after a failed move)."""
        robot, calibration = self.context.robot, self.context.calibration
        try:
            robot.freedrive(False)
            for base_T_tcp in hover_path(plan, calibration.tcp_p_tip_m, robot.base_T_tcp()):
                robot.move_linear(base_T_tcp, HOVER_SPEED_M_S)
        finally:
            try:
                robot.freedrive(True)
            except RobotError:
                pass  # the move's own error (or the next robot call) tells the operator

    def _tap_recorded(self, tap: Tap) -> None:
        self._stopped = False
        count = len(self.context.session.taps)
        self._say(f"Tap {count} recorded and saved. Move to the next point and press {keys.name(keys.TAP)}.")
        self._taps_changed()

    def _robot_failed(self, error: ShownError) -> None:
        if getattr(error, "recorded_tap", None) is not None:
            self._taps_changed()
        self._stopped = self._stopped or isinstance(error, ProtectiveStop)
        self.refresh_bindings()
        text = robot_problem_text(error_message(error), len(self.context.session.taps), self.context.session.path)
        if isinstance(error, NoContact) and self.context.hands is not None:
            text += (f"\nSIMULATED: press {keys.name(keys.HANDS)} and the simulated hands bring the ball above the "
                     "fixture.")
        self._problem(text)

    # --- the live check ---

    def _start_live_check(self) -> None:
        """Cancel the running quick solve and start one for the current taps (from 3 taps on)."""
        self._live_cancel.set()
        cancel = self._live_cancel = threading.Event()
        calibration, fixture = self.context.calibration, self.context.fixture
        base_p_taps = self.context.session.base_p_taps
        previous = self.live
        self.advice = self.hover_plan = None  # they were for the taps before
        self._show_live(running=len(base_p_taps) >= MIN_TAPS)
        if len(base_p_taps) < MIN_TAPS:
            return

        def work() -> None:
            try:
                check = quick_check(fixture, base_p_taps, calibration.ball_diameter_m, calibration.sample_bound_m,
                                    cancel, previous=previous)
            except SearchCancelled:
                return
            except FixwizardError as error:
                self.app.call_from_thread(self._live_failed, cancel, error)
                return
            self.app.call_from_thread(self._live_done, cancel, check)
            if check.estimate_base_T_cad is None or cancel.is_set():
                return
            advice, plan = next_tap_and_plan(fixture, check.solution, calibration.sample_bound_m,
                                             calibration.ball_diameter_m / 2.0)
            self.app.call_from_thread(self._advice_done, cancel, advice, plan)
            try:
                refined = refine_check(fixture, check, cancel)
            except SearchCancelled:
                return
            self.app.call_from_thread(self._live_done, cancel, refined)
            if advice is not None and plan is None:  # the refined bounds may leave room for a safe way down
                plan = plan_hover(advice, fixture, [mode.bounds for mode in refined.solution.modes],
                                  calibration.ball_diameter_m / 2.0)
                self.app.call_from_thread(self._advice_done, cancel, advice, plan)

        self.run_worker(work, thread=True, group="live", exclusive=True)

    def _live_done(self, cancel: threading.Event, check: LiveCheck) -> None:
        if cancel.is_set() or not self.is_attached:
            return
        self.live = check
        self._show_taps()
        self._show_live(running=False)

    def _advice_done(self, cancel: threading.Event, advice: TapAdvice | None, plan: HoverPlan | None) -> None:
        if cancel.is_set() or not self.is_attached:
            return
        self.advice, self.hover_plan = advice, plan
        self._show_live(running=False)

    def _live_failed(self, cancel: threading.Event, error: FixwizardError) -> None:
        if not cancel.is_set() and self.is_attached:
            self.query_one("#live", Static).update(f"Live check: {error_message(error)}")

    # --- display ---

    def _taps_changed(self) -> None:
        self._show_taps()
        self._start_live_check()

    def _show_taps(self) -> None:
        taps = self.context.session.base_p_taps
        self.query_one("#title", Static).update(
            f"Sampling{' (SIMULATED)' if self.context.simulated else ''}: {len(taps)} "
            f"tap{'s' if len(taps) != 1 else ''} of {self.context.fixture.path.name}")
        estimate = self.live.estimate_base_T_cad if self.live is not None else None
        distances_mm = (tap_surface_distances_m(self.context.fixture, taps, self.context.calibration.ball_diameter_m,
                                                estimate) * 1e3 if estimate is not None and len(taps)
                        else np.full(len(taps), np.nan))
        table = self.query_one(DataTable)
        table.clear()
        for number, (base_p_mm, distance_mm) in enumerate(zip(taps * 1e3, distances_mm, strict=True), start=1):
            table.add_row(Text(str(number), justify="right"),
                          *(Text(f"{value:.1f}", justify="right") for value in base_p_mm),
                          Text("-" if np.isnan(distance_mm) else f"{distance_mm:+.1f}", justify="right"))
        if len(taps):
            table.move_cursor(row=len(taps) - 1)

    def _show_live(self, running: bool) -> None:
        self.query_one("#live", Static).update(live_text(self.live, len(self.context.session.taps), running))
        guide = self.query_one("#guide", Static)
        text = guide_text(self.advice, self.hover_plan) if self.advice is not None and not running else ""
        guide.update(text)
        guide.set_class(not text, "-empty")
        top_view = self.query_one("#top-view", PictureView)
        top_view.set_class(self.live is None or self.live.estimate_base_T_cad is None, "-empty")
        top_view.redraw()

    def _draw_top_view(self, width: int, height: int):
        """The taps over the fixture at the live estimate, and the suggested next tap."""
        estimate = self.live.estimate_base_T_cad if self.live is not None else None
        target = self.advice.base_p_point_m if self.advice is not None else None
        return taps_view(self.context.session.base_p_taps, width, height, self.context.fixture.mesh, estimate,
                         base_p_target=target)

    def _say(self, text: str) -> None:
        """What just happened, in the note line; clears any problem shown."""
        problem = self.query_one("#problem", Static)
        problem.update("")
        problem.add_class("-empty")
        note = self.query_one("#note", Static)
        note.update(text)
        note.set_class(not text, "-empty")

    def _problem(self, text: str) -> None:
        problem = self.query_one("#problem", Static)
        problem.update(text)
        problem.remove_class("-empty")
        note = self.query_one("#note", Static)
        note.update("")
        note.add_class("-empty")
        table = self.query_one(DataTable)
        table.call_after_refresh(table.scroll_end, animate=False)  # the latest taps stay in view
