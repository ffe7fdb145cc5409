"""Resuming a session in the real wizard (Pilot, simulated demo cell): a resume that works says which session
it opened; every refusal is explained on screen and leaves the operator on the start screen."""

import asyncio
import contextlib
import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import zlib
from collections.abc import AsyncIterator
from pathlib import Path

import numpy as np
import pytest
from textual.pilot import Pilot
from textual.widgets import Static

from fixwizard.calibration.store import load_calibration, save_calibration
from fixwizard.demo import demo_fixture
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.cell import SavedCalibration
from fixwizard.tui.launch import simulated_cell
from fixwizard.tui.solve.screen import SolveScreen
from fixwizard.tui.start.screen import NEW, StartScreen
from fixwizard.tui.start.sessions import calibration_changes, start_session
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.tui.widgets.help import HelpScreen, help_text, keys_of
from fixwizard.tui.widgets.key_footer import KeyFooter
from fixwizard.tui.widgets.status import StatusBar
from fixwizard.workflow.session import SamplingSession
from pilot_wait import dialog_shown, until
from tui_cell import sampling_of, start_fixture

SIZE = (80, 24)
REPO = Path(__file__).resolve().parents[1]


def recorded_session(folder: Path, taps: int = 3) -> Path:
    """A released session with ``taps`` taps on the demo bracket, with the stored example calibration."""
    cell = simulated_cell(3, pace_s=0.0, folder=folder)
    shutil.copytree(REPO / "calibrations", folder / "calibrations", dirs_exist_ok=True)
    calibration_path = folder / "calibrations" / "example_matlab_logo.yaml"
    session = start_session(cell, demo_fixture(), SavedCalibration(load_calibration(calibration_path),
                                                                   calibration_path))
    for index in range(taps):
        session.record_tap(np.diag([1.0, 1.0, 1.0, 1.0]) + np.eye(4, k=3) * 0.01 * index)
    session.release()
    return session.path


def sampling_note(app: FixwizardApp) -> str:
    """The sampling screen's note line ("" on any other screen, or before it is mounted)."""
    if type(app.screen).__name__ != "SamplingScreen" or not app.screen.is_mounted:
        return ""
    return str(app.screen.query_one("#note", Static).render())


def damage_line(path: Path, number: int, replacement: bytes) -> None:
    lines = path.read_bytes().splitlines(keepends=True)
    lines[number - 1] = replacement
    path.write_bytes(b"".join(lines))


def test_a_resume_says_which_session_it_opened_and_shows_every_tap(tmp_path):
    path = recorded_session(tmp_path, taps=12)
    lines = path.read_bytes().splitlines(keepends=True)  # an older version's journal after a full disk:
    path.write_bytes(b"".join(lines[:11] + [lines[11][:60]] + lines[11:]))  # tap 11 half written, then tap 11

    async def run():
        context = simulated_cell(3, pace_s=0.0, folder=tmp_path)
        app = FixwizardApp(context, "")
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: "Resumed" in sampling_note(app))
            notice = sampling_note(app)
            assert f"Resumed the session {path}: 12 taps recorded, fixture demo_bracket.stl" in notice
            assert "tip calibration example_matlab_logo.yaml" in notice
            assert "line 12 of the session journal holds a record that was never finished" in notice
            assert [tap.id for tap in app.screen.session.taps] == list(range(1, 13))
            await until(pilot, lambda: app.screen.query_one("#taps").row_count == 12)
    asyncio.run(run())



def test_a_resumed_journal_double_spaced_by_an_editor_says_so_in_one_note_and_shows_the_taps(tmp_path):
    """Twenty blank lines and two copies are one note on the sampling screen, not a note per line filling the
    screen above the taps."""
    path = recorded_session(tmp_path, taps=20)
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join([lines[0]] + [piece for line in lines[1:] for piece in (line, b"\n")]
                              + [lines[3], lines[5]]))

    async def run():
        app = FixwizardApp(simulated_cell(3, pace_s=0.0, folder=tmp_path), "")
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: "Resumed" in sampling_note(app))
            notes = sampling_note(app).split("\n")[1:]
            assert notes == ["Note: lines 3, 5, 7, 9, 11 and 15 more are blank and lines 42 and 43 repeat earlier "
                             "lines exactly in the session journal (an edit or a copy: fixwizard writes no such "
                             "line), so they are skipped; every record is kept."]
            assert [tap.id for tap in app.screen.session.taps] == list(range(1, 21))
    asyncio.run(run())


def test_a_resumed_session_whose_last_change_was_a_drop_says_u_takes_it_back(tmp_path):
    """u takes back the last drop also after a resume, and after a solve left without d: the screen said nothing of
    the drop, so u, pressed to undo the last tap, brought back the tap the operator had dropped."""
    path = recorded_session(tmp_path, taps=6)
    with SamplingSession.open(path) as session:
        session.drop(3)

    async def run():
        app = FixwizardApp(simulated_cell(3, pace_s=0.0, folder=tmp_path), "")
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: "Resumed" in sampling_note(app))
            said = ("Tap 3 was dropped last: it does not count (the journal keeps it, marked dropped). Press u to "
                    "take the drop back.")
            assert sampling_note(app).split("\n")[1:] == [said]
            await pilot.press("s")  # a solve, cancelled: back on the sampling screen, u still takes the drop back
            await until(pilot, lambda: isinstance(app.screen, SolveScreen))
            await pilot.press("escape")
            await until(pilot, lambda: sampling_note(app) == said)
            await pilot.press("u")
            await until(pilot, lambda: "counts again" in sampling_note(app))
            assert [tap.id for tap in app.screen.session.taps] == list(range(1, 7))
    asyncio.run(run())

def missing(path: Path) -> str:
    return str(path.with_name("gone.jsonl"))


def garbled_line(path: Path) -> str:
    damage_line(path, 3, b"#### coffee ####\n")
    return str(path)


def checksum_mismatch(path: Path) -> str:
    damage_line(path, 3, path.read_bytes().splitlines(keepends=True)[2].replace(b"0.0", b"0.5", 1))
    return str(path)


def deleted_calibration(path: Path) -> str:
    (path.parents[1] / "calibrations" / "example_matlab_logo.yaml").unlink()
    return str(path)


def damaged_calibration(path: Path) -> str:
    (path.parents[1] / "calibrations" / "example_matlab_logo.yaml").write_text("schema: fixwizard.tip/1\ntcp: [\n")
    return str(path)


def recalibrated_with_another_ball(path: Path) -> str:
    """The tip calibration the session names written again (``calibrate-tip -o`` the same file) for a 6 mm ball:
    the session's taps were made with the 3 mm one, and the solve would have used 6 mm for them."""
    calibration_path = path.parents[1] / "calibrations" / "example_matlab_logo.yaml"
    save_calibration(dataclasses.replace(load_calibration(calibration_path), ball_diameter_m=0.006), calibration_path)
    return str(path)


def calibration_missing_a_step(path: Path) -> str:
    """A calibration that parses but lacks a step's figures (its message ends with a full stop)."""
    calibration = path.parents[1] / "calibrations" / "example_matlab_logo.yaml"
    calibration.write_text(calibration.read_text().replace("steps:\n  pivot:", "steps:\n  pivot_gone:"))
    return str(path)


def not_a_number_in_a_tap(path: Path) -> str:
    """A tap line with NaN (which JSON readers take, and no record holds), its checksum made to match."""
    record = json.loads(path.read_bytes().splitlines()[2])
    record["base_T_tcp_ur"][0] = float("nan")
    damage_line(path, 3, with_checksum(record))
    return str(path)


def deeply_nested_line(path: Path) -> str:
    damage_line(path, 3, b"[" * 100_000 + b"\n")
    return str(path)


def header_naming_no_fixture(path: Path) -> str:
    """A header that checks out but whose fixture is a word, not the mesh's path, units and hash."""
    header = json.loads(path.read_bytes().splitlines()[0])
    header["fixture"] = "bracket"
    damage_line(path, 1, with_checksum(header))
    return str(path)


def deeply_nested_calibration(path: Path) -> str:
    (path.parents[1] / "calibrations" / "example_matlab_logo.yaml").write_text("[" * 100_000)
    return str(path)


def with_checksum(record: dict) -> bytes:
    """A journal line holding ``record`` under a checksum that matches (the journal's own encoding)."""
    record.pop("crc", None)
    body = json.dumps(record, sort_keys=True, separators=(",", ":"))
    record["crc"] = f"{zlib.crc32(body.encode()):08x}"
    return (json.dumps(record, sort_keys=True, separators=(",", ":")) + "\n").encode()


def unknown_users_home(path: Path) -> str:
    return "~nosuchuser-fixwizard/gone.jsonl"  # Path.expanduser raises for it: a traceback before


def no_unfinished_session(path: Path) -> str:
    with SamplingSession.open(path) as session:
        session.close(report="done.yaml")
    return ""


def finished_session_by_path(path: Path) -> str:
    """A session closed with its report, asked for by its path: it opened for sampling, and a tap the robot made
    there was refused after the move (the session is finished)."""
    with SamplingSession.open(path) as session:
        session.close(report="done.yaml")
    return str(path)


@pytest.mark.parametrize("spoil, reason", [
    (missing, "gone.jsonl does not exist; check the path"),
    (unknown_users_home, "~nosuchuser-fixwizard/gone.jsonl does not exist; check the path"),
    (garbled_line, "line 3 of the session"),
    (checksum_mismatch, "is damaged (checksum or JSON)"),
    (deleted_calibration, "example_matlab_logo.yaml"),
    (damaged_calibration, "example_matlab_logo.yaml"),
    (calibration_missing_a_step, "'steps.pivot' is missing"),
    (recalibrated_with_another_ball, "the tip calibration example_matlab_logo.yaml changed since the session "
                                     "started (ball 6.0 mm, the session's taps: 3.0 mm)"),
    (not_a_number_in_a_tap, "line 3 of the session"),
    (deeply_nested_line, "line 3 of the session"),
    (header_naming_no_fixture, "was not started by the wizard"),
    (deeply_nested_calibration, "nested too deeply to read"),
    (no_unfinished_session, "there is no unfinished session in"),
    (finished_session_by_path, "is finished already (its report was written): start a new session to tap again"),
])
def test_every_refused_resume_is_explained_on_the_start_screen(tmp_path, spoil, reason):
    requested = spoil(recorded_session(tmp_path))

    async def run():
        context = simulated_cell(3, pace_s=0.0, folder=tmp_path)
        app = FixwizardApp(context, requested)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            assert str(app.screen.query_one("#dialog-title", Static).render()).strip() == "Cannot resume the session"
            message = str(app.screen.query_one("#dialog-message", Static).render())
            assert message.startswith("Could not resume ") and reason in message
            assert message.endswith("On the start screen, resume another session or start a new one.")
            assert "Traceback" not in message
            assert re.search(r"[^.]\.\. ", message) is None, message  # one full stop between two sentences
            await pilot.press("escape")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            assert reason in str(app.screen.query_one("#resume-problem", Static).render())  # it stays in view
            assert sampling_of(app) is None
    asyncio.run(run())


def test_a_session_open_in_another_wizard_is_refused_with_the_reason(tmp_path):
    path = recorded_session(tmp_path)

    async def run():
        context = simulated_cell(3, pace_s=0.0, folder=tmp_path)
        app = FixwizardApp(context, str(path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            message = str(app.screen.query_one("#dialog-message", Static).render())
            assert "is open in another fixwizard; close that one first" in message
            await pilot.press("escape")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            assert app.screen.query_one("#session").value == NEW
    with SamplingSession.open(path):  # the other wizard
        asyncio.run(run())


def test_the_start_screen_resume_says_which_session_it_opened(tmp_path):
    path = recorded_session(tmp_path, taps=2)

    async def run():
        context = simulated_cell(3, pace_s=0.0, folder=tmp_path)
        app = FixwizardApp(context)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None)
            app.screen.query_one("#session").value = str(path)
            await pilot.pause()
            app.screen.query_one("#continue").focus()
            await pilot.press("enter")
            await until(pilot, lambda: "Resumed" in sampling_note(app))
            assert f"Resumed the session {path}: 2 taps recorded" in sampling_note(app)
    asyncio.run(run())


def test_while_resume_opens_the_session_the_terminal_says_so_with_the_status_line_and_stop(tmp_path):
    """``fixwizard --resume`` showed a blank terminal while it loaded the session's mesh: 8 s for 330 000 faces, no
    words, no status line, no STOP key in view (and ? said "Answer the question"). The screen under the session's
    steps now says what it is doing, and its help why."""
    path = recorded_session(tmp_path, taps=2)

    async def run():
        app = FixwizardApp(simulated_cell(3, pace_s=0.0, folder=tmp_path), str(path))
        async with app.run_test(size=SIZE) as pilot:
            await until(pilot, lambda: "Resumed" in sampling_note(app))
            underneath = app.screen_stack[0]  # what the terminal shows until the sampling screen comes
            assert str(underneath.query_one("#opening", Static).render()) == (
                "Opening the session to resume: loading its fixture and tip calibration...")
            assert underneath.query(StatusBar) and underneath.query(KeyFooter)  # the status line, F12 STOP
            assert help_text(underneath.HELP_ABOUT, keys_of(underneath), False).plain.startswith(
                "The wizard is starting. With --resume it first loads the session's fixture and tip calibration")
    asyncio.run(run())


@contextlib.asynccontextmanager
async def opening_held(tmp_path: Path, monkeypatch) -> AsyncIterator[tuple[FixwizardApp, Pilot, threading.Event]]:
    """The wizard resuming a session of two taps, held on its opening screen (the session loading) until the
    returned event is set: the test acts meanwhile."""
    from fixwizard.tui import app as app_module

    path = recorded_session(tmp_path, taps=2)
    release = threading.Event()
    loading = app_module.resume_session

    def held(cell, requested):
        assert release.wait(30.0), "the test acts while the session loads, then lets it open"
        return loading(cell, requested)

    monkeypatch.setattr(app_module, "resume_session", held)
    app = FixwizardApp(simulated_cell(3, pace_s=0.0, folder=tmp_path), str(path))
    async with app.run_test(size=SIZE) as pilot:
        await until(pilot, lambda: app.screen.query("#opening"))
        yield app, pilot, release


def test_a_help_opened_while_resume_loads_closes_when_the_session_opens(tmp_path, monkeypatch):
    """? pressed while the session's mesh loads showed the opening screen's help; the sampling screen then came over
    it, and leaving sampling showed that help again, under every later screen."""
    async def run():
        async with opening_held(tmp_path, monkeypatch) as (app, pilot, help_shown):
            await pilot.press("question_mark")
            await until(pilot, lambda: isinstance(app.screen, HelpScreen))
            help_shown.set()
            await until(pilot, lambda: "Resumed" in sampling_note(app))
            assert not any(isinstance(screen, HelpScreen) for screen in app.screen_stack)
            await pilot.press("escape")  # leave sampling: the start screen, no help over it
            await until(pilot, lambda: isinstance(app.screen, (StartScreen, Confirm)))
            if isinstance(app.screen, Confirm):
                await pilot.press("y")
            await until(pilot, lambda: isinstance(app.screen, StartScreen))
            assert not any(isinstance(screen, HelpScreen) for screen in app.screen_stack)
    asyncio.run(run())


def test_a_re_arm_question_asked_while_resume_loads_is_answered_before_the_session_opens(tmp_path, monkeypatch):
    """F12 and Ctrl+R while the session's mesh loads: the sampling screen came over the re-arm question, the robot
    keys stayed off, and Ctrl+R there asked nothing (the question was asked already, under the screen)."""
    async def run():
        async with opening_held(tmp_path, monkeypatch) as (app, pilot, asked):
            await pilot.press("f12")
            await until(pilot, lambda: app.stopped)
            await pilot.press("ctrl+r")
            await until(pilot, lambda: isinstance(app.screen, Confirm))
            asked.set()
            await pilot.pause(0.5)  # the session has loaded: the question stays on top until answered
            assert isinstance(app.screen, Confirm)
            await pilot.press("y")
            await until(pilot, lambda: "Resumed" in sampling_note(app))
            assert not app.stopped
            assert not any(isinstance(screen, Confirm) for screen in app.screen_stack)
    asyncio.run(run())

def test_a_tip_calibration_changed_since_the_session_started_is_told_by_each_figure_its_taps_depend_on():
    calibration = load_calibration(REPO / "calibrations" / "example_matlab_logo.yaml")
    tip_info = {"ball_diameter_m": calibration.ball_diameter_m, "sample_bound_m": calibration.sample_bound_m,
                "tcp_p_tip_m": calibration.tcp_p_tip_m.tolist()}
    assert calibration_changes(tip_info, calibration) == []
    moved = dataclasses.replace(calibration, tcp_p_tip_m=calibration.tcp_p_tip_m + [0.0, 0.0, 0.0005],
                                sample_bound_m=0.001)
    assert calibration_changes(tip_info, moved) == ["sample bound 1.0 mm, the session's taps: 0.8 mm",
                                                    "the tip 0.50 mm from where the session's taps had it"]
    assert calibration_changes({"ball_diameter_m": "3 mm", "tcp_p_tip_m": [0.0, 0.05]}, moved) == []  # not held


def test_continue_pressed_again_while_the_session_opens_opens_it_once(tmp_path):
    """Continue pressed a second time before the resume was back (a large mesh takes seconds to load, with nothing
    to show for it) resumed the session again: "could not resume ...: the session ... is open in another fixwizard"
    about the session this wizard was opening. Now the second press says to wait, and the session opens once."""
    path = recorded_session(tmp_path, taps=2)

    async def run():
        app = FixwizardApp(simulated_cell(3, pace_s=0.0, folder=tmp_path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None)
            app.screen.query_one("#session").value = str(path)
            await pilot.pause()
            button = app.screen.query_one("#continue")
            button.press()
            button.press()  # the second, before the resume is back
            stacks = []
            while not ("Resumed" in sampling_note(app) or isinstance(app.screen, ErrorModal)):
                stacks.append([type(screen).__name__ for screen in app.screen_stack])
                await pilot.pause(0.02)
                assert len(stacks) < 3000, stacks[-1]
            assert not isinstance(app.screen, ErrorModal), app.screen.query_one("#dialog-message").render()
            assert not any("ErrorModal" in stack for stack in stacks)
            assert [str(note.message) for note in app._notifications] == [
                f"Still opening the session {path.name}: wait a moment."]
    asyncio.run(run())


def test_after_a_refused_resume_on_the_start_screen_continue_works_again(tmp_path):
    path = recorded_session(tmp_path, taps=2)
    checksum_mismatch(path)

    async def run():
        app = FixwizardApp(simulated_cell(3, pace_s=0.0, folder=tmp_path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None)
            start = app.screen
            start.query_one("#session").value = str(path)
            await pilot.pause()
            start.query_one("#continue").press()
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            await pilot.press("escape")
            await until(pilot, lambda: app.screen is start)
            assert "Last change" in str(start.query_one("#session-info", Static).render())
            start.query_one("#continue").press()  # the same session again: refused again, not "still opening"
            await until(pilot, lambda: dialog_shown(app, ErrorModal))
            assert "is damaged (checksum or JSON)" in str(app.screen.query_one("#dialog-message", Static).render())
            assert not any("Still opening" in str(note.message) for note in app._notifications)
    asyncio.run(run())


def test_the_wizard_without_a_terminal_says_it_needs_one(tmp_path):
    result = subprocess.run([sys.executable, "-m", "fixwizard.cli"], cwd=tmp_path, stdin=subprocess.DEVNULL,
                            capture_output=True, timeout=60, check=False, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert result.returncode == 1
    assert "the wizard needs an interactive terminal" in result.stderr.decode()
    assert "Traceback" not in result.stderr.decode() and not list(tmp_path.iterdir())


def test_a_journal_with_a_not_a_number_tap_does_not_stop_the_wizard_starting(tmp_path):
    """The start screen lists the unfinished sessions as it opens: one damaged journal does not stop the wizard."""
    not_a_number_in_a_tap(recorded_session(tmp_path))

    async def run():
        app = FixwizardApp(simulated_cell(3, pace_s=0.0, folder=tmp_path))
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: isinstance(app.screen, StartScreen) and app.screen.is_mounted)
            await pilot.pause()
            assert isinstance(app.screen, StartScreen)
    asyncio.run(run())
