"""The sampling screen: freedrive on, one key taps, the taps in a table with their distance from the surface
under the current estimate, undo, and a live quick solve after each tap. Once the pose is pinned down it
suggests where to tap next (in words and in a top view) and, on request and after confirmation, moves the
robot to hover above that point. Dismisses with True to solve.

Robot calls run in thread workers, the live check (``workflow.live_pipeline``) and "which fixture?" in solver
processes (``workflow.solver_process``), whose answers and progress arrive on the event loop; every tap is
journaled (fsynced) by the session before the table shows it, so an error never loses a recorded tap.
"""

import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.containers import Horizontal
from textual.screen import Screen
from textual.widgets import Static

from fixwizard.errors import FixwizardError
from fixwizard.plots.taps_view import taps_view
from fixwizard.robot.base import ConnectionLost, NoContact, ProtectiveStop, RobotError, TapResult
from fixwizard.solver.solve import MIN_TAPS
from fixwizard.tui import keys
from fixwizard.tui.cell import Cell, Sampling
from fixwizard.tui.dismiss import dismiss_when_on_top
from fixwizard.tui.freedrive import freedrive_on, freedrive_unless_stopped, say_off_once_stopped
from fixwizard.tui.sampling.text import (
    NO_SAFE_HOVER,
    guide_text,
    hover_question,
    identify_text,
    live_details,
    live_text,
    robot_problem_text,
)
from fixwizard.tui.solve.progress_text import progress_words
from fixwizard.tui.start.choices import FixtureChoice, fixture_choices
from fixwizard.tui.tapping import FREEDRIVE_STAYS_OFF, freedrive_again, tap_and_record, unless_stopped
from fixwizard.tui.tip_origin import other_robot_cause
from fixwizard.tui.widgets.confirm import Confirm, ConfirmMove
from fixwizard.tui.widgets.dialog import Dialog
from fixwizard.tui.widgets.doing import TICK_S, Doing, seconds_text
from fixwizard.tui.widgets.errors import error_message
from fixwizard.tui.widgets.key_footer import KeyFooter
from fixwizard.tui.widgets.picture_view import PictureView
from fixwizard.tui.widgets.taps_table import TapsTable
from fixwizard.tui.workers import run_in_solver, services
from fixwizard.workflow.advice import TapAdvice
from fixwizard.workflow.hover import HoverPlan, hover_path
from fixwizard.workflow.live import LiveView
from fixwizard.workflow.session import Tap
from fixwizard.workflow.solver_process import (
    Event,
    Failed,
    Finished,
    Identified,
    IdentifyRequest,
    LiveRequest,
    NextTap,
    Progress,
    SolverProcess,
)

ROBOT_ACTIONS = {key.method for key in (keys.TAP, keys.UNDO, keys.SOLVE, keys.BACK, keys.GO, keys.HANDS, keys.UNLOCK)}
HOVER_SPEED_M_S = 0.1
HOW_TO_TAP = ("Freedrive is on: guide the ball 5-10 mm above the fixture, tool pointing at the surface, then press "
              f"{keys.name(keys.TAP)}. Spread 10-20 taps over several faces.")
COLUMNS = ("#", "x mm", "y mm", "z mm", "off surface mm")
T = TypeVar("T")
ShownError = FixwizardError | OSError


class SamplingScreen(Screen[bool]):
    """Tap the fixture of ``sampling`` (the live check in ``solver``, the fixture's solver process); ``opened``:
    which session this is, in words. Dismisses with True to solve, False to leave (asks; the session stays
    resumable)."""

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
        keys.binding(keys.FREEDRIVE, show=False),
    ]
    HELP_TITLE = "sampling"
    HELP_ABOUT = ("Freedrive is on: bring the ball 5-10 mm above the fixture and tap; each tap is saved at once. "
                  "Spread 10-20 taps over its faces. From 3 taps on, a live check says where to tap next; solve "
                  "once it says unique.")  # three lines: the help of its ten keys fits 80x24

    def __init__(self, cell: Cell, sampling: Sampling, solver: SolverProcess, opened: str = "") -> None:
        super().__init__()
        self.opened = opened  # which session this is, said on the note line at the start
        self.cell = cell
        self.sampling = sampling
        self.session, self.fixture, self.calibration = sampling.session, sampling.fixture, sampling.calibration
        self.solver = solver
        self.busy = False
        self.live: LiveView | None = None
        self.advice: TapAdvice | None = None
        self.hover_plan: HoverPlan | None = None  # the robot's safe way above the advised point, if there is one
        self.live_running = False  # a live check of the current taps is on its way
        self._live_progress: str | None = None  # what it is doing, in words
        self._live_started = 0.0  # time.monotonic() of its start
        self._live_shown = ""  # the live line as last shown
        self._distances_mm = np.zeros(0)  # of the first taps from the surface, under the shown check's estimate
        self._identify: SolverProcess | None = None
        self._spread_index = len(sampling.session.taps)
        self._stopped = False
        self._doing: Doing | None = None  # says what the running robot call does, on the note line

    def compose(self) -> ComposeResult:
        yield Static("", id="title", markup=False)
        yield Static(HOW_TO_TAP, id="help", markup=False)
        with Horizontal(id="middle"):
            yield TapsTable(id="taps")
            yield PictureView(self._draw_top_view, id="top-view")
        yield Static("", id="live", markup=False)
        yield Static("", id="guide", classes="-empty", markup=False)
        yield Static("", id="note", classes="-empty", markup=False)
        yield Static("", id="problem", classes="-empty", markup=False)
        yield KeyFooter(compact=True)

    def on_mount(self) -> None:
        self._doing = Doing(self.query_one("#note", Static))
        self.query_one("#top-view").add_class("-empty")
        table = self.query_one(TapsTable)
        for column in COLUMNS:
            table.add_column(column, key=column)
        self._show_taps()
        self._say(self.opened)
        self.set_interval(TICK_S, self._count_live_seconds)
        self.run_worker(self.solver.start, thread=True, group="solver")  # warm (fixture loaded) by the third tap
        self._start_live_check()
        freedrive_unless_stopped(self, self.action_freedrive, self.query_one("#help", Static).update)
        say_off_once_stopped(self, self.query_one("#help", Static).update)

    def on_unmount(self) -> None:
        self._cancel_live()  # nobody is left to show them; the solver process stays for the solve
        self._end_identify()

    def action_freedrive(self) -> None:
        """Freedrive on again (a STOP ends it; re-arming calls this)."""
        self._run_robot(freedrive_on(self.cell.robot), lambda _: self.query_one("#help", Static).update(
            HOW_TO_TAP))

    # --- keys ---

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in keys.SIMULATED_ACTIONS and self.cell.hands is None:
            return False
        if action == keys.UNLOCK.action and not self._stopped:
            return False
        if action in (keys.GO.action, keys.HANDS.action) and self._stopped:
            return False  # no motion until unlocked: room in the footer for the unlock and re-arm keys at 80 columns
        if action in ROBOT_ACTIONS and self.busy:
            return None
        return True

    def action_tap(self) -> None:
        cancel = threading.Event()  # STOP sets it: no freedrive after the tap then
        self._run_robot(lambda: self._tap_and_record(cancel), lambda tap: self._tap_recorded(tap, cancel.is_set()),
                        doing="Tapping: the robot moves the ball along the tool axis until it touches", cancel=cancel)

    def action_undo(self) -> None:
        """Undo the last change: a drop (the results screen's) is taken back, else the last tap is undone."""
        session = self.session
        try:
            if session.last_dropped is not None:
                restored = session.restore()
                said = (f"Tap {session.taps.index(restored) + 1} counts again: its drop is undone (the journal keeps "
                        "both).")
            elif session.undo() is not None:
                said = f"Tap {len(session.taps) + 1} undone; the journal keeps it, marked undone."
            else:
                self._say("There is no tap to undo.")
                return
        except (FixwizardError, OSError) as error:
            self._problem(error_message(error))
            return
        self._say(said)
        self._taps_changed()

    def action_solve(self) -> None:
        if len(self.session.taps) < MIN_TAPS:
            self._problem(f"Tap at least {MIN_TAPS} points before solving; 10-20 over several faces give tight "
                          "bounds.")
            return
        self._cancel_live()
        self._run_robot(lambda: self.cell.robot.freedrive(False), lambda _: dismiss_when_on_top(self, True),
                        on_failed=lambda _: dismiss_when_on_top(self, True),
                        doing="Turning freedrive off, then solving")

    def action_back(self) -> None:
        """Back to the start screen, after asking: the session stays resumable there (and is selected)."""
        count = len(self.session.taps)

        def answered(yes: bool | None) -> None:
            if yes:
                self._cancel_live()
                self._run_robot(lambda: self.cell.robot.freedrive(False), lambda _: dismiss_when_on_top(self, False),
                                on_failed=lambda _: dismiss_when_on_top(self, False), doing="Turning freedrive off")

        self.app.push_screen(Confirm("Leave sampling?", f"Back to the start screen. The session "
                                     f"{self.session.path.name} with its {count} tap"
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
                services(self).refuse_motion()
            elif move:
                cancel = threading.Event()  # STOP sets it: no move of the three starts after a STOP

                def hovering(_: None) -> None:
                    if cancel.is_set():
                        self._say(f"The ball hovers above the suggested point; STOP was pressed as it got there. "
                                  f"{FREEDRIVE_STAYS_OFF}")
                    else:
                        self._say("The ball hovers above the suggested point (freedrive is on again): press "
                                  f"{keys.name(keys.TAP)} to tap it.")

                self._run_robot(lambda: self._move_above(plan, cancel), hovering,
                                doing="Moving above the suggested point", cancel=cancel)
            else:  # Cancel (the focused button: Enter), n or Esc
                self._say(f"Not moved. Press {keys.name(keys.GO)} to move above the suggested point, or guide the "
                          "ball there by hand.")

        self.app.push_screen(ConfirmMove("Move the robot?", hover_question(plan, self.cell.simulated)), answered)

    def action_identify(self) -> None:
        """Check the taps against every fixture the wizard offers (in a solver process of its own) and show which
        fit."""
        base_p_taps = self.session.base_p_taps
        if len(base_p_taps) < MIN_TAPS:
            self._problem(f"Tap at least {MIN_TAPS} points before asking which fixture this is.")
            return
        self._end_identify()
        solver = self._identify = SolverProcess(None)
        choices = fixture_choices(self.cell.fixtures_dir)
        calibration = self.calibration
        self._say(f"Checking the {len(base_p_taps)} taps against {len(choices)} fixtures...")
        run_in_solver(self, solver, IdentifyRequest(base_p_taps, [(choice.path, choice.units) for choice in choices],
                                                    calibration.ball_diameter_m, calibration.sample_bound_m),
                      lambda event: self._identify_event(event, choices))

    def _identify_event(self, event: Event, choices: list[FixtureChoice]) -> None:
        if isinstance(event, Progress):
            self._say(f"Checking the taps against {len(choices)} fixtures: {progress_words(event)}...")
        elif isinstance(event, Identified):
            self._say("")
            self.app.push_screen(Dialog("Which fixture is this?",
                                        identify_text(choices, event.verdicts, self.fixture.path)),
                                 lambda _: self._end_identify())
        elif isinstance(event, Failed):
            self._problem(f"Which fixture: {event.message}")
            self._end_identify()

    def _end_identify(self) -> None:
        if self._identify is not None:
            self._identify.close()
            self._identify = None

    def action_details(self) -> None:
        """The live check's technical figures in a dialog."""
        self.app.push_screen(Dialog("Live check: details", live_details(self.live)))

    def action_simulated_hands(self) -> None:
        index = self._spread_index
        self._spread_index += 1
        hands = self.cell.simulated_hands()
        self._run_robot(lambda: hands.near_spread_point(index),
                        lambda _: self._say("SIMULATED: the operator's hands brought the ball above the fixture; "
                                            f"press {keys.name(keys.TAP)} to tap."),
                        doing="SIMULATED: the operator's hands bring the ball above the fixture")

    def action_simulated_unlock(self) -> None:
        self.cell.simulated_hands().cell.unlock()
        self._stopped = False
        self.refresh_bindings()
        self._say("SIMULATED: the protective stop is unlocked, as on the teach pendant. Check the cell and re-arm "
                  f"({keys.name(keys.REARM)}), then press {keys.name(keys.TAP)} to tap again.")

    # --- robot work in a thread ---

    def _run_robot(self, call: Callable[[], T], on_done: Callable[[T], object],
                   on_failed: Callable[[ShownError], object] | None = None, doing: str | None = None,
                   cancel: threading.Event | None = None) -> None:
        """Run a robot call in a thread worker with the robot keys disabled; errors are shown on this screen
        unless ``on_failed`` takes them. ``doing``: what it does, said at once on the note line with the seconds
        it takes; ``cancel``: set by STOP while the call runs."""
        self.busy = True
        self.refresh_bindings()
        if doing is not None and self._doing is not None:
            self._clear_problem()
            self._doing.start(doing)
        if cancel is not None:
            services(self).cancel_on_stop(cancel)
        self._robot_call(call, on_done, on_failed or self._robot_failed, cancel)

    @work(thread=True, group="robot")
    def _robot_call(self, call: Callable[[], T], on_done: Callable[[T], object],
                    on_failed: Callable[[ShownError], object], cancel: threading.Event | None) -> None:
        try:
            result = call()
        except (FixwizardError, OSError) as error:
            self.app.call_from_thread(self._robot_finished, on_failed, error, cancel)
        else:
            self.app.call_from_thread(self._robot_finished, on_done, result, cancel)

    def _robot_finished(self, callback: Callable[[Any], object], result: object,
                        cancel: threading.Event | None) -> None:
        if cancel is not None:
            services(self).forget_cancel(cancel)
        self.busy = False
        if self._doing is not None:
            self._doing.done()
        if self.is_attached:
            self.refresh_bindings()
            callback(result)

    def _tap_and_record(self, cancel: threading.Event) -> Tap:
        return tap_and_record(self.cell.robot, self._record, lambda: len(self.session.taps), cancel)

    def _record(self, result: TapResult) -> Tap:
        return self.session.record_tap(
            result.base_T_tcp_contact,
            force={"peak_n": result.peak_force_n, "travel_m": result.travel_m, "settle_s": result.settle_s})

    def _move_above(self, plan: HoverPlan, cancel: threading.Event) -> None:
        """Freedrive off, the three moves of ``hover_path`` (none after ``cancel`` is set), freedrive on again;
        after a stop or a fault freedrive stays off."""
        robot, calibration = self.cell.robot, self.calibration
        robot.freedrive(False)
        try:
            for base_T_tcp in hover_path(plan, calibration.tcp_p_tip_m, robot.base_T_tcp()):
                robot.move_linear(base_T_tcp, HOVER_SPEED_M_S,
                                  stop_mark=unless_stopped(robot, cancel, "move above the suggested point"))
        except RobotError as error:
            error.add_note(FREEDRIVE_STAYS_OFF)
            raise
        freedrive_again(robot, cancel)

    def _tap_recorded(self, tap: Tap, stopped: bool) -> None:
        """``stopped``: STOP was pressed as the tap ended (freedrive stayed off)."""
        self._stopped = False
        count = len(self.session.taps)
        if stopped:
            self._say(f"Tap {count} recorded and saved; STOP was pressed as it ended. {FREEDRIVE_STAYS_OFF}")
        else:
            self._say(f"Tap {count} recorded and saved. Move to the next point and press {keys.name(keys.TAP)}.")
        self._taps_changed()

    def _robot_failed(self, error: ShownError) -> None:
        if getattr(error, "recorded_tap", None) is not None:
            self._taps_changed()
        self._stopped = self._stopped or isinstance(error, ProtectiveStop)
        self.refresh_bindings()
        text = robot_problem_text(error_message(error), len(self.session.taps), self.session.path)
        if isinstance(error, NoContact) and self.cell.hands is not None:
            text += (f"\nSIMULATED: press {keys.name(keys.HANDS)} and the simulated hands bring the ball above the "
                     "fixture.")
        self._problem(text)
        if isinstance(error, ConnectionLost) and self._link_known_lost():
            services(self).show_error(error)  # Reconnect: the lost link's dialog was shown, and may have been closed

    def _link_known_lost(self) -> bool:
        """Whether the app's status says the link is down: then it has shown the lost link's dialog (with Reconnect)
        already; a link lost during this call it is about to show."""
        status = services(self).robot_status
        return status is None or not status.connected

    # --- the live check ---

    def _start_live_check(self) -> None:
        """Supersede the running live check and start one for the current taps (from 3 taps on) in the fixture's
        solver process, which goes on from its previous check."""
        base_p_taps = self.session.base_p_taps
        self.advice = self.hover_plan = None  # they were for the taps before
        self.live_running = len(base_p_taps) >= MIN_TAPS
        self._live_progress = None
        self._live_started = time.monotonic()
        if not self.live_running:
            self._cancel_live()
            self._show_live()
            return
        calibration = self.calibration
        self._show_live()
        run_in_solver(self, self.solver,
                      LiveRequest(base_p_taps, calibration.ball_diameter_m, calibration.sample_bound_m),
                      self._live_event)

    def _cancel_live(self) -> None:
        self.solver.cancel()
        self.live_running = False

    def _live_event(self, event: Event) -> None:
        """One answer of the live check: progress, a check, the next tap, or its end."""
        if isinstance(event, Progress):
            self._live_progress = progress_words(event)
            self._show_live_text()
            return
        if isinstance(event, LiveView):
            self.live, self._live_progress = event, None
            self._distances_mm = np.zeros(0) if event.distances_m is None else event.distances_m * 1e3
            self._show_taps()
        elif isinstance(event, NextTap):
            self.advice, self.hover_plan = event.advice, event.plan
        elif isinstance(event, Failed):
            self.live_running = False
            self._problem(f"Live check: {event.message}")
        elif isinstance(event, Finished):
            self.live_running = False
        self._show_live()

    # --- display ---

    def _taps_changed(self) -> None:
        if self.live is not None and not self.live.is_of_first(self.session.base_p_taps):
            self.live, self._distances_mm = None, np.zeros(0)  # it counted a tap now gone: it no longer holds
        self._show_taps()
        self._start_live_check()

    def _show_taps(self) -> None:
        taps = self.session.base_p_taps
        self.query_one("#title", Static).update(
            f"Sampling{' (SIMULATED)' if self.cell.simulated else ''}: {len(taps)} "
            f"tap{'s' if len(taps) != 1 else ''} of {self.fixture.path.name}")
        self._distances_mm = self._distances_mm[:len(taps)]  # an undone tap's slot may take a new tap
        distances_mm = np.full(len(taps), np.nan)
        distances_mm[:len(self._distances_mm)] = self._distances_mm
        table = self.query_one(TapsTable)
        table.clear()
        for number, (base_p_mm, distance_mm) in enumerate(zip(taps * 1e3, distances_mm, strict=True), start=1):
            table.add_row(Text(str(number), justify="right"),
                          *(Text(f"{value:.1f}", justify="right") for value in base_p_mm),
                          Text("-" if np.isnan(distance_mm) else f"{distance_mm:+.1f}", justify="right"))
        if len(taps):
            table.move_cursor(row=len(taps) - 1)

    def _count_live_seconds(self) -> None:
        if self.live_running:
            self._show_live_text()

    def _show_live_text(self) -> None:
        tap_count = len(self.session.taps)
        progress = None
        if self.live_running:
            shown_these = self.live is not None and self.live.tap_count == tap_count
            words = self._live_progress or ("going on from what it found" if shown_these else "starting")
            progress = words + seconds_text(time.monotonic() - self._live_started)
        text = live_text(self.live, tap_count, progress, other_robot_cause(self.calibration, self.cell.robot_name))
        if text != self._live_shown:  # the count looks often, the screen changes twice a second
            self._live_shown = text
            self.query_one("#live", Static).update(text)

    def _show_live(self) -> None:
        self._show_live_text()
        guide = self.query_one("#guide", Static)
        text = guide_text(self.advice, self.hover_plan) if self.advice is not None else ""
        guide.update(text)
        guide.set_class(not text, "-empty")
        top_view = self.query_one("#top-view", PictureView)
        top_view.set_class(self.live is None or self.live.estimate_base_T_cad is None, "-empty")
        top_view.redraw()

    def _draw_top_view(self, width: int, height: int):
        """The taps over the fixture at the live estimate, and the suggested next tap."""
        estimate = self.live.estimate_base_T_cad if self.live is not None else None
        target = self.advice.base_p_point_m if self.advice is not None else None
        return taps_view(self.session.base_p_taps, width, height, self.fixture.mesh, estimate,
                         base_p_target=target)

    def _clear_problem(self) -> None:
        problem = self.query_one("#problem", Static)
        problem.update("")
        problem.add_class("-empty")
        self.remove_class("-problem")

    def _say(self, text: str) -> None:
        """What just happened, in the note line; clears any problem shown."""
        self._clear_problem()
        note = self.query_one("#note", Static)
        note.update(text)
        note.set_class(not text, "-empty")

    def _problem(self, text: str) -> None:
        problem = self.query_one("#problem", Static)
        problem.update(text)
        problem.remove_class("-empty")
        self.add_class("-problem")  # the next-tap advice makes room for it, until it is cleared
        note = self.query_one("#note", Static)
        note.update("")
        note.add_class("-empty")  # the table shrinks under the problem and keeps its newest tap in view itself
