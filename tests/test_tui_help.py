"""The help (``?``) as an operator reads it: at 80x23, the wizard's smallest terminal (80x24 in tmux), every screen's
help is on one page, with every key it can list; below that it scrolls by the keys and says when more is below."""

import asyncio

import pytest
from textual.containers import Vertical, VerticalScroll
from textual.screen import Screen
from textual.widgets import Static

from fixwizard.tui import keys
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.solve.screen import SolveScreen
from fixwizard.tui.widgets.help import TEXT_WIDTH, HelpScreen, help_text, key_lines, keys_of
from pilot_wait import until
from test_tui_app import SIZE, at_start, wizard
from test_tui_keys import at_pivot, open_help, wizard_screens
from tui_cell import PausedSolver, ScreenHost, wizard_context

SMALLEST = (80, 23)
SCREENS_WITH_HELP = [cls for cls in wizard_screens() if getattr(cls, "HELP_ABOUT", "")]


def every_key_of(cls: type[Screen]) -> list[keys.Key]:
    """The keys the help can list for a screen of ``cls``: its bindings and its base classes' (but the global ones)."""
    found: list[keys.Key] = []
    for base in reversed(cls.__mro__):
        for binding in base.__dict__.get("BINDINGS", []):
            key = keys.key_of(binding.action)
            if key is not None and key not in keys.GLOBAL_KEYS and key not in found:
                found.append(key)
    return found


def worst_help(cls: type[Screen]) -> HelpScreen:
    """The longest help of a screen of ``cls``: every key it binds, one of them not working now, and STOPPED."""
    screen_keys = every_key_of(cls)
    return HelpScreen(cls.__name__, help_text(cls.HELP_ABOUT, [(key, key is not screen_keys[0])
                                                               for key in screen_keys], stopped=True))


def subtitle(app) -> str:
    return str(app.screen.query_one(Vertical).border_subtitle)


def test_every_key_s_help_line_fits_the_help_s_width_at_80_columns():
    every_key = [*keys.GLOBAL_KEYS, *keys.SCREEN_KEYS, *keys.DIALOG_KEYS]
    too_wide = [line for line in key_lines(every_key) if len(line) > TEXT_WIDTH]
    assert not too_wide
    assert key_lines([keys.SCROLL_DOWN, keys.SCROLL_UP, keys.PAGE_DOWN, keys.PAGE_UP]) == [
        "  Down/Up/PgDn/PgUp Scroll: the text by a line or a page"]  # one line for the four


@pytest.mark.asyncio
@pytest.mark.parametrize("cls", SCREENS_WITH_HELP, ids=lambda cls: cls.__name__)
async def test_every_screen_s_help_is_on_one_page_at_80x23(cls):
    """The pivot's and sampling's help scrolled at 80x24 (sampling's by 7 lines), with a scroll bar as the only
    sign of more."""
    app = ScreenHost(lambda: worst_help(cls))
    async with app.run_test(size=SMALLEST) as pilot:
        await until(pilot, lambda: isinstance(app.screen, HelpScreen) and bool(app.screen.query(VerticalScroll)))
        await pilot.pause()
        text = app.screen.query_one(VerticalScroll)
        assert text.max_scroll_y == 0 and text.size.width >= TEXT_WIDTH
        assert subtitle(app) == " n or Esc closes this help "
        if every_key_of(cls):
            not_now = f"Keys on this screen (not now: {every_key_of(cls)[0].shown}):"
            assert not_now in str(app.screen.query_one("#help-text", Static).render())


@pytest.mark.asyncio
async def test_below_80x23_the_help_scrolls_by_the_keys_and_says_more_is_below():
    app = ScreenHost(lambda: worst_help(SamplingScreen))
    async with app.run_test(size=(60, 20)) as pilot:
        await until(pilot, lambda: isinstance(app.screen, HelpScreen) and bool(app.screen.query(VerticalScroll)))
        text = app.screen.query_one(VerticalScroll)
        await until(pilot, lambda: text.max_scroll_y > 0 and "MORE BELOW: Down or PgDn" in subtitle(app))
        await pilot.press("down")
        await until(pilot, lambda: text.scroll_y == 1)
        assert "MORE BELOW" in subtitle(app)
        for _ in range(5):
            await pilot.press("pagedown")
        await until(pilot, lambda: text.scroll_y == text.max_scroll_y and "MORE BELOW" not in subtitle(app))
        await pilot.press("up")
        await until(pilot, lambda: "MORE BELOW" in subtitle(app))
        await pilot.press("escape")
        await until(pilot, lambda: not isinstance(app.screen, HelpScreen))


def test_the_wizard_s_help_is_on_one_page_at_80x24_on_the_start_the_pivot_and_sampling(tmp_path):
    async def run():
        app = FixwizardApp(wizard(tmp_path))
        async with app.run_test(size=SIZE) as pilot:
            await at_start(pilot)
            assert "Tab moves between the fields" in await open_help(pilot)
            await at_pivot(pilot)
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped)
            text = await open_help(pilot)
            assert "STOPPED: the robot keys are refused until you re-arm (Ctrl+R)." in text
            assert "Keys on this screen:\n  Esc     Back" in text
        context = wizard_context(tmp_path / "sampling")
        app = FixwizardApp(context.cell, sampling=context.sampling)
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: isinstance(app.screen, SamplingScreen) and not app.screen.busy)
            assert "  i       Which?" in await open_help(pilot)
        context.session.release()
    asyncio.run(run())


@pytest.mark.asyncio
async def test_the_help_names_each_key_as_the_footer_does(tmp_path):
    """The solve screen's footer says 'esc Cancel', its help said 'Esc Back: one step back'."""
    context = wizard_context(tmp_path)
    app = ScreenHost(lambda: context.solve_screen(PausedSolver()))
    async with app.run_test(size=SIZE) as pilot:
        await until(pilot, lambda: isinstance(app.screen, SolveScreen))
        assert [(key.shown, key.label) for key, _ in keys_of(app.screen)] == [("Esc", "Cancel"), ("o", "Details")]
        text = help_text(SolveScreen.HELP_ABOUT, keys_of(app.screen), stopped=False).plain
        assert "  Esc     Cancel: " in text
    context.session.release()
