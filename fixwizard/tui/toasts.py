"""Notifications (toasts) that cannot freeze the wizard. Textual 8.2.8, the newest 8.x, freezes its event loop for
good when a toast is made for a notification that expired after the toast rack looked (another thread held the GIL
in between): the toast's timer gets a negative delay, and ``Timer._run`` then loops without ever awaiting, so no
key works any more, F12 STOP included. ``keep_toast_delays_positive`` lets such a toast wait a moment instead."""

from textual.widgets._toast import Toast

SHORTEST_TOAST_S = 0.01


def keep_toast_delays_positive() -> None:
    """Make every toast's timer wait at least ``SHORTEST_TOAST_S`` (once; the app calls it as it starts)."""
    on_mount = Toast._on_mount
    if getattr(on_mount, "keeps_delays_positive", False):
        return

    def at_least_a_moment(toast: Toast, event) -> None:
        toast._timeout = max(toast._timeout, SHORTEST_TOAST_S)
        on_mount(toast, event)

    at_least_a_moment.keeps_delays_positive = True  # type: ignore[attr-defined]
    Toast._on_mount = at_least_a_moment  # type: ignore[method-assign,assignment]
