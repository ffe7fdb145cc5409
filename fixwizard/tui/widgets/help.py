"""The help screen (``?`` on every screen): what to do on this step in one paragraph, the keys of this screen
and the ones that work everywhere, each with what it does, on one page from 80x23 (tmux's 80x24) on. Smaller,
it scrolls by the keys, and its bottom line says when more is below. Esc, n or ``?`` closes it."""

from dataclasses import replace

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical, VerticalScroll
from textual.screen import ModalScreen, Screen
from textual.widgets import Static

from fixwizard.tui import keys

TEXT_WIDTH = 72  # the help's text at 80 columns: the box (76) less its border and padding


def keys_of(screen: Screen) -> list[tuple[keys.Key, bool]]:
    """The keys of ``screen`` as they stand now (but the app's own), each named as its footer names it, and whether
    it works now."""
    entries: list[tuple[keys.Key, bool]] = []
    for active in screen.active_bindings.values():
        key = keys.key_of(active.binding.action)
        if active.node is not screen.app and key is not None and key not in keys.GLOBAL_KEYS and \
                all(key.action != seen.action for seen, _ in entries):
            entries.append((replace(key, label=active.binding.description), active.enabled))
    return entries


def key_lines(screen_keys: list[keys.Key]) -> list[str]:
    """One line per key: its name, label and explanation; keys that share a label and explanation (Up, Down, PgUp,
    PgDn) share a line."""
    groups: dict[tuple[str, str], list[keys.Key]] = {}
    for key in screen_keys:
        groups.setdefault((key.label, key.explanation), []).append(key)
    return [f"  {'/'.join(key.shown for key in group):7} {label}: {explanation}"
            for (label, explanation), group in groups.items()]


def help_text(about: str, screen_keys: list[tuple[keys.Key, bool]], stopped: bool) -> Text:
    """The help screen's text: the step's paragraph, its keys (those that do nothing right now named in their
    heading), then the keys of every screen but ``?``, which the reader has just pressed."""
    text = Text(about + "\n")
    if stopped:
        text.append(f"STOPPED: the robot keys are refused until you re-arm ({keys.name(keys.REARM)}).\n", "bold")
    if screen_keys:
        not_now = [key.shown for key, enabled in screen_keys if not enabled]
        text.append("Keys on this screen" + (f" (not now: {', '.join(not_now)})" if not_now else "") + ":\n",
                    "bold")
        text.append("\n".join(key_lines([key for key, _ in screen_keys])) + "\n")
    text.append("Keys everywhere:\n", "bold")
    text.append("\n".join(key_lines([key for key in keys.GLOBAL_KEYS if key != keys.HELP])))
    return text


class HelpScreen(ModalScreen[None]):
    """The help over the screen it explains; ``text`` from ``help_text``."""

    BINDINGS = [keys.binding(keys.NO, "Close"), keys.binding(keys.HELP, "Close", show=False)]

    def __init__(self, title: str, text: Text) -> None:
        super().__init__()
        self.title_text, self.text = title, text

    def compose(self) -> ComposeResult:
        with Vertical() as box:  # the title and how to close it are in its border: every row left is the text's
            box.border_title = Text(f" Help: {self.title_text} ")
            yield VerticalScroll(Static(self.text, id="help-text"))

    def on_mount(self) -> None:
        scroll = self.query_one(VerticalScroll)
        self.watch(scroll, "scroll_y", lambda _: self._show_position(), init=False)
        self.watch(scroll, "virtual_size", lambda _: self._show_position())

    def on_resize(self) -> None:
        self.call_after_refresh(self._show_position)

    def _show_position(self) -> None:
        """The bottom line: how to close the help, and how to read on while more of it is below."""
        scroll = self.query_one(VerticalScroll)
        more = scroll.scroll_y < scroll.max_scroll_y
        read_on = " MORE BELOW: Down or PgDn; " if more else " "
        self.query_one(Vertical).border_subtitle = Text(f"{read_on}{keys.name(keys.NO)} or Esc closes this help ",
                                                        "bold reverse" if more else "")

    def action_no(self) -> None:
        self.dismiss(None)

    def action_help(self) -> None:
        self.dismiss(None)
