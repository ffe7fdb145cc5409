"""The wizard app: Start -> (new tip calibration | stored one) -> Sampling -> Solve -> Results, with the
status bar and footer on every screen, the STOP key on every screen, robot status polled in a worker
thread and every ``FixwizardError`` shown as a readable message with the next step.

After STOP or a protective stop the wizard is STOPPED: the status bar says so and every key that moves the robot
(``keys.MOTION_ACTIONS``) is refused with a message until the operator re-arms (``keys.REARM``, confirmed).
``?`` shows the help of the current screen; quitting while the robot moves asks first. The look of every screen
is in ``wizard.tcss``."""

import asyncio
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TypeVar

from textual import events, work
from textual.actions import ActionParseResult
from textual.app import App
from textual.dom import DOMNode
from textual.reactive import var
from textual.screen import ModalScreen, Screen
from textual.widgets import Footer
from textual.worker import WorkerFailed

from fixwizard.errors import FixwizardError
from fixwizard.robot.base import ConnectionLost, ProtectiveStop, Robot, RobotError, RobotStatus
from fixwizard.tui import keys
from fixwizard.tui.cell import Cell, NewSession, Resumed, Sampling, SavedCalibration
from fixwizard.tui.launch import session_to_resume
from fixwizard.tui.results.screen import Done, ResultsScreen
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.solve.screen import SolveScreen
from fixwizard.tui.start.screen import StartScreen
from fixwizard.tui.start.sessions import (
    drop_to_take_back,
    resume_refusal,
    resume_session,
    start_session,
    started_text,
)
from fixwizard.tui.tip_calibration.steps import calibrate_tip_on_screens, open_tip_calibration
from fixwizard.tui.toasts import keep_toast_delays_positive
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import ErrorModal, Recovery, ResumeRefused
from fixwizard.tui.widgets.help import HelpScreen, help_text, keys_of
from fixwizard.tui.widgets.key_footer import KeyFooter
from fixwizard.tui.widgets.opening import Opening
from fixwizard.tui.widgets.status import StatusBar
from fixwizard.tui.widgets.too_small import TooSmall, too_small
from fixwizard.tui.workers import ShownError, in_thread
from fixwizard.workflow.solver_process import SolverProcess

T = TypeVar("T")
STATUS_INTERVAL_S = 0.5
DIALOG_POLL_S = 0.05  # how often the flow looks whether a dialog over the opening screen is answered
REARM_QUESTION = "Re-arm the robot?"
CSS_FILE = Path(__file__).with_name("wizard.tcss")  # package data: every screen's look


class FixwizardApp(App[None]):
    """The wizard on ``cell`` (``self.cell``: the start screen can switch the robot); ``resume`` (a session's
    path, or "" for the newest unfinished one) opens that session straight into sampling, or says on the start
    screen why it cannot; ``sampling`` (an open session) starts the wizard in sampling instead. The flow (``_flow``)
    hands each screen what the one before returned and owns the fixture's solver process."""

    TITLE = "fixwizard"
    CSS_PATH = CSS_FILE
    ENABLE_COMMAND_PALETTE = False
    BINDINGS = [keys.binding(keys.STOP, priority=True), keys.binding(keys.QUIT, priority=True),
                keys.binding(keys.REARM, priority=True), keys.binding(keys.HELP)]

    robot_status: var[RobotStatus | None] = var(None)
    stopped: var[bool] = var(False)  # after STOP or a protective stop, until the operator re-arms

    def __init__(self, cell: Cell, resume: str | None = None, sampling: Sampling | None = None) -> None:
        super().__init__()
        keep_toast_delays_positive()  # a toast of an expired notification froze Textual's event loop
        self.cell = cell
        self.resume = resume
        self._first_sampling = sampling
        self._solver: SolverProcess | None = None  # the solver process of the session's fixture
        self._motion_cancels: set[threading.Event] = set()
        self._polling_status = False
        self._quitting = False  # once set, errors of the steps being stopped are not shown (the app is closing)
        self._left_session: Path | None = None  # the session the operator left sampling from (resumable)
        self._link_up = False  # the robot's latest status said connected
        self._reconnects = 0  # Reconnects the operator asked for: a lost link's error from before one is old news
        self._stops = 0  # STOP presses, so that a re-arm question asked before one re-arms nothing

    def get_default_screen(self) -> Screen:
        return Opening(resuming=self.resume is not None)

    def on_mount(self) -> None:
        self.screen_change_signal.subscribe(self, self._frame_screen)
        if self.resume is not None:  # the session's mesh can take seconds to load: not a blank terminal meanwhile
            self._frame_screen(self.screen)
        self._connect()
        self.set_interval(STATUS_INTERVAL_S, self.refresh_robot_status)
        self._run_flow()

    # --- every screen: status bar, footer, STOP, errors ---

    def _frame_screen(self, screen: Screen) -> None:
        """Give every full screen the status bar and the footer (with the STOP key) unless it has them; cover it
        while the terminal is too small."""
        self.call_later(self._fit_terminal)
        if isinstance(screen, ModalScreen):
            return
        if not screen.query(StatusBar):
            screen.mount(StatusBar())
        if not screen.query(Footer):
            screen.mount(KeyFooter(compact=True))

    def on_resize(self, event: events.Resize) -> None:
        self.call_later(self._fit_terminal)

    def _fit_terminal(self) -> None:
        """A step's screen on top in a terminal too small for it: cover it with ``TooSmall``; ``TooSmall`` on top in
        a terminal large enough: close it. A dialog on top stays as it is (dialogs scroll what does not fit)."""
        screen = self.screen
        if isinstance(screen, TooSmall):
            if not too_small(self.size):
                screen.dismiss()
        elif not isinstance(screen, ModalScreen) and too_small(self.size):
            self.push_screen(TooSmall(getattr(screen, "HELP_TITLE", "starting")))

    def step_screen(self) -> Screen:
        """The step's screen: the topmost full screen, under any dialog or ``TooSmall``."""
        return next(screen for screen in reversed(self.screen_stack) if not isinstance(screen, ModalScreen | TooSmall))

    def refresh_robot_status(self) -> None:
        """Ask the robot for its status in a worker thread (one request at a time); the bars follow."""
        if self._polling_status:
            return
        self._polling_status = True
        self._poll_status()

    @work(thread=True, group="status", exit_on_error=False)
    def _poll_status(self) -> None:
        robot, status = self.cell.robot, None
        try:
            status = robot.status()
        except FixwizardError:
            pass
        finally:
            self.call_from_thread(self._status_arrived, robot, status)

    def _status_arrived(self, robot: Robot, status: RobotStatus | None) -> None:
        self._polling_status = False
        if robot is not self.cell.robot:  # asked before the start screen switched the robot
            return
        self.robot_status = status
        if status is not None and (status.protective_stop or status.emergency_stop):
            self.stopped = True
        link_was_up, self._link_up = self._link_up, status is not None and status.connected
        if link_was_up and not self._link_up:
            self._announce_lost_link(robot, self._reconnects)

    @work(thread=True, group="link", exit_on_error=False)
    def _announce_lost_link(self, robot: Robot, reconnects: int) -> None:
        """The link dropped while nothing asked the robot for anything (the operator guiding the arm, say): the
        robot's own error for it, with Reconnect. Asking for the pose gives it once the arm is sure to stand (a UR
        arm's link waits for its watchdog first); a link that came back meanwhile raises nothing. ``reconnects``:
        the count when the link was seen to go; once the operator has pressed Reconnect since (on a failed motion's
        error that came first), the answer is about the link that went or the one still connecting: not shown."""
        try:
            robot.base_T_tcp()
        except RobotError as error:
            self.call_from_thread(self._lost_link_answered, error, reconnects)

    def _lost_link_answered(self, error: RobotError, reconnects: int) -> None:
        if reconnects == self._reconnects:
            self.show_error(error)

    def watch_stopped(self) -> None:
        self.refresh_bindings()

    def motion_running(self) -> bool:
        """Whether the robot may be moving: an automatic step runs or a screen waits on a robot call."""
        return bool(self._motion_cancels) or any(getattr(screen, "busy", False) for screen in self.screen_stack)

    def cancel_on_stop(self, cancel: threading.Event) -> None:
        """Set ``cancel`` too when the operator presses STOP (automatic steps stop between two motions)."""
        self._motion_cancels.add(cancel)

    def forget_cancel(self, cancel: threading.Event) -> None:
        self._motion_cancels.discard(cancel)

    def use_cell(self, cell: Cell) -> None:
        """The start screen switched the robot: status, STOP and the next steps use ``cell``'s."""
        self.cell = cell
        self._link_up = False

    def action_stop_robot(self) -> None:
        """STOP: cancel automatic steps and halt the robot's motion now, from any screen; STOPPED until re-armed.
        The cancels are set before the robot's stop: a worker that found its cancel unset had read the robot's STOP
        count before, so the robot refuses the motion it then asks for (``tapping.unless_stopped``)."""
        for cancel in self._motion_cancels:
            cancel.set()
        in_thread(self, self.cell.robot.stop)
        self.stopped = True
        self._stops += 1  # a re-arm question asked before is answered about the cell before this STOP
        if isinstance(self.screen, Confirm) and self.screen.title_text == REARM_QUESTION:
            self.screen.dismiss(False)
        self.notify(f"STOP sent: the robot halts. Check the cell, then re-arm with {keys.name(keys.REARM)}.",
                    severity="warning")

    async def run_action(self, action: "str | ActionParseResult", default_namespace: DOMNode | None = None,
                         namespaces: Mapping[str, DOMNode] | None = None) -> bool:
        """Every action, as Textual runs it; while STOPPED a key that moves the robot is refused, with why."""
        if self.stopped and isinstance(action, str) and \
                action.split("(", 1)[0].rsplit(".", 1)[-1] in keys.MOTION_ACTIONS:
            self.refuse_motion()
            return True
        return await super().run_action(action, default_namespace, namespaces)

    def refuse_motion(self) -> None:
        self.notify(f"STOPPED: the robot does not move until you re-arm. Check the cell, then press "
                    f"{keys.name(keys.REARM)}.", severity="error")

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action == keys.REARM.action:
            return self.stopped
        return True

    def action_rearm(self) -> None:
        """Allow motion again after a STOP, once the operator confirms the cell is clear (refused while the
        robot itself is still in a protective or emergency stop)."""
        status = self.robot_status
        if status is not None and (status.protective_stop or status.emergency_stop):
            unlock = (f"press {keys.name(keys.UNLOCK)} on the sampling screen or use the error's unlock button"
                      if self.cell.simulated else "unlock it on the teach pendant")
            self.notify(f"The robot is still in a {'protective' if status.protective_stop else 'emergency'} stop: "
                        f"{unlock}, then re-arm.", severity="warning")
            return

        stops = self._stops

        def answered(yes: bool | None) -> None:
            if yes and stops != self._stops:  # under another dialog (the help) when that STOP came
                self.notify(f"A STOP came after the re-arm question: check the cell, then re-arm again with "
                            f"{keys.name(keys.REARM)}.", severity="warning")
            elif yes:
                self.stopped = False
                freedrive = self._freedrive_by_hand()  # a STOP ended that freedrive
                if freedrive is not None:
                    freedrive()
                self.notify("Re-armed: the robot keys work again" + (" and freedrive is on." if freedrive else "."))

        self._ask_once(Confirm(REARM_QUESTION, "The robot keys (tap, go, the automatic steps) will move the arm "
                               "again. Is the cell checked and clear of people and objects?", "Re-arm"), answered)

    def _freedrive_by_hand(self) -> Callable[[], None] | None:
        """The step screen's freedrive action where the operator guides the arm by hand on it now (its freedrive is
        on until a STOP or a lost link ends it), else None: a screen with ``action_freedrive`` guides by hand unless
        its ``guided_by_hand()`` says it does not now (the automatic taps: only after f)."""
        screen = self.step_screen()
        freedrive: Callable[[], None] | None = getattr(screen, "action_freedrive", None)
        guided_by_hand: Callable[[], bool] = getattr(screen, "guided_by_hand", lambda: True)
        return freedrive if freedrive is not None and guided_by_hand() else None

    def _ask_once(self, question: Confirm, answered: Callable[[bool | None], None]) -> None:
        """Ask ``question`` unless it is asked already (a key pressed twice asked twice, one dialog over the other)."""
        if not any(isinstance(screen, Confirm) and screen.title_text == question.title_text
                   for screen in self.screen_stack):
            self.push_screen(question, answered)

    def action_help(self) -> None:
        """The help of the screen below: its paragraph, its keys (as they stand now) and the global ones."""
        screen = self.screen
        if isinstance(screen, HelpScreen):
            return
        about = getattr(screen, "HELP_ABOUT", "Answer the question, or press Esc to close it.")
        title = getattr(screen, "HELP_TITLE", "this dialog")
        self.push_screen(HelpScreen(title, help_text(about, keys_of(screen), self.stopped)))

    def action_help_quit(self) -> None:
        """Ctrl+C (Textual's: it copies in a field and quits nothing): which keys stop the robot and quit, in the
        wizard's words (Textual's said "Press ctrl+q to quit the app")."""
        self.notify(f"Ctrl+C stops nothing here: {keys.name(keys.STOP)} stops the robot, {keys.name(keys.QUIT)} "
                    "quits the wizard.", title="Stop or quit?", severity="warning")

    async def action_quit(self) -> None:
        """Quit; while the robot moves (or an automatic step runs) ask first, then stop it. An automatic step
        stops after its current motion, a solve at once (its process ends), and the session stays resumable."""
        if self.motion_running():
            def answered(yes: bool | None) -> None:
                if yes:
                    self._quit_now(stop=True)

            self._ask_once(Confirm("Quit while the robot moves?", "The robot is moving or an automatic step is "
                                   "running. Quit stops it first; everything recorded is saved and an open session "
                                   "stays resumable.", "Stop and quit"), answered)
            return
        self._quit_now(stop=False)

    def _quit_now(self, stop: bool) -> None:
        self._quitting = True
        for cancel in self._motion_cancels:
            cancel.set()
        SolverProcess.close_all()
        if stop:
            in_thread(self, self.cell.robot.stop)
        self.exit()

    def show_error(self, error: ShownError, reconnect: bool = False) -> None:
        """The error's message and next step in a modal (with Reconnect for a lost link, or when ``reconnect``); then
        the recovery the operator chose. Not while quitting: stopping a running step may end it with an error, and
        the app is closing; not a lost link while one is shown (a step that failed on it and the status that saw it
        go)."""
        if isinstance(error, ConnectionLost) and any(
                isinstance(screen, ErrorModal) and isinstance(screen.error, ConnectionLost)
                for screen in self.screen_stack):
            return
        modal = self._error_modal(error, reconnect)
        if modal is not None:
            self.push_screen(modal, self._recover)

    async def _error_answered(self, error: ShownError) -> None:
        """``show_error`` for the flow: it goes on once the operator closed the error (a screen the flow shows next
        would otherwise cover it)."""
        modal = self._error_modal(error)
        if modal is not None:
            recovery: Recovery = await self.push_screen_wait(modal)
            self._recover(recovery)

    def _error_modal(self, error: ShownError, reconnect: bool = False) -> ErrorModal | None:
        if self._quitting:
            return None
        can_unlock = callable(getattr(self.cell.robot, "unlock_protective_stop", None))
        if isinstance(error, ProtectiveStop):
            self.stopped = True
        return ErrorModal(error, self.cell.simulated, can_unlock, reconnect)

    def _connect(self, on_done: Callable[[None], None] | None = None) -> None:
        """Connect the robot (in a thread); a connect that fails leaves it unconnected whatever the cause (local
        control, no program started), so its error offers Reconnect."""
        in_thread(self, self.cell.robot.connect, on_done, offer_reconnect=lambda: True)

    def _recover(self, recovery: Recovery | None) -> None:
        hands = self.cell.hands
        if recovery == "reconnect":
            self._reconnects += 1
            self._connect(lambda _: self._reconnected())
        elif recovery == "unlock" and hands is not None:
            in_thread(self, hands.cell.unlock, lambda _: self.notify("SIMULATED: protective stop unlocked."))
        elif recovery == "unlock":
            unlock: Callable[[], None] | None = getattr(self.cell.robot, "unlock_protective_stop", None)
            if unlock is not None:
                in_thread(self, unlock, lambda _: self.notify("Protective stop unlocked. Check the cell, then retry."))

    def _reconnected(self) -> None:
        """Say so; where the operator guides the arm by hand, that freedrive is off until turned on (the lost link
        ended it, and after a fault nothing starts by itself)."""
        by_hand = self._freedrive_by_hand() is not None
        self.notify("Connected to the robot again" + (f": freedrive is off, press {keys.name(keys.FREEDRIVE)} to "
                                                       "guide the arm by hand." if by_hand else "."))

    # --- blocking steps of the flow ---

    @work(thread=True, group="flow-step", exit_on_error=False)
    def _flow_step(self, call: Callable[[], T]) -> T:
        return call()

    async def _off_loop(self, call: Callable[[], T]) -> T:
        """Run a blocking call of the flow in a thread worker and await it; its error is raised here."""
        try:
            return await self._flow_step(call).wait()
        except WorkerFailed as failed:
            raise failed.error from None

    async def _step_or_error(self, call: Callable[[], T]) -> T | None:
        """A blocking call of the flow off the event loop; None (and the error shown) when it fails."""
        try:
            return await self._off_loop(call)
        except (FixwizardError, OSError) as error:
            await self._error_answered(error)
            return None

    # --- the flow ---

    def _run_flow(self) -> None:
        self.run_worker(self._flow(), group="flow", exclusive=True)

    async def _resume(self, requested: str) -> Resumed | ResumeRefused:
        """Resume the session ``--resume`` asked for; the refusal to show on the start screen when it cannot."""
        cell = self.cell
        try:
            resumed = await self._off_loop(lambda: resume_session(cell, session_to_resume(cell, requested)))
        except (FixwizardError, OSError) as error:
            return resume_refusal(requested, error)
        return resumed

    async def _flow(self) -> None:
        refusal = None
        if self._first_sampling is not None:
            await self._sample_until_done(self._first_sampling)
        elif self.resume is not None:
            resumed = await self._resume(self.resume)
            await self._clear_opening()
            if isinstance(resumed, Resumed):
                await self._sample_until_done(resumed.sampling, resumed.opened)
            else:
                refusal = resumed
        while True:
            await self._clear_opening()
            choice = await self.push_screen_wait(StartScreen(self.cell, refusal, self._left_session))
            refusal = self._left_session = None
            started = (choice.sampling, choice.opened) if isinstance(choice, Resumed) else \
                await self._new_session(choice)
            if started is not None:
                await self._sample_until_done(*started)

    async def _clear_opening(self) -> None:
        """Close a help left open over the opening screen (``?`` while ``--resume`` loads), and wait until a question
        asked or an error shown over it meanwhile (the re-arm after F12) is answered: the step's screen that comes
        now would cover them, a help to show again, explaining nothing, once that screen is gone, a question that
        could not be asked again (it is asked once) and so the robot keys off for good."""
        while isinstance(self.screen, ModalScreen):
            if isinstance(self.screen, HelpScreen):
                self.pop_screen()
            else:
                await asyncio.sleep(DIALOG_POLL_S)

    async def _new_session(self, choice: NewSession) -> tuple[Sampling, str] | None:
        """A new session for the chosen fixture, after a new tip calibration if none was chosen, and what was
        started in words; None when the operator went back from the calibration or the session could not be
        created (the error shown)."""
        tip: SavedCalibration | None = choice.tip
        if tip is None:
            cell, unfinished = self.cell, choice.unfinished_tip
            workflow = await self._step_or_error(lambda: open_tip_calibration(cell, unfinished))
            if workflow is None:
                return None
            tip = await calibrate_tip_on_screens(self, cell, workflow)
            await self._step_or_error(lambda: cell.robot.freedrive(False))
            saved_to = None if tip is None else tip.path
            await self._step_or_error(lambda: workflow.close(saved_to))
            if tip is None:
                return None
        cell, fixture, saved = self.cell, choice.fixture, tip
        session = await self._step_or_error(lambda: start_session(cell, fixture, saved))
        if session is None:
            return None
        return Sampling(session, fixture, saved), started_text(session, saved, calibrated_now=choice.tip is None)

    def _solver_for(self, sampling: Sampling) -> SolverProcess:
        """The solver process holding the session's fixture: started on first use, replaced when the fixture
        changes."""
        if self._solver is not None and self._solver.fixture is not sampling.fixture:
            self._solver.close()
            self._solver = None
        if self._solver is None:
            self._solver = SolverProcess(sampling.fixture)
        return self._solver

    async def _sample_until_done(self, sampling: Sampling, opened: str = "") -> None:
        """Sampling (its first screen saying ``opened``: which session, with what), solve and results until the
        operator is done or leaves sampling; then the session is closed (with its report) or released for a
        later resume."""
        report_path: Path | None = None
        try:
            while await self.push_screen_wait(SamplingScreen(self.cell, sampling, self._solver_for(sampling),
                                                             opened)) is True:
                solution = await self.push_screen_wait(SolveScreen(self.cell, sampling, self._solver_for(sampling)))
                if solution is not None:
                    outcome = await self.push_screen_wait(ResultsScreen(self.cell, sampling, solution))
                    if isinstance(outcome, Done):
                        report_path = outcome.report_path
                        break
                # back to sampling (the taps may change: a report written no longer describes them), saying which
                # drop u takes back if the last change was one (the results' d, or a drop before this solve)
                opened = drop_to_take_back(sampling.session)
        finally:
            await self._step_or_error(lambda: self._end_session(sampling, report_path))

    def _end_session(self, sampling: Sampling, report_path: Path | None) -> None:
        """Close the session naming its report, or release it unfinished (also when its closing record could not be
        saved: held on, it could not be resumed in this wizard), selected to resume on the start screen."""
        session = sampling.session
        if session.closed:
            return
        try:
            if report_path is not None:
                session.close(report=str(report_path))
        except (FixwizardError, OSError) as error:
            error.add_note("The session stays unfinished: it is selected on the start screen to resume.")
            raise
        finally:
            if not session.closed:
                session.release()
                self._left_session = session.path
