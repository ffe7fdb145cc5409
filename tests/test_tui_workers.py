"""Answers of the solver process reach a screen on the event loop only while it is there to show them: an answer
that arrives while the screen is being taken down (its widgets gone, the screen not in view) is dropped, and a
widget missing from a screen in view is still an error."""

import asyncio

import pytest
from textual.app import App, ComposeResult
from textual.css.query import NoMatches
from textual.screen import Screen
from textual.widgets import Static

from fixwizard.tui.workers import run_in_solver

pytestmark = pytest.mark.asyncio


class OneRequestSolver:
    """The two members of ``SolverProcess`` that ``run_in_solver`` uses; answers are delivered by the test."""

    latest_request = 1

    def submit(self, request, on_event):
        self.arrived = on_event
        return 1


class LiveScreen(Screen):
    def compose(self) -> ComposeResult:
        yield Static("", id="live")


class Host(App):
    def on_mount(self) -> None:
        self.push_screen(LiveScreen())


async def delivered(solver: OneRequestSolver, event: str) -> None:
    """Deliver an answer from another thread, as the solver's reader thread does (it waits for the loop)."""
    await asyncio.to_thread(solver.arrived, event)


async def test_an_answer_reaches_the_screen_while_the_app_holds_it_and_is_dropped_after():
    app = Host()
    async with app.run_test() as pilot:
        await pilot.pause()
        screen = app.screen
        assert isinstance(screen, LiveScreen)
        solver = OneRequestSolver()
        run_in_solver(screen, solver, None, lambda event: screen.query_one("#live", Static).update(event))
        await delivered(solver, "first look")
        assert str(screen.query_one("#live", Static).content) == "first look"
        app.push_screen(Screen())  # under another screen: still the app's, still updated
        await pilot.pause()
        await delivered(solver, "quick check")
        assert str(screen.query_one("#live", Static).content) == "quick check"
        await screen.query_one("#live").remove()
        with pytest.raises(NoMatches):  # a widget missing from a screen the app holds is a bug, not hidden
            await delivered(solver, "refined check")
        app.pop_screen()
        app.pop_screen()  # the live screen is gone: its answers are dropped, no error in the reader thread
        await pilot.pause()
        await delivered(solver, "next tap")
