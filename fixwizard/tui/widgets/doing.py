"""What a running robot call is doing, said the moment its key is pressed and counted in seconds while it runs:
no key goes unanswered while the arm moves (a real tap takes seconds), and no wait passes without a sign of
progress. The screen writes the outcome once the call is done."""

import time

from textual.timer import Timer
from textual.widgets import Static

TICK_S = 0.1  # how often the count is looked at: a new half second shows within this of its start


COUNT_STEP_S = 0.5  # the count goes up in half seconds: a long step shows a change at least twice a second


def seconds_text(elapsed_s: float) -> str:
    """" (3.5 s)": the seconds a step has taken so far, in ``COUNT_STEP_S``, once there is one."""
    if elapsed_s < COUNT_STEP_S:
        return ""
    return f" ({elapsed_s // COUNT_STEP_S * COUNT_STEP_S:.1f} s)"


def doing_text(what: str, elapsed_s: float) -> str:
    """``what`` a step is doing, with the seconds it has taken."""
    return f"{what}...{seconds_text(elapsed_s)}"


class Doing:
    """Says on ``line`` what the running call does and how long it has taken; hides ``line`` (class ``-empty``)
    again when done unless the screen wrote something else there."""

    def __init__(self, line: Static) -> None:
        self.line = line
        self._what = ""
        self._started = 0.0
        self._shown = ""
        self._timer: Timer | None = None

    def start(self, what: str) -> None:
        """Say ``what`` now (e.g. "Tapping: the robot moves the ball down until it touches") and count seconds."""
        self.done()
        self._what, self._started, self._shown = what, time.monotonic(), ""
        self._show()
        self._timer = self.line.set_interval(TICK_S, self._show)

    def done(self) -> None:
        """Stop counting; the line keeps its text until the screen writes the outcome (or clears it)."""
        if self._timer is not None:
            self._timer.stop()
            self._timer = None

    def _show(self) -> None:
        text = doing_text(self._what, time.monotonic() - self._started)
        if text != self._shown:
            self._shown = text
            self.line.update(text)
        self.line.remove_class("-empty")
