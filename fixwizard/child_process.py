"""Starting a child process from inside the wizard (the UR link, the solver): what Textual's app changes about the
parent that a child's start must undo."""

import sys
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def real_stderr() -> Iterator[None]:
    """The process's own standard error for the duration: starting a process hands its file descriptor on, and the
    wizard's Textual app replaces ``sys.stderr`` by a capture without one (fd -1: 'bad value(s) in fds_to_keep')."""
    captured = sys.stderr
    sys.stderr = sys.__stderr__
    try:
        yield
    finally:
        sys.stderr = captured
