"""A full disk while tapping, on the real sampling screen and a real 64 KiB tmpfs: the tap that could not be
saved is refused with the reason, the taps before it stay, tapping on after freeing space follows no partial
record, and a resume shows every tap that was said to be saved."""

import re

import pytest
from textual.widgets import DataTable, Static

from conftest import fill_disk
from fixwizard.workflow.session import SamplingSession
from pilot_wait import until
from tui_cell import ScreenHost, record_spread_taps, wizard_context

pytestmark = pytest.mark.asyncio
SIZE = (80, 24)


def text_of(screen, selector: str) -> str:
    return str(screen.query_one(selector, Static).content)


@pytest.mark.slow
async def test_a_full_disk_mid_session_strands_no_tap(small_disk):
    context = wizard_context(small_disk)
    record_spread_taps(context, 9)  # the journal's last page is nearly full: the disk fills after a tap or two
    app = ScreenHost(lambda: context.sampling_screen())
    said_saved = list(range(1, 10))
    async with app.run_test(size=SIZE) as pilot:
        screen = app.screen

        async def press(key: str) -> None:
            await until(pilot, lambda: not screen.busy)
            await pilot.press(key)
            await until(pilot, lambda: not screen.busy)

        filler = fill_disk(small_disk)
        while not text_of(screen, "#problem"):
            await press("m")
            await press("t")
            said = re.search(r"Tap (\d+) recorded and saved", text_of(screen, "#note"))
            if said and not text_of(screen, "#problem"):
                said_saved.append(int(said.group(1)))
            assert len(said_saved) < 30, "the disk never filled up"
        problem = text_of(screen, "#problem")
        assert "the disk is full; free some space on it. This tap was not saved" in problem
        assert f"Nothing recorded is lost: {len(said_saved)} taps are saved" in problem
        assert screen.query_one(DataTable).row_count == len(said_saved)
        filler.unlink()  # the operator frees space and taps on
        await press("t")
        assert f"Tap {len(said_saved) + 1} recorded and saved" in text_of(screen, "#note")
        said_saved.append(len(said_saved) + 1)
    context.session.release()
    with SamplingSession.open(context.session.path) as resumed:
        assert resumed.recovered == ()
        assert [tap.id for tap in resumed.taps] == said_saved == list(range(1, len(said_saved) + 1))
