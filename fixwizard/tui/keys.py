"""The wizard's one key map: every key defined once, with one meaning on every screen. Screens build their
``BINDINGS`` from it (``binding``), messages that name a key take its name from here (``name``), and the help
screen (``?``) lists a screen's keys with their longer explanations.

Dialogs are modal and answer a question; their two answer keys (``YES``, ``NO``) are a map of their own and
written on their buttons. Keys marked ``motion`` make the robot move; they are refused while the wizard is
STOPPED (after the STOP key or a protective stop) until the operator re-arms."""

from dataclasses import dataclass

from textual.binding import Binding
from textual.dom import DOMNode


@dataclass(frozen=True)
class Key:
    """One key: Textual key names (``keys``, comma-separated), the action every screen names its method after
    (``action_<action>``), the footer's short label, the help screen's explanation, and whether it moves the
    robot."""

    keys: str
    action: str
    label: str
    explanation: str
    motion: bool = False
    display: str = ""

    @property
    def method(self) -> str:
        """The action's name without its parameters (the screen's method is ``action_<method>``)."""
        return self.action.split("(", 1)[0]

    @property
    def shown(self) -> str:
        """The key as the operator reads it (e.g. ``t``, ``Esc``, ``F12``)."""
        return self.display or self.keys.split(",")[0]


# --- every screen --- (each key's help line fits the help's 72 columns: tests/test_tui_help.py)
STOP = Key("f12,ctrl+x", "stop_robot", "STOP", "halt the robot now (also Ctrl+X); STOPPED until re-armed",
           display="F12")
REARM = Key("ctrl+r", "rearm", "Re-arm", "after a STOP, allow motion again (asks first)", display="Ctrl+R")
QUIT = Key("ctrl+q", "quit", "Quit", "leave (asks if the robot moves); a session can resume", display="Ctrl+Q")
HELP = Key("question_mark", "help", "Help", "this help", display="?")
BACK = Key("escape", "back", "Back", "one step back or cancel (asks before dropping records)", display="Esc")

# --- the steps ---
TAP = Key("t", "tap", "Tap", "the robot taps along the tool axis, records the contact", motion=True)
CAPTURE = Key("space", "capture", "Capture", "record the arm's pose (the ball stays on its point)", display="Space")
UNDO = Key("u", "undo", "Undo", "undo the last tap or drop (the journal keeps it)")
SOLVE = Key("s", "solve", "Solve", "find every fixture pose that explains the taps")
CHECK = Key("c", "check", "Check", "the taps against the fixture's report: has it moved?")
GO = Key("g", "go", "Go", "the robot moves: above the next tap, or the automatic taps", motion=True)
NEXT = Key("n", "next", "Next", "go on to the next step")
FREEDRIVE = Key("f", "freedrive", "Freedrive", "turn freedrive on, to guide the arm by hand")
IDENTIFY = Key("i", "identify", "Which?", "the taps against every fixture offered: which is this?")
HANDS = Key("m", "simulated_hands", "SIM hands", "the simulated hands move the arm to the next point",
            motion=True)
UNLOCK = Key("k", "simulated_unlock", "SIM unlock", "unlock a protective stop, as on the teach pendant")
DETAILS = Key("o", "details", "Details", "show or hide the solver's own figures (cells, levels)")
WRITE = Key("w", "write", "Write", "write the report to the path shown")
EDIT_PATH = Key("e", "edit_path", "Edit path", "edit where the report goes (Enter writes it there)")
VIEW = Key("v", "next_view", "View", "next view: summary, rotation set, taps on the fixture")
DROP = Key("d", "drop_suspect", "Drop tap", "drop the tap that does not fit, then solve again")
RESAMPLE = Key("r", "resample", "Resample", "back to sampling to add taps, then solve again")
DONE = Key("q", "done", "Done", "finish this fixture (asks if the report is not written)")
SCROLL = "the text by a line or a page"  # one line in the help for the four
SCROLL_DOWN = Key("down", "scroll_summary(1)", "Scroll", SCROLL, display="Down")
SCROLL_UP = Key("up", "scroll_summary(-1)", "Scroll", SCROLL, display="Up")
PAGE_DOWN = Key("pagedown", "scroll_summary(10)", "Scroll", SCROLL, display="PgDn")
PAGE_UP = Key("pageup", "scroll_summary(-10)", "Scroll", SCROLL, display="PgUp")

# --- dialogs ---
YES = Key("y", "yes", "Yes", "answer yes (the button says what it does)")
NO = Key("n,escape", "no", "No", "answer no, or close a message; nothing changes", display="n")

GLOBAL_KEYS = (HELP, QUIT, STOP, REARM)
SCREEN_KEYS = (BACK, TAP, CAPTURE, UNDO, SOLVE, CHECK, GO, NEXT, FREEDRIVE, IDENTIFY, HANDS, UNLOCK, DETAILS, WRITE,
               EDIT_PATH, VIEW, DROP, RESAMPLE, DONE, SCROLL_DOWN, SCROLL_UP, PAGE_DOWN, PAGE_UP)
DIALOG_KEYS = (YES, NO)
MOTION_ACTIONS = frozenset(key.method for key in (*GLOBAL_KEYS, *SCREEN_KEYS) if key.motion)
SIMULATED_ACTIONS = frozenset({HANDS.method, UNLOCK.method})


def binding(key: Key, label: str | None = None, show: bool = True, priority: bool = False) -> Binding:
    """The Textual binding of ``key``; ``label`` only rewords the footer for this screen (the meaning stays)."""
    return Binding(key.keys, key.action, label or key.label, show=show, priority=priority,
                   key_display=key.display if "," in key.keys else None)


def relabel(node: DOMNode, key: Key, label: str | None = None) -> None:
    """Reword ``key``'s footer label on ``node`` alone while its state lasts (None: the key map's own label), e.g. Esc
    while the step runs what Esc cancels; the meaning stays, and the footer and the help follow at once. (Textual
    reads a node's bindings from its own copy of the map, ``_bindings``, and has no public way to change one.)"""
    bound = node._bindings.key_to_bindings
    for reworded in Binding.make_bindings([binding(key, label)]):
        bound[reworded.key] = [reworded if each.action == key.action else each
                               for each in bound.get(reworded.key, [])]
    node.refresh_bindings()


def name(key: Key) -> str:
    """How a message names the key, e.g. ``m`` or ``Esc``."""
    return key.shown


def short_name(key: Key) -> str:
    """The key in the fewest columns, as terminals write control keys (``^R`` for Ctrl+R)."""
    return key.shown.replace("Ctrl+", "^")


def key_of(action: str) -> Key | None:
    """The key-map entry of a screen or app ``action`` (None for a widget's own key)."""
    return next((key for key in (*GLOBAL_KEYS, *SCREEN_KEYS, *DIALOG_KEYS) if key.action == action), None)
