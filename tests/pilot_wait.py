"""Waiting in Pilot tests: worker threads report back through the event loop, so let the app run."""

from collections.abc import Callable

from textual.app import App
from textual.pilot import Pilot
from textual.screen import Screen

TIMEOUT_S = 60.0


async def until(pilot: Pilot, condition: Callable[[], bool], timeout_s: float = TIMEOUT_S) -> None:
    """Let the app run until ``condition()`` holds; fail after ``timeout_s`` seconds, saying what the app showed."""
    for _ in range(int(timeout_s / 0.02)):
        if condition():
            return
        await pilot.pause(0.02)
    raise AssertionError(f"the app did not get there in time; it showed {shown(pilot)}")


def shown(pilot: Pilot) -> str:
    """The app's screens (bottom to top) and its last notifications: what a failed wait found."""
    app = pilot.app
    screens = " > ".join(type(screen).__name__ for screen in app.screen_stack)
    notes = [str(note.message) for note in list(app._notifications)[-3:]]
    return f"screens {screens}; last notifications {notes}"


def dialog_shown(app: App, kind: type[Screen]) -> bool:
    """The top screen is a ``kind`` dialog with its message mounted (the message sits in a scroll, which mounts its
    content after the screen is pushed and the title is in)."""
    return isinstance(app.screen, kind) and bool(app.screen.query("#dialog-message"))
