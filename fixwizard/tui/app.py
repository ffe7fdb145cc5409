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

from textual.actions import ActionParseResult
from textual.app import App
from textual.dom import DOMNode
from textual.reactive import var
from textual.screen import ModalScreen, Screen
from textual.widgets import Footer

from fixwizard.errors import FixwizardError
from fixwizard.robot.base import ProtectiveStop, RobotStatus
from fixwizard.tui import keys
from fixwizard.tui.background import ShownError, run_in_thread
from fixwizard.tui.context import WizardContext
from fixwizard.tui.launch import session_to_resume
from fixwizard.tui.results.screen import ResultsScreen
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.solve.screen import SolveScreen
from fixwizard.tui.start.screen import StartScreen
from fixwizard.tui.start.sessions import resume_refusal, resume_session, start_session
from fixwizard.tui.tip_calibration.steps import calibrate_tip_on_screens
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import ErrorModal, Recovery, ResumeRefused
from fixwizard.tui.widgets.help import HelpScreen, help_text
from fixwizard.tui.widgets.status import StatusBar
from fixwizard.workflow.solver_process import SolverProcess

T = TypeVar("T")
STATUS_INTERVAL_S = 0.5
RESUMED_NOTICE_S = 12.0  # how long "Session resumed: ..." stays up
CSS_FILE = Path(__file__).with_name("wizard.tcss")  # package data: every screen's look


class FixwizardApp(App[None]):
    """The wizard on the context's robot; ``resume`` (a session's path, or "" for the newest unfinished one)
    opens that session straight into sampling, or says on the start screen why it cannot."""

    TITLE = "fixwizard"
    CSS_PATH = CSS_FILE
    ENABLE_COMMAND_PALETTE = False
    BINDINGS = [keys.binding(keys.STOP, priority=True), keys.binding(keys.QUIT, priority=True),
                keys.binding(keys.REARM, priority=True), keys.binding(keys.HELP)]

    robot_status: var[RobotStatus | None] = var(None)
    stopped: var[bool] = var(False)  # after STOP or a protective stop, until the operator re-arms

    def __init__(self, context: WizardContext, resume: str | None = None) -> None:
        super().__init__()
        self.context = context
        self.resume = resume
        self._motion_cancels: set[threading.Event] = set()
        self._polling_status = False
        self._quitting = False  # once set, errors of the steps being stopped are not shown (the app is closing)
        self._left_session: Path | None = None  # the session the operator left sampling from (resumable)

    def on_mount(self) -> None:
        self.screen_change_signal.subscribe(self, self._frame_screen)
        run_in_thread(self, self.context.robot.connect)
        self.set_interval(STATUS_INTERVAL_S, self.refresh_robot_status)
        self._run_flow()

    # --- every screen: status bar, footer, STOP, errors ---

    def _frame_screen(self, screen: Screen) -> None:
        """Give every full screen the status bar and the footer (with the STOP key) unless it has them."""
        if isinstance(screen, ModalScreen):
            return
        if not screen.query(StatusBar):
            screen.mount(StatusBar())
        if not screen.query(Footer):
            screen.mount(Footer(compact=True))

    def refresh_robot_status(self) -> None:
        """Ask the robot for its status in a worker thread (one request at a time); the bars follow."""
        if self._polling_status:
            return
        self._polling_status = True
        self.run_worker(self._poll_status, thread=True, group="status", exit_on_error=False)

    def _poll_status(self) -> None:
        status = None
        try:
            status = self.context.robot.status()
        except FixwizardError:
            pass
        finally:
            self.call_from_thread(self._status_arrived, status)

    def _status_arrived(self, status: RobotStatus | None) -> None:
        self._polling_status = False
        self.robot_status = status
        if status is not None and (status.protective_stop or status.emergency_stop):
            self.stopped = True

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

    def action_stop_robot(self) -> None:
        """STOP: cancel automatic steps and halt the robot's motion now, from any screen; STOPPED until re-armed."""
        for cancel in self._motion_cancels:
            cancel.set()
        run_in_thread(self, self.context.robot.stop, group="stop")
        self.stopped = True
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
                      if self.context.simulated else "unlock it on the teach pendant")
            self.notify(f"The robot is still in a {'protective' if status.protective_stop else 'emergency'} stop: "
                        f"{unlock}, then re-arm.", severity="warning")
            return

        def answered(yes: bool | None) -> None:
            if yes:
                self.stopped = False
                self.notify("Re-armed: the robot keys work again.")

        self.push_screen(Confirm("Re-arm the robot?", "The robot keys (tap, go, the automatic steps) will move the "
                                 "arm again. Is the cell checked and clear of people and objects?", "Re-arm"),
                         answered)

    def action_help(self) -> None:
        """The help of the screen below: its paragraph, its keys (as they stand now) and the global ones."""
        screen = self.screen
        if isinstance(screen, HelpScreen):
            return
        entries, seen = [], set()
        for active in self.active_bindings.values():
            key = keys.key_of(active.binding.action)
            if active.node is not self and key is not None and key not in keys.GLOBAL_KEYS and key not in seen:
                seen.add(key)
                entries.append((key, active.enabled))
        about = getattr(screen, "HELP_ABOUT", "Answer the question, or press Esc to close it.")
        title = getattr(screen, "HELP_TITLE", "this dialog")
        self.push_screen(HelpScreen(title, help_text(about, entries, self.stopped)))

    async def action_quit(self) -> None:
        """Quit; while the robot moves (or an automatic step runs) ask first, then stop it. An automatic step
        stops after its current motion, a solve at once (its process ends), and the session stays resumable."""
        if self.motion_running():
            def answered(yes: bool | None) -> None:
                if yes:
                    self._quit_now(stop=True)

            self.push_screen(Confirm("Quit while the robot moves?", "The robot is moving or an automatic step is "
                                     "running. Quit stops it first; everything recorded is saved and an open "
                                     "session stays resumable.", "Stop and quit"), answered)
            return
        self._quit_now(stop=False)

    def _quit_now(self, stop: bool) -> None:
        self._quitting = True
        for cancel in self._motion_cancels:
            cancel.set()
        SolverProcess.close_all()
        if stop:
            run_in_thread(self, self.context.robot.stop, group="stop")
        self.exit()

    def show_error(self, error: ShownError) -> None:
        """The error's message and next step in a modal; then the recovery the operator chose. Not while quitting:
        stopping a running step may end it with an error, and the app is closing."""
        if self._quitting:
            return
        can_unlock = callable(getattr(self.context.robot, "unlock_protective_stop", None))
        if isinstance(error, ProtectiveStop):
            self.stopped = True
        self.push_screen(ErrorModal(error, self.context.simulated, can_unlock), self._recover)

    def _recover(self, recovery: Recovery | None) -> None:
        robot, hands = self.context.robot, self.context.hands
        if recovery == "reconnect":
            run_in_thread(self, robot.connect, lambda _: self.notify("Connected to the robot again."))
        elif recovery == "unlock" and hands is not None:
            run_in_thread(self, hands.cell.unlock, lambda _: self.notify("SIMULATED: protective stop unlocked."))
        elif recovery == "unlock":
            run_in_thread(self, robot.unlock_protective_stop,
                          lambda _: self.notify("Protective stop unlocked. Check the cell, then retry."))

    async def _in_thread(self, call: Callable[[], T]) -> T | None:
        """Run a blocking call off the event loop from the flow; None (and the error shown) when it fails."""
        try:
            return await asyncio.to_thread(call)
        except (FixwizardError, OSError) as error:
            self.show_error(error)
            return None

    # --- the flow ---

    def _run_flow(self) -> None:
        self.run_worker(self._flow(), group="flow", exclusive=True)

    def notify_resumed(self, opened: str) -> None:
        """Say which session was resumed (and any record of it that was never finished)."""
        self.notify(opened, title="Session resumed", timeout=RESUMED_NOTICE_S, markup=False,
                    severity="warning" if self.context.session and self.context.session.recovered else "information")

    async def _resume(self, requested: str) -> ResumeRefused | None:
        """Resume the session ``--resume`` asked for; the refusal to show on the start screen when it cannot."""
        context = self.context
        try:
            opened = await asyncio.to_thread(lambda: resume_session(context, session_to_resume(context, requested)))
        except (FixwizardError, OSError) as error:
            return resume_refusal(requested, error)
        self.notify_resumed(opened)
        return None

    async def _flow(self) -> None:
        context = self.context
        refusal = await self._resume(self.resume) if self.resume is not None else None
        if context.session is not None:
            await self._sample_until_done()
        while True:
            await self.push_screen_wait(StartScreen(context, refusal, self._left_session))
            refusal = self._left_session = None
            if context.session is None:
                if context.calibration is None:
                    calibrated = await calibrate_tip_on_screens(self, context)
                    await self._in_thread(lambda: context.robot.freedrive(False))
                    if not calibrated:
                        continue
                context.session = await self._in_thread(lambda: start_session(context))
                if context.session is None:
                    continue
            await self._sample_until_done()

    async def _sample_until_done(self) -> None:
        """Sampling, solve and results until the operator is done or leaves sampling; then the session is
        closed (with its report) or released for a later resume."""
        context = self.context
        try:
            while await self.push_screen_wait(SamplingScreen(context)) is True:
                if await self.push_screen_wait(SolveScreen(context)) is None:
                    continue
                if await self.push_screen_wait(ResultsScreen(context)) != "resample":
                    break
                context.report_path = None  # the taps change, so that report no longer describes them
        finally:
            await self._in_thread(self._end_session)

    def _end_session(self) -> None:
        """Close the session naming its report, or release it unfinished; clear what belonged to it."""
        context = self.context
        session, report_path = context.session, context.report_path
        context.session = context.solution = context.report_path = None
        if session is None or session.closed:
            return
        if report_path is not None:
            session.close(report=str(report_path))
        else:
            session.release()
            self._left_session = session.path
