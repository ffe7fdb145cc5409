"""Waiting in Pilot tests: worker threads report back through the event loop, so let the app run."""

from collections.abc import Callable

from textual.pilot import Pilot

TIMEOUT_S = 60.0


async def until(pilot: Pilot, condition: Callable[[], bool], timeout_s: float = TIMEOUT_S) -> None:
    """Let the app run until ``condition()`` holds; fail after ``timeout_s`` seconds."""
    for _ in range(int(timeout_s / 0.02)):
        if condition():
            return
        await pilot.pause(0.02)
    raise AssertionError("the app did not get there in time")
