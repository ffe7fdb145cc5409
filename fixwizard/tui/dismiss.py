"""Dismissing a screen when its work ends (a solve, a robot call, the automatic taps), with a dialog perhaps over it:
Textual's ``Screen.dismiss`` pops whatever screen is on top, so the dialog (an error, a question, the help) vanished
unread and the finished screen stayed under the next one. The screen goes once the operator has closed the dialog."""

from typing import TypeVar

from textual.screen import Screen

T = TypeVar("T")


def dismiss_when_on_top(screen: Screen[T], result: T) -> None:
    """Dismiss ``screen`` with ``result`` now if it is on top, else as soon as the screens over it are closed."""
    app = screen.app
    if app.screen is screen:
        screen.dismiss(result)
        return

    def changed(current: Screen) -> None:
        if current is screen:
            app.screen_change_signal.unsubscribe(screen)
            screen.dismiss(result)

    app.screen_change_signal.subscribe(screen, changed)
