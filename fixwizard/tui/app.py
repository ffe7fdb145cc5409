"""The wizard app: Start -> (new tip calibration | stored one) -> Sampling -> Solve -> Results, with the
status bar and footer on every screen, the STOP key on every screen, robot status polled in a worker
thread and every ``FixwizardError`` shown as a readable message with the next step."""

import asyncio
import threading
from collections.abc import Callable
from typing import TypeVar

from textual.app import App
from textual.binding import Binding
from textual.reactive import var
from textual.screen import ModalScreen, Screen
from textual.widgets import Footer

from fixwizard.errors import FixwizardError
from fixwizard.robot.base import RobotStatus
from fixwizard.tui.background import ShownError, run_in_thread
from fixwizard.tui.context import WizardContext
from fixwizard.tui.errors import ErrorModal, Recovery, ResumeRefused
from fixwizard.tui.launch import session_to_resume
from fixwizard.tui.results import ResultsScreen
from fixwizard.tui.sampling import SamplingScreen
from fixwizard.tui.sessions import resume_refusal, resume_session, start_session
from fixwizard.tui.solve_screen import SolveScreen
from fixwizard.tui.start import StartScreen
from fixwizard.tui.status import STOP_KEYS, StatusBar
from fixwizard.tui.tip_calibration import calibrate_tip_on_screens
from fixwizard.workflow.solver_process import SolverProcess

T = TypeVar("T")
STATUS_INTERVAL_S = 0.5
RESUMED_NOTICE_S = 12.0  # how long "Session resumed: ..." stays up


class FixwizardApp(App[None]):
    """The wizard on the context's robot; ``resume`` (a session's path, or "" for the newest unfinished one)
    opens that session straight into sampling, or says on the start screen why it cannot."""

    TITLE = "fixwizard"
    ENABLE_COMMAND_PALETTE = False
    BINDINGS = [Binding(STOP_KEYS, "stop_robot", "STOP", priority=True, key_display="F12"),
                Binding("ctrl+q", "quit", "Quit", priority=True)]

    robot_status: var[RobotStatus | None] = var(None)

    def __init__(self, context: WizardContext, resume: str | None = None) -> None:
        super().__init__()
        self.context = context
        self.resume = resume
        self._motion_cancels: set[threading.Event] = set()
        self._polling_status = False

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

    def cancel_on_stop(self, cancel: threading.Event) -> None:
        """Set ``cancel`` too when the operator presses STOP (automatic steps stop between two motions)."""
        self._motion_cancels.add(cancel)

    def forget_cancel(self, cancel: threading.Event) -> None:
        self._motion_cancels.discard(cancel)

    def action_stop_robot(self) -> None:
        """STOP: cancel automatic steps and halt the robot's motion now, from any screen."""
        for cancel in self._motion_cancels:
            cancel.set()
        run_in_thread(self, self.context.robot.stop, group="stop")
        self.notify("STOP sent: the robot halts. Check the cell before going on.", severity="warning")

    async def action_quit(self) -> None:
        """Quit; an automatic step stops after its current motion, a solve at once (its process ends), and the
        session stays resumable."""
        for cancel in self._motion_cancels:
            cancel.set()
        SolverProcess.close_all()
        self.exit()

    def show_error(self, error: ShownError) -> None:
        """The error's message and next step in a modal; then the recovery the operator chose."""
        can_unlock = callable(getattr(self.context.robot, "unlock_protective_stop", None))
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
            await self.push_screen_wait(StartScreen(context, refusal))
            refusal = None
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
