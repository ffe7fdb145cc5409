"""Blocking work (robot calls, files, fits) off the event loop: a thread worker whose result or readable
error comes back to the event loop; solver requests to a solver process whose answers come back to it too.
Errors the operator can act on become an error modal; anything else is a bug and ends the app as Textual does."""

from collections.abc import Callable
from typing import TypeVar

from textual.dom import DOMNode
from textual.worker import Worker

from fixwizard.errors import FixwizardError
from fixwizard.workflow.solver_process import Event, Request, SolverProcess

T = TypeVar("T")
ShownError = FixwizardError | OSError


def run_in_thread(node: DOMNode, call: Callable[[], T], on_done: Callable[[T], None] | None = None,
                  on_failed: Callable[[ShownError], None] | None = None, group: str = "robot",
                  modal: bool = True) -> Worker[None]:
    """Run ``call`` in a thread worker owned by ``node``. Afterwards, on the event loop: ``on_done(result)``,
    or for a ``FixwizardError``/``OSError`` ``on_failed(error)`` and (when ``modal``) the app's error modal;
    then the status bar refreshes. Callbacks are skipped when ``node`` has left the screen meanwhile."""
    app = node.app

    def finish(callback: Callable[..., None] | None, *args) -> None:
        if callback is not None and node.is_attached:
            callback(*args)
        app.refresh_robot_status()

    def fail(error: ShownError) -> None:
        finish(on_failed, error)
        if modal:
            app.show_error(error)

    def work() -> None:
        try:
            result = call()
        except (FixwizardError, OSError) as error:
            app.call_from_thread(fail, error)
        else:
            app.call_from_thread(finish, on_done, result)

    return node.run_worker(work, thread=True, group=group, exit_on_error=True)


def run_in_solver(node: DOMNode, solver: SolverProcess, request: Request,
                  on_event: Callable[[Event], None]) -> Callable[[], bool]:
    """Send ``request`` to ``solver``; each answer is handed to ``on_event`` on the event loop while ``node`` is on
    the screen and the request is the solver's latest. Returns whether it still is (False once superseded)."""
    app = node.app
    request_id = 0

    def current() -> bool:
        return solver.latest_request == request_id

    def on_loop(event: Event) -> None:
        if node.is_attached and current():
            on_event(event)

    def arrived(event: Event) -> None:
        try:
            app.call_from_thread(on_loop, event)
        except RuntimeError:
            pass  # the app has ended: nobody is left to show it

    request_id = solver.submit(request, arrived)
    return current
