"""A toast of a notification that expired as it was made (a worker thread held the GIL after the toast rack looked)
leaves the wizard running: with Textual 8.2.8 its negative timer froze the event loop for good, F12 STOP included.
The app runs in a child process, so that a freeze fails the test instead of holding it."""

import subprocess
import sys

TOAST_OF_AN_EXPIRED_NOTIFICATION = """
import asyncio, pathlib, tempfile, time
from textual.notifications import Notification
from textual.widgets._toast import Toast
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.launch import simulated_cell

async def run(folder):
    app = FixwizardApp(simulated_cell(folder=pathlib.Path(folder)))
    async with app.run_test(size=(80, 24), notifications=True) as pilot:
        expired = Notification("the robot does not move until you re-arm", timeout=0.001)
        time.sleep(0.01)
        await app.screen.mount(Toast(expired))
        await pilot.pause(0.2)
        await pilot.press("f12")
        await pilot.pause()
        print("stopped" if app.stopped else "not stopped")

with tempfile.TemporaryDirectory() as folder:
    asyncio.run(run(folder))
"""


def test_a_toast_of_a_notification_that_just_expired_leaves_the_wizard_and_stop_working():
    try:
        result = subprocess.run([sys.executable, "-c", TOAST_OF_AN_EXPIRED_NOTIFICATION], capture_output=True,
                                text=True, timeout=60, check=False)
    except subprocess.TimeoutExpired:
        raise AssertionError("the wizard froze: F12 did nothing within 60 s") from None
    assert result.stdout.strip() == "stopped", result.stderr[-2000:]
