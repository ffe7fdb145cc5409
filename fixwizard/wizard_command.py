"""The ``fixwizard`` command without a sub-command: the wizard in this terminal. Its own module, with light imports,
so that it says it is starting before the seconds of loading the solver and the screens."""

import argparse
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from fixwizard.errors import InputError
from fixwizard.exit_codes import EXIT_OK


@contextmanager
def _dots_while(what: str, every_s: float = 0.3) -> Iterator[None]:
    """Say ``what`` on the terminal, with a dot every ``every_s`` seconds while the block runs (no blank wait)."""
    print(what, end="", flush=True)
    done = threading.Event()

    def dots() -> None:
        while not done.wait(every_s):
            print(".", end="", flush=True)

    thread = threading.Thread(target=dots, name="fixwizard-start-dots", daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()
        print(flush=True)


def wizard_command(args: argparse.Namespace) -> int:
    if not (sys.stdin.isatty() and sys.stdout.isatty()):
        raise InputError("the wizard needs an interactive terminal (its input or output is not one here); run "
                         "fixwizard in a terminal or over SSH, or use a command such as `fixwizard solve` in scripts "
                         "(see fixwizard --help)")
    with _dots_while("Starting the wizard: loading the fixtures and the solver"):  # a second or two of imports
        from fixwizard.fixture import warm_up_distance_queries
        from fixwizard.tui.app import FixwizardApp
        from fixwizard.tui.heap import freeze_long_lived_objects
        from fixwizard.tui.launch import simulated_cell, ur_cell

        warm_up_distance_queries()  # not at the first simulated tap, while the keys wait

        app = FixwizardApp(ur_cell(args.robot) if args.robot else simulated_cell(args.seed), args.resume)
        freeze_long_lived_objects()
    app.run()
    app.cell.robot.close()  # the robot chosen last (the start screen can switch it)
    return EXIT_OK
