"""The wizard's keys and states as an operator meets them at 80x24 on the simulated cell: one key map for every
screen (no key means two things, the simulated hands on one key everywhere), help on ``?`` everywhere, the
STOPPED state that refuses motion until a confirmed re-arm, confirmations before anything recorded is dropped
or the wizard quits during motion, the footer's Esc and Quit in view, the newest tap in view, focus visible
without colour."""

import asyncio
import dataclasses
import importlib
import inspect
import pkgutil
import re
import sys
from pathlib import Path

import pytest
from textual.containers import Vertical, VerticalScroll
from textual.pilot import Pilot
from textual.screen import Screen
from textual.widgets import DataTable, Footer, Select, Static
from textual.widgets._footer import FooterKey

import fixwizard.tui
from fixwizard.calibration.store import load_calibration, save_calibration
from fixwizard.tui import keys
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.start.screen import NEW, StartScreen
from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.dialog import Dialog
from fixwizard.tui.widgets.help import HelpScreen
from fixwizard.tui.widgets.too_small import TooSmall
from pilot_wait import dialog_shown, until
from test_tui_app import (
    REPO,
    SIZE,
    at_start,
    at_the_automatic_taps,
    calibrate_by_hand,
    pivot_by_hand,
    press_button,
    rearm,
    status_of,
    wizard,
)
from tui_cell import ScreenHost, record_spread_taps, wizard_context


def wizard_screens() -> list[type[Screen]]:
    """Every screen and dialog class the wizard defines."""
    for module in pkgutil.walk_packages(fixwizard.tui.__path__, "fixwizard.tui."):
        importlib.import_module(module.name)
    found = set()
    for module_name, module in list(sys.modules.items()):
        if module_name.startswith("fixwizard.tui."):
            found |= {cls for _, cls in inspect.getmembers(module, inspect.isclass)
                      if issubclass(cls, Screen) and cls.__module__.startswith("fixwizard.tui.")}
    return sorted(found, key=lambda cls: cls.__name__)


async def at_pivot(pilot: Pilot) -> None:
    """From the wizard's start to the pivot, its first step of a new tip calibration."""
    await at_start(pilot)
    await press_button(pilot, "#continue")
    await until(pilot, lambda: isinstance(pilot.app.screen, PivotScreen) and not pilot.app.screen.busy)


def key_names(key: keys.Key) -> list[str]:
    return key.keys.split(",")


def test_every_binding_of_every_screen_comes_from_the_key_map_and_has_its_action():
    screens = wizard_screens()
    assert {"StartScreen", "PivotScreen", "SamplingScreen", "ResultsScreen", "CheckScreen", "HelpScreen",
            "Confirm"} <= {cls.__name__ for cls in screens}
    for cls in [*screens, FixwizardApp]:
        for binding in cls.__dict__.get("BINDINGS", []):
            key = keys.key_of(binding.action)
            assert key is not None, f"{cls.__name__}: {binding.action} is not in the key map"
            assert binding.key == key.keys, f"{cls.__name__}: {binding.action} on {binding.key}, not {key.keys}"
            assert hasattr(cls, f"action_{key.method}"), f"{cls.__name__} has no action_{key.method}"


def test_no_key_means_two_things():
    for scope in ((*keys.GLOBAL_KEYS, *keys.SCREEN_KEYS), (*keys.GLOBAL_KEYS, *keys.DIALOG_KEYS)):
        names = [name for key in scope for name in key_names(key)]
        assert len(names) == len(set(names)), sorted(name for name in names if names.count(name) > 1)
        actions = [key.action for key in scope]
        assert len(actions) == len(set(actions))


def test_messages_name_letter_keys_as_the_key_map_writes_them():
    """The table points said "press T", "press N" and "press F" for t, n and f: a tired operator's Shift+T does
    nothing. Messages take a key's name from the key map (``keys.name``), lower case for the letter keys."""
    letter_keys = {name for key in (*keys.GLOBAL_KEYS, *keys.SCREEN_KEYS, *keys.DIALOG_KEYS)
                   for name in key_names(key) if len(name) == 1 and name.isalpha()}
    assert letter_keys and all(name.islower() for name in letter_keys)
    package = Path(fixwizard.tui.__file__).parent
    upper = [f"{path.relative_to(package)}: {match.group(0)!r}" for path in sorted(package.rglob("*.py"))
             for match in re.finditer(r"\b[Pp]ress [A-Z]\b", path.read_text())]
    assert not upper, upper


def test_the_simulated_hands_are_on_one_key_on_every_screen_that_has_them():
    with_hands = [cls for cls in wizard_screens() if any(b.action == keys.HANDS.action for b in cls.BINDINGS)]
    assert {cls.__name__ for cls in with_hands} == {"PivotScreen", "TablePointsScreen", "AutoTapsScreen",
                                                    "SamplingScreen", "CheckScreen"}
    for cls in wizard_screens():
        for binding in cls.__dict__.get("BINDINGS", []):
            assert (binding.key == keys.HANDS.keys) == (binding.action == keys.HANDS.action)


def help_of(app) -> str:
    assert isinstance(app.screen, HelpScreen)
    return str(app.screen.query_one("#help-text", Static).render())


async def open_help(pilot: Pilot) -> str:
    """Open the help, check it is all in view (at 80x24, the tests' size), close it; its text."""
    await pilot.press("question_mark")
    await until(pilot, lambda: isinstance(pilot.app.screen, HelpScreen) and bool(pilot.app.screen.query(Static)))
    await pilot.pause()
    assert pilot.app.screen.query_one(VerticalScroll).max_scroll_y == 0
    text = help_of(pilot.app)
    await pilot.press("escape")
    await until(pilot, lambda: not isinstance(pilot.app.screen, HelpScreen))
    return text


def test_question_mark_opens_the_help_of_each_step_with_its_keys_and_the_global_ones(tmp_path):
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            text = await open_help(pilot)
            assert text.startswith("Choose the robot") and "Keys everywhere:" in text and "F12" in text
            assert isinstance(app.screen, StartScreen)
            await press_button(pilot, "#continue")
            await until(pilot, lambda: isinstance(app.screen, PivotScreen) and not app.screen.busy)
            text = await open_help(pilot)
            assert text.startswith("Find the ball tip roughly") and "Keys on this screen:" in text
            assert "  m       SIM hands: the simulated hands move" in text and "  Space   Capture" in text
            assert "  Esc     Back" in text and "  Ctrl+R  Re-arm" in text
            for _ in range(app.cell.hands.pivot_count):
                await pilot.press("m")
                await until(pilot, lambda: not app.screen.busy)
            await pilot.press("n")
            await until(pilot, lambda: isinstance(app.screen, TablePointsScreen) and not app.screen.busy)
            assert (await open_help(pilot)).startswith("Tap three points of a flat, clear table corner")
            for _ in range(3):
                await pilot.press("m")
                await until(pilot, lambda: not app.screen.busy)
            await pilot.press("n")
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))
            text = await open_help(pilot)
            assert text.startswith("The robot taps the table by itself") and "  g       Go" in text
            await pilot.press("g")  # the simulated taps may be done before the next frame
            await until(pilot, lambda: isinstance(app.screen, Confirm | CalibrationResultScreen) or app.screen.busy)
            await pilot.press("question_mark")  # also over a dialog or the result
            await until(pilot, lambda: isinstance(app.screen, HelpScreen))
    asyncio.run(run())


def test_help_on_the_sampling_screen_lists_its_keys(tmp_path):
    async def run():
        context = wizard_context(tmp_path)
        app = FixwizardApp(context.cell, sampling=context.sampling)
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
            text = await open_help(pilot)
            assert text.startswith("Freedrive is on") and "  t       Tap" in text and "  s       Solve" in text
            assert "  m       SIM hands" in text and "  i       Which?" in text  # also the keys the footer hides
            assert "SIM unlock" not in text  # only after a protective stop
    asyncio.run(run())


def test_stop_shows_stopped_refuses_motion_until_a_confirmed_rearm(tmp_path):
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await at_pivot(pilot)
            await pilot.press("m")
            await until(pilot, lambda: len(app.screen.workflow.poses("pivot")) == 1 and not app.screen.busy)
            await pilot.press("f12")
            await until(pilot, lambda: status_of(app).startswith(" SIMULATED   STOPPED  ^R re-arms | demo cell"))
            assert "F12 STOP" not in status_of(app)
            await pilot.press("m")  # a motion key: refused, with why
            await pilot.pause()
            assert len(app.screen.workflow.poses("pivot")) == 1
            assert any("STOPPED: the robot does not move until you re-arm" in str(note.message)
                       for note in app._notifications)
            await pilot.press("ctrl+r")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("n")  # not yet
            await until(pilot, lambda: isinstance(app.screen, PivotScreen))
            assert app.stopped and app.cell.robot.status().mode == "idle"  # the STOP ended freedrive
            await rearm(pilot)
            assert "STOPPED" not in status_of(app) and "F12 STOP" in status_of(app)
            await until(pilot, lambda: app.cell.robot.status().mode == "freedrive")  # as the screen says it is
            await pilot.press("m")
            await until(pilot, lambda: len(app.screen.workflow.poses("pivot")) == 2)
    asyncio.run(run())


def test_re_arm_pressed_twice_asks_once_and_a_stop_meanwhile_takes_the_question_back(tmp_path):
    """Ctrl+R pressed twice stacked two re-arm questions (and Ctrl+Q twice during motion two quit questions); a yes
    to a question asked before another STOP re-armed after that STOP. Now each is asked once, and STOP closes an
    open re-arm question: the wizard stays STOPPED until the operator asks again."""
    def questions(app) -> list[str]:
        return [screen.title_text for screen in app.screen_stack if isinstance(screen, Confirm)]

    async def run():
        # 0.1 s a simulated motion: the automatic taps (112 motions) outlast both Ctrl+Q; at 0.02 s they could end
        # between the two on a quiet machine, and the second quit at once
        app = FixwizardApp(wizard(tmp_path, pace_s=0.1))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped)
            await pilot.press("ctrl+r", "ctrl+r")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.pause()
            assert questions(app) == ["Re-arm the robot?"]
            await pilot.press("f12")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            await pilot.press("y")
            await pilot.pause()
            assert app.stopped and questions(app) == []
            await rearm(pilot)
            await calibrate_by_hand(pilot)
            await pilot.press("g")
            await until(pilot, lambda: app.motion_running())
            await pilot.press("ctrl+q", "ctrl+q")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.pause()
            assert questions(app) == ["Quit while the robot moves?"]
            await pilot.press("n")
            await until(pilot, lambda: not questions(app))
            assert app.is_running
    asyncio.run(run())


def test_a_yes_to_a_re_arm_question_asked_before_a_stop_under_the_help_re_arms_nothing(tmp_path):
    """The help over the re-arm question, STOP pressed there (the question is not on top, so it stays open), the help
    closed, then yes: the answer was about the cell before that STOP; the wizard stays STOPPED and says so."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await at_start(pilot)
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped)
            await pilot.press("ctrl+r")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("question_mark")  # the help over the question (a modal screen cuts the app's keys off)
            await until(pilot, lambda: isinstance(app.screen, HelpScreen))
            assert "Answer the question" in str(app.screen.query_one("#help-text", Static).render())
            await pilot.press("f12")
            await pilot.press("escape")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("y")
            await until(pilot, lambda: not isinstance(app.screen, Confirm))
            await pilot.pause()
            assert app.stopped
            assert any("A STOP came after the re-arm question" in str(note.message) for note in app._notifications)
            await rearm(pilot)
            assert not app.stopped
    asyncio.run(run())


def test_a_protective_stop_makes_the_wizard_stopped_and_rearm_waits_for_the_unlock(tmp_path):
    async def run():
        context = wizard_context(tmp_path)
        app = FixwizardApp(context.cell, sampling=context.sampling)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
            sampling = app.screen
            context.robot.inject_fault("protective_stop_during_tap")
            await pilot.press("m")
            await until(pilot, lambda: not sampling.busy)
            await pilot.press("t")
            await until(pilot, lambda: app.stopped and " STOPPED" in status_of(app))
            await until(pilot, lambda: app.robot_status.protective_stop)
            if app.screen is not sampling:  # the error dialog
                await pilot.press("escape")
            # also with the unlock and re-arm keys shown (re-arm and help were cut off at 80 columns)
            await assert_in_view(pilot, "escape", "t", "k", "ctrl+q", "ctrl+r", "question_mark")
            await pilot.press("ctrl+r")
            await pilot.pause()
            assert not isinstance(app.screen, Confirm) and app.stopped  # still locked: unlock first
            await pilot.press("k")
            await until(pilot, lambda: not app.robot_status.protective_stop)
            assert app.stopped
            await rearm(pilot)
            await until(pilot, lambda: context.robot.status().mode == "freedrive")  # sampling's freedrive is back
    asyncio.run(run())


def test_ctrl_c_says_which_keys_stop_the_robot_and_quit(tmp_path):
    """A tired operator's Ctrl+C (to stop the robot, or to quit) said "Press ctrl+q to quit the app"."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await at_pivot(pilot)
            await pilot.press("ctrl+c")
            await until(pilot, lambda: any("Ctrl+C stops nothing here: F12 stops the robot, Ctrl+Q quits the wizard."
                                           == str(note.message) for note in app._notifications))
            assert isinstance(app.screen, PivotScreen) and app.is_running
    asyncio.run(run())


@pytest.mark.parametrize("cancel", ["n", "enter"])  # Enter presses the focused Cancel button
def test_quitting_while_the_robot_moves_asks_first(tmp_path, cancel):
    async def run():
        app = FixwizardApp(wizard(tmp_path, pace_s=0.2))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await calibrate_by_hand(pilot)
            await pilot.press("g")
            await until(pilot, lambda: app.motion_running())
            await pilot.press("ctrl+q")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            assert "Stop and quit (y)" in str(app.screen.query_one("#yes").label)
            await pilot.press(cancel)
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))
            await pilot.pause(0.3)
            assert isinstance(app.screen, AutoTapsScreen) and app.is_running  # the screen below stays
            await pilot.press("escape")  # cancels the automatic taps
            await until(pilot, lambda: not app.motion_running())
            await pilot.press("ctrl+q")  # nothing moves: quits at once
            await until(pilot, lambda: not app.is_running)
    asyncio.run(run())


@pytest.mark.parametrize("stay, drop", [("n", "y"), ("enter", "#yes")])  # keys, or Enter and a click on a button
def test_esc_on_the_pivot_asks_before_dropping_the_captured_poses(tmp_path, stay, drop):
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_pivot(pilot)
            pivot = app.screen
            await pilot.press("m")
            await until(pilot, lambda: len(pivot.workflow.poses("pivot")) == 1 and not pivot.busy)
            await pilot.press("escape")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            assert "drops the 1 captured pose;" in str(app.screen.query_one("#dialog-message").render())
            await pilot.press(stay)
            await until(pilot, lambda: app.screen is pivot)
            await pilot.pause(0.3)
            assert app.screen is pivot and len(pivot.workflow.poses("pivot")) == 1  # one screen closed, not two
            await pilot.press("escape")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await (pilot.click(drop) if drop.startswith("#") else pilot.press(drop))
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            await pilot.pause(0.3)
            assert isinstance(app.screen, StartScreen)
    asyncio.run(run())


def test_on_the_automatic_taps_esc_goes_back_and_next_answers_when_not_yet(tmp_path):
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await at_start(pilot)
            await calibrate_by_hand(pilot)
            await pilot.press("n")
            await pilot.pause()
            assert isinstance(app.screen, AutoTapsScreen)
            assert any("Not yet: press g to start the automatic taps" in str(note.message)
                       for note in app._notifications)
            await pilot.press("escape")
            await until(pilot, lambda: isinstance(app.screen, TablePointsScreen))
    asyncio.run(run())


def test_on_the_automatic_taps_the_footer_names_what_esc_does_now(tmp_path):
    """The footer said 'esc Back' while Esc cancelled the running taps: while they run it says 'esc Cancel taps' and
    Esc cancels them (the step stays); once they have ended it says 'esc Back' again, and Esc goes back."""
    async def run():
        async with at_the_automatic_taps(tmp_path, pace_s=0.05) as (_, app, pilot):
            screen = app.screen
            await until(pilot, lambda: footer_text(app, "escape") == "esc Back")
            await pilot.press("g")
            await until(pilot, lambda: app.motion_running())
            await until(pilot, lambda: footer_text(app, "escape") == "esc Cancel taps")
            await assert_in_view(pilot, "escape")
            await pilot.press("escape")
            await until(pilot, lambda: not app.motion_running())
            assert app.screen is screen
            assert "were cancelled after" in str(screen.query_one("#auto-state", Static).render())
            await until(pilot, lambda: footer_text(app, "escape") == "esc Back")
            await pilot.press("escape")
            await until(pilot, lambda: isinstance(app.screen, TablePointsScreen))
    asyncio.run(run())


def test_leaving_sampling_asks_and_lands_on_the_start_screen_with_that_session_to_resume(tmp_path):
    async def run():
        context = wizard(tmp_path)
        example = load_calibration(REPO / "calibrations" / "example_matlab_logo.yaml")
        save_calibration(dataclasses.replace(example, robot=context.robot_name), context.calibrations_dir / "tip.yaml")
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await at_start(pilot)
            assert app.screen.query_one("#calibration", Select).value != NEW
            await press_button(pilot, "#continue")
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
            session_path = app.screen.session.path
            assert str(app.screen.query_one("#note", Static).render()) == (
                f"Tip calibration tip.yaml. New session {session_path.name}: every tap is saved there as you go.")
            await pilot.press("escape")
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("y")
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and bool(app.screen.query("#session")))
            assert app.screen.query_one("#session", Select).value == str(session_path)
            await press_button(pilot, "#continue")
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and app.screen.is_mounted)
            note = str(app.screen.query_one("#note", Static).render())
            assert note.startswith(f"Resumed the session {session_path}: 0 taps recorded")
    asyncio.run(run())


def footer_keys(app) -> dict[str, FooterKey]:
    return {footer_key.key: footer_key for footer_key in app.screen.query_one(Footer).query(FooterKey)}


def footer_text(app, key: str) -> str:
    """What the footer shows for ``key`` (e.g. ``esc Back``); "" while it shows no such key."""
    shown = footer_keys(app).get(key) if app.screen.query(Footer) else None
    return "" if shown is None else " ".join(str(shown.render()).split())


async def assert_in_view(pilot: Pilot, *key_names: str) -> None:
    app = pilot.app
    await until(pilot, lambda: bool(app.screen.query(Footer)) and bool(footer_keys(app)))
    await pilot.pause()
    shown = footer_keys(app)
    for name in key_names:
        assert name in shown, f"{name} not in the footer of {type(app.screen).__name__}"
        region = shown[name].region
        assert region.width > 0 and region.right <= app.size.width, f"{name} cut off on {type(app.screen).__name__}"


def test_the_footer_keeps_esc_and_quit_in_view_at_80x24(tmp_path):
    async def run():
        context = wizard_context(tmp_path)
        app = FixwizardApp(context.cell, sampling=context.sampling)
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
            await pilot.pause()
            await assert_in_view(pilot, "escape", "ctrl+q", "question_mark")
        app = FixwizardApp(wizard(tmp_path / "calibration"))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await assert_in_view(pilot, "ctrl+q", "question_mark")
            await press_button(pilot, "#continue")
            await until(pilot, lambda: isinstance(app.screen, PivotScreen) and not app.screen.busy)
            await pilot.pause()
            await assert_in_view(pilot, "escape", "ctrl+q", "question_mark")
    asyncio.run(run())


def test_when_stopped_the_footer_of_the_hand_steps_keeps_re_arm_and_help_in_view_at_80x24(tmp_path):
    """STOPPED adds Ctrl+R to the footer, and the pivot's footer lost ? Help at 80 columns. Freedrive (on by itself
    on these steps, named in the messages that need it) is in their help, not their footer, as on sampling."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_pivot(pilot)
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped)
            await assert_in_view(pilot, "f12", "escape", "space", "m", "n", "ctrl+q", "ctrl+r", "question_mark")
            await rearm(pilot)
            for _ in range(app.cell.hands.pivot_count):
                await until(pilot, lambda: not app.screen.busy)
                await pilot.press(keys.HANDS.keys)
            await until(pilot, lambda: not app.screen.busy)
            await pilot.press("n")
            await until(pilot, lambda: isinstance(app.screen, TablePointsScreen) and not app.screen.busy)
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped)
            await assert_in_view(pilot, "f12", "escape", "t", "m", "n", "ctrl+q", "ctrl+r", "question_mark")
    asyncio.run(run())


def test_stop_stays_in_the_footer_and_the_help_fits_the_terminal(tmp_path):
    """At 60x20 the footer of the table points lost F12 STOP to the keys before it and the help was cut; at 80x24
    the help's close line was cut and the last line of the automatic taps' help scrolled. Below 80x23 the step is
    covered by a notice (tests/test_tui_small_terminal.py); a help open when the terminal shrinks stays, and
    scrolls."""
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            await pivot_by_hand(pilot)
            await assert_in_view(pilot, "f12")
            for _ in range(3):
                await pilot.press(keys.HANDS.keys)
                await until(pilot, lambda: not app.screen.busy)
            await pilot.press("n")
            await until(pilot, lambda: isinstance(app.screen, AutoTapsScreen))
            await pilot.press("question_mark")
            await until(pilot, lambda: isinstance(app.screen, HelpScreen) and bool(app.screen.query(VerticalScroll)))
            for width, height in (SIZE, (60, 20)):
                await pilot.resize_terminal(width, height)
                await pilot.pause()
                box = app.screen.query_one(Vertical)
                assert "Esc closes this help" in str(box.border_subtitle)
                # within the terminal, the status line above it and the footer (F12 STOP) below it in view
                assert box.region.x >= 0 and box.region.right <= width and box.region.y >= 1
                assert box.region.bottom <= height - 1
                text = app.screen.query_one(VerticalScroll)
                if width == SIZE[0]:
                    assert text.max_scroll_y == 0  # all of it in view
                else:
                    await pilot.press("end")
                    await until(pilot, lambda text=text: text.max_scroll_y > 0 and text.scroll_y == text.max_scroll_y)
            await pilot.press("escape")
            await until(pilot, lambda: isinstance(app.screen, TooSmall))
            await assert_in_view(pilot, "f12", "ctrl+q", "question_mark")
    asyncio.run(run())


@pytest.mark.asyncio
@pytest.mark.parametrize("size", [(60, 20), SIZE])
async def test_a_long_message_in_a_dialog_scrolls_with_the_keys_while_a_button_keeps_the_focus(size):
    """A robot error with its notes can be longer than a small terminal: the message scrolled only with a mouse."""
    message = "\n".join(f"line {number} of what happened and what to do next" for number in range(1, 41))
    app = ScreenHost(lambda: Dialog("Robot problem", message))
    async with app.run_test(size=size) as pilot:
        await until(pilot, lambda: bool(app.screen.query("#dialog-scroll")))
        text = app.screen.query_one("#dialog-scroll", VerticalScroll)
        await until(pilot, lambda: text.max_scroll_y > 0)
        await pilot.press("down", "down")
        await until(pilot, lambda: text.scroll_y == 2)
        await pilot.press("pagedown", "pagedown", "pagedown", "pagedown")
        await until(pilot, lambda: text.scroll_y == text.max_scroll_y)
        await pilot.press("up", "pageup")
        await until(pilot, lambda: text.scroll_y == text.max_scroll_y - 11)
        assert app.screen.focused is app.screen.query_one("#ok")
        await pilot.press("enter")
        await until(pilot, lambda: app.results == ["ok"])


@pytest.mark.asyncio
async def test_the_newest_tap_stays_in_view_after_25_taps(tmp_path):
    context = wizard_context(tmp_path)
    record_spread_taps(context, 24)
    app = ScreenHost(lambda: context.sampling_screen())
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        for key in "mt":
            await until(pilot, lambda: not screen.busy)
            await pilot.press(key)
        await until(pilot, lambda: not screen.busy and len(context.session.taps) == 25)
        await pilot.pause()
        table = screen.query_one(DataTable)
        await until(pilot, lambda: table.max_scroll_y > 0 and table.scroll_y == table.max_scroll_y)
        assert table.cursor_row == 24 and table.size.height >= 4
    context.session.release()


@pytest.mark.asyncio
async def test_a_resumed_session_opens_with_its_newest_tap_in_view_under_a_long_note(tmp_path):
    context = wizard_context(tmp_path)
    record_spread_taps(context, 14)
    opened = "Resumed the session with a long name: " + "its fixture, its tip calibration and more; " * 4
    app = ScreenHost(lambda: context.sampling_screen(opened))
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen
        table = screen.query_one(DataTable)
        await until(pilot, lambda: table.row_count == 14 and screen.live is not None and not screen.live_running)
        await pilot.pause()
        await until(pilot, lambda: table.max_scroll_y > 0 and table.scroll_y == table.max_scroll_y)
        assert table.cursor_row == 13
        height = table.size.height
        screen._say(opened * 2)  # the table shrinks
        await until(pilot, lambda: table.size.height < height)
        await pilot.pause()
        await until(pilot, lambda: table.scroll_y == table.max_scroll_y)
        height = table.size.height
        screen._problem(opened * 3)  # a robot problem's box shrinks it further
        await until(pilot, lambda: table.size.height < height)
        await pilot.pause()
        await until(pilot, lambda: table.scroll_y == table.max_scroll_y)
    context.session.release()


def test_focus_shows_without_colour(tmp_path, monkeypatch):
    monkeypatch.setenv("NO_COLOR", "1")

    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            assert "nocolor" in app.pseudo_classes
            focused = app.screen.query_one("#fixture", Select)
            other = app.screen.query_one("#units", Select)
            assert focused.has_focus
            # a bar glyph left of the focused field, none left of the others; bold reverse on the choice
            assert focused.styles.border_left[0] == "outer" and other.styles.border_left[0] == "blank"
            assert app.screen.query_one("#continue").styles.border_left[0] == "blank"
    asyncio.run(run())
