"""Long work that Ctrl+C stops at once: the work runs in a thread and the main thread waits for it, so the
interrupt reaches Python within a tenth of a second even while compiled code (which releases the interpreter)
runs for longer."""

import os
import sys
import threading
from collections.abc import Callable
from typing import TypeVar

from fixwizard.exit_codes import EXIT_CANCELLED

Result = TypeVar("Result")
POLL_S = 0.05
GRACE_S = 0.5  # how long the work gets to notice the cancel before the process leaves without it


def run_interruptibly(work: Callable[[threading.Event], Result]) -> Result:
    """``work(cancel)`` in a thread; its result, or its exception re-raised here. On Ctrl+C the cancel event is
    set and ``KeyboardInterrupt`` raised once the work stopped; work still running after ``GRACE_S`` (compiled
    code cannot be interrupted) is left behind: the process exits with ``EXIT_CANCELLED`` there and then."""
    cancel = threading.Event()
    outcome: dict[str, object] = {}

    def run() -> None:
        try:
            outcome["result"] = work(cancel)
        except BaseException as error:  # handed to the waiting thread as it is
            outcome["error"] = error

    thread = threading.Thread(target=run, name="fixwizard-work", daemon=True)
    thread.start()
    try:
        while thread.is_alive():
            thread.join(POLL_S)
    except KeyboardInterrupt:
        cancel.set()
        thread.join(GRACE_S)
        if thread.is_alive():
            print("fixwizard: cancelled; nothing was written", file=sys.stderr, flush=True)
            sys.stdout.flush()
            os._exit(EXIT_CANCELLED)
        raise
    if "error" in outcome:
        raise outcome["error"]  # type: ignore[misc]
    return outcome["result"]  # type: ignore[return-value]
