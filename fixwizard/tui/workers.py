"""Blocking work (robot calls, files, fits) off the event loop in Textual thread workers, whose result or readable
error comes back to the event loop; solver requests to a solver process whose answers come back to it too; and
the app services the screens call (error modal, status refresh, STOP). Errors the operator can act on become an
error modal; anything else is a bug and ends the app as Textual does."""

import threading
from collections.abc import Callable
from typing import Protocol, TypeVar, cast

from textual import work
from textual.css.query import NoMatches
from textual.dom import DOMNode
from textual.worker import get_current_worker

from fixwizard.errors import FixwizardError
from fixwizard.robot.base import RobotStatus
from fixwizard.tui.cell import Cell
from fixwizard.workflow.solver_process import Event, Request, SolverProcess

T = TypeVar("T")
ShownError = FixwizardError | OSError


class WizardServices(Protocol):
    """What the screens ask of the wizard app (``FixwizardApp``; test hosts give the few a screen uses)."""

    cell: Cell
    robot_status: RobotStatus | None
    stopped: bool

    def show_error(self, error: ShownError, reconnect: bool = False) -> None: ...

    def refresh_robot_status(self) -> None: ...

    def refuse_motion(self) -> None: ...

    def cancel_on_stop(self, cancel: threading.Event) -> None: ...

    def forget_cancel(self, cancel: threading.Event) -> None: ...

    def use_cell(self, cell: Cell) -> None: ...


def services(node: DOMNode) -> WizardServices:
    """The app of ``node`` as the services it offers the screens."""
    return cast(WizardServices, node.app)


@work(thread=True, group="blocking", exit_on_error=True)
def in_thread(node: DOMNode, call: Callable[[], T], on_done: Callable[[T], None] | None = None,
              on_failed: Callable[[ShownError], None] | None = None, modal: bool = True,
              offer_reconnect: Callable[[], bool] | None = None) -> None:
    """Run ``call`` in a thread worker owned by ``node``. Afterwards, on the event loop: ``on_done(result)``,
    or for a ``FixwizardError``/``OSError`` ``on_failed(error)`` and (when ``modal``) the app's error modal, with
    Reconnect where ``offer_reconnect()`` says so (a connect that failed); then the status bar refreshes.
    Callbacks are skipped when ``node`` has left the screen meanwhile (its workers are cancelled then)."""
    worker, app = get_current_worker(), services(node)

    def left() -> bool:
        return worker.is_cancelled or not node.is_attached

    def done(result: T) -> None:
        if on_done is not None and not left():
            on_done(result)
        app.refresh_robot_status()

    def failed(error: ShownError) -> None:
        if on_failed is not None and not left():
            on_failed(error)
        app.refresh_robot_status()
        if modal:
            app.show_error(error, offer_reconnect is not None and offer_reconnect())

    try:
        result = call()
    except (FixwizardError, OSError) as error:
        node.app.call_from_thread(failed, error)
    else:
        node.app.call_from_thread(done, result)


def run_in_solver(node: DOMNode, solver: SolverProcess, request: Request,
                  on_event: Callable[[Event], None]) -> Callable[[], bool]:
    """Send ``request`` to ``solver``; each answer is handed to ``on_event`` on the event loop while ``node`` is on
    the screen and the request is the solver's latest. Returns whether it still is (False once superseded)."""
    app = node.app
    request_id = 0

    def current() -> bool:
        return solver.latest_request == request_id

    def on_loop(event: Event) -> None:
        if not (node.is_attached and node.app.is_running and current()):
            return  # the screen or the app is gone, or a newer request answers
        try:
            on_event(event)
        except NoMatches:
            if node.screen in node.app.screen_stack:
                raise  # a widget missing from a screen the app holds is a bug
            # the screen is being taken down (off the stack, its widgets go before it is detached): nothing to show

    def arrived(event: Event) -> None:
        try:
            app.call_from_thread(on_loop, event)
        except RuntimeError:
            pass  # the app has ended: nobody is left to show it

    request_id = solver.submit(request, arrived)
    return current
