"""A tired operator at the wizard on the simulated demo cell (Pilot): from a seeded RNG, keys of the screen on top
and the global ones, mostly those that go on (so that a run gets through the tip calibration, or past it with a
saved one, into taps, undo, the live check, the solve and the results) with noise between them; now and then a
terminal resized below 80x23 and back, a robot fault, the teach pendant's unlock, a pause for the robot. After
every step:

- the app runs and no exception escaped it; no traceback text is on any screen or in a notification;
- no motion of the robot starts while the wizard shows STOPPED, or while an error dialog is open, once nothing
  was on its way (a motion asked for before the STOP or the error is the targeted tests' business);
- the status bar says STOPPED exactly when the wizard is;
- every tap the sampling screen shows is in its session journal on disk, read back by the product's own reader,
  and undone ones are not; the screen's title counts them.

At the end the wizard quits and every session journal, resumed, holds the taps the wizard last had.

CI runs the cases in ``CASES``; ``MONKEY_RUNS=N`` runs N more with random seeds (each printed), ``MONKEY_SEED=S``
replays one, ``MONKEY_STEPS`` sets the steps of a run. A replay makes the same choices while the wizard is where
the first run found it; the pace of the robot calls, the live check and the solve can lead it elsewhere, so a failure
prints the steps that led to it (a minimised one belongs in a plain test)."""

import asyncio
import contextlib
import dataclasses
import faulthandler
import os
import random
import re
import shutil
import sys
import time
from collections.abc import Awaitable, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from textual.pilot import Pilot
from textual.widgets import Button, Input, Select
from textual.widgets._select import SelectOverlay

from fixwizard.calibration.store import load_calibration, save_calibration
from fixwizard.demo import demo_fixture
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.tui import keys
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.cell import Cell
from fixwizard.tui.check.screen import CheckScreen
from fixwizard.tui.launch import simulated_cell
from fixwizard.tui.results.screen import ResultsScreen
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.solve.screen import SolveScreen
from fixwizard.tui.start.screen import StartScreen
from fixwizard.tui.tip_calibration.auto import AutoTapsScreen
from fixwizard.tui.tip_calibration.hands import PivotScreen, TablePointsScreen
from fixwizard.tui.tip_calibration.result import CalibrationResultScreen
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.dialog import Dialog
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.tui.widgets.help import HelpScreen
from fixwizard.tui.widgets.status import StatusBar
from fixwizard.tui.widgets.taps_table import TapsTable
from fixwizard.tui.widgets.too_small import TooSmall
from fixwizard.workflow.session import SamplingSession, SessionError
from pilot_wait import until
from tui_cell import sampling_of, start_fixture, truth_calibration

CASES = ((2, False), (4, True))  # (seed, a tip calibration saved): through the calibration, and past it
STEPS = int(os.environ.get("MONKEY_STEPS", "90"))
EXTRA_RUNS = int(os.environ.get("MONKEY_RUNS", "0"))
SIZE = (80, 24)
SIZES = ((80, 24), (80, 23), (100, 30), (79, 24), (80, 22), (60, 20), (30, 8))
PACES_S = (0.0, 0.005, 0.02)  # seconds per simulated motion: a STOP lands in one more often when slower
MAX_CELLS = 4e6  # the solve's cell budget: a few seconds a solve
FAULTS = ("protective_stop_during_tap", "connection_loss", "no_surface")
BUSY_LIMIT_S = 90.0  # a robot call or a solve running longer than this is a hang
FROZEN_S = 300.0  # a step longer than this: the event loop is frozen (a step waits 60 s at most for what it needs)
EXAMPLE_CALIBRATION = Path(__file__).resolve().parents[1] / "calibrations" / "example_matlab_logo.yaml"
TRACEBACK = re.compile(r"Traceback \(most recent call last\)|File \"[^\"]+\", line \d+|\b\w+Error\(")


@dataclass
class Motion:
    """A motion of the simulated robot as it started, with the wizard's state then."""

    kind: str
    step: int
    stopped: bool
    error_open: bool
    settled: bool  # the STOPPED state or error dialog had been seen with nothing on its way before


class WatchedCell(SimulatedCell):
    """The simulated cell that reports each motion it starts (a tap or a move that passed its checks) to
    ``on_motion``, from the thread that asked for it."""

    on_motion: Callable[[str], None] | None = None

    def _move_for_pace(self, motion: str, stop_mark: int | None) -> None:
        with self._lock:
            self._require_ready()  # refused motions do not start
        with self._stopped:  # a STOP waits until the motion has started, or been refused for an earlier one
            if self.on_motion is not None and (stop_mark is None or stop_mark == self._stop_count):
                self.on_motion(motion)
            super()._move_for_pace(motion, stop_mark)


class WatchedApp(FixwizardApp):
    """The wizard, counting the STOPs it is sent."""

    stop_count = 0

    def action_stop_robot(self) -> None:
        self.stop_count += 1
        super().action_stop_robot()


def monkey_cell(seed: int, folder: Path, pace_s: float) -> tuple[Cell, WatchedCell]:
    """The demo cell of ``seed`` as ``simulated_cell`` makes it, with its robot watched."""
    robot = WatchedCell.with_fixture(demo_fixture(), seed=seed, pace_s=pace_s)
    cell = dataclasses.replace(simulated_cell(seed, pace_s, folder), robot=robot,
                               hands=SimulatedHands(robot, seed=seed), max_cells=MAX_CELLS)
    return cell, robot


def save_truth_calibration(cell: Cell, robot: WatchedCell) -> None:
    """A tip calibration of this robot holding its hidden tip and ball (the example's steps: a stored calibration
    keeps them), for the start screen to preselect."""
    truth = truth_calibration(robot)
    calibration = dataclasses.replace(load_calibration(EXAMPLE_CALIBRATION), name="saved", robot=cell.robot_name,
                                      created=truth.created, tcp_p_tip_m=truth.tcp_p_tip_m,
                                      ball_diameter_m=truth.ball_diameter_m, sample_bound_m=truth.sample_bound_m)
    save_calibration(calibration, cell.calibrations_dir / "saved.yaml")


def screen_text(app: FixwizardApp) -> str:
    """What the terminal shows of every screen on the stack (a dialog's, and the screens under it)."""
    lines = []
    for screen in app.screen_stack:
        if screen.is_mounted:
            lines += [strip.text for strip in screen._compositor.render_strips()]
    return "\n".join(lines)


def table_rows(screen: SamplingScreen) -> list[tuple[str, str, str]]:
    """The x, y, z (mm) cells of the taps table, as shown."""
    table = screen.query_one(TapsTable)
    return [tuple(str(cell) for cell in table.get_row_at(row)[1:4]) for row in range(table.row_count)]


def shown_mm(taps: list) -> list[tuple[str, str, str]]:
    return [tuple(f"{value:.1f}" for value in tap.base_p_ball_m * 1e3) for tap in taps]


def same_taps(one: list, other: list) -> bool:
    return len(one) == len(other) and all(a.id == b.id and np.array_equal(a.base_p_ball_m, b.base_p_ball_m)
                                          for a, b in zip(one, other, strict=True))


def journal_taps(path: Path, scratch: Path) -> list:
    """The active taps of the session journal at ``path`` as resuming it replays them (a copy is resumed: the wizard
    holds the journal's lock)."""
    scratch.mkdir(exist_ok=True)
    copy = scratch / path.name
    shutil.copyfile(path, copy)
    session = SamplingSession.open(copy)
    try:
        return session.taps
    finally:
        session.release()
        shutil.rmtree(scratch)


@dataclass
class Monkey:
    """One run: the RNG, the app and its watched robot, what was done and what was seen."""

    seed: int
    app: WatchedApp
    pilot: Pilot
    robot: WatchedCell
    folder: Path
    rng: random.Random
    step: int = 0
    log: list[str] = field(default_factory=list)
    motions: list[Motion] = field(default_factory=list)
    sessions: dict[Path, SamplingSession] = field(default_factory=dict)  # every session sampled, by journal
    screens_seen: set[str] = field(default_factory=set)
    names: int = 0
    settled_stop: int | None = None  # the STOP count when STOPPED was seen with nothing on its way
    settled_error: ErrorModal | None = None  # an error dialog seen open with nothing on its way
    quit: bool = False
    busy_since: float | None = None  # time.monotonic() since which something runs
    left_held: list[str] = field(default_factory=list)  # sessions still held by the process after the wizard quit

    def __post_init__(self) -> None:
        self.robot.on_motion = self._motion

    # --- watching ---

    def _motion(self, kind: str) -> None:
        """A motion starts (worker thread): note the wizard's state."""
        app = self.app
        stopped = app.stopped
        error = next((screen for screen in app.screen_stack if isinstance(screen, ErrorModal)), None)
        settled = (stopped and self.settled_stop == app.stop_count) or \
            (error is not None and error is self.settled_error)
        self.motions.append(Motion(kind, self.step, stopped, error is not None, settled))

    def fail(self, what: str) -> None:
        recent = "\n  ".join(self.log[-40:])
        raise AssertionError(f"seed {self.seed}, step {self.step}: {what}\nlast steps:\n  {recent}")

    async def check(self) -> None:
        """The invariants, after a step."""
        app = self.app
        if not app.is_running or app._exception is not None:
            self.fail(f"the app ended (return code {app.return_code}, exception {app._exception!r})")
        self.screens_seen.add(type(app.screen).__name__)
        text = screen_text(app) + "\n".join(str(note.message) for note in app._notifications)
        if TRACEBACK.search(text):
            self.fail(f"traceback text on screen:\n{text}")
        bad = [motion for motion in self.motions if motion.settled]
        if bad:
            self.fail(f"the robot moved while the wizard showed STOPPED or an error: {bad}")
        self._check_status_bar()
        self._check_taps()
        self._note_settled()

    def _note_settled(self) -> None:
        """Note the STOPPED state and an open error dialog once nothing is on its way: from then on, no motion may
        start until the operator re-arms or closes the error."""
        app = self.app
        if not app.stopped:
            self.settled_stop = None
        if app.motion_running():
            return
        self.settled_stop = app.stop_count if app.stopped else None
        self.settled_error = next((screen for screen in app.screen_stack if isinstance(screen, ErrorModal)), None)

    def _check_status_bar(self) -> None:
        app = self.app
        bars = [screen.query_one(StatusBar) for screen in app.screen_stack
                if screen.is_mounted and screen.query(StatusBar)]
        for bar in bars:
            shown = str(bar.render())
            if (" STOPPED " in shown) != app.stopped or ("F12 STOP" in shown) == app.stopped:
                if shown.strip():  # a bar not yet drawn says nothing
                    self.fail(f"the status bar says {shown!r} while stopped is {app.stopped}")

    def _check_taps(self) -> None:
        """The taps shown, the session's own and the journal's agree (the journal first: a tap on its way may be in
        it before the screen shows it)."""
        screen = sampling_of(self.app)
        if screen is None or not screen.is_mounted or not screen.query(TapsTable):
            return
        session = screen.session
        self.sessions[session.path] = session
        busy = screen.busy
        shown = table_rows(screen)
        title = str(screen.query_one("#title").render())
        memory = session.taps
        on_disk = journal_taps(session.path, self.folder / "scratch")
        if not (same_taps(memory, on_disk) or (busy and same_taps(memory, on_disk[:-1]))):
            self.fail(f"the session holds taps {[tap.id for tap in memory]}, its journal "
                      f"{[tap.id for tap in on_disk]}")
        if not (shown == shown_mm(memory) or (busy and shown == shown_mm(memory[:-1]))):
            self.fail(f"the table shows {shown}, the session holds {shown_mm(memory)}")
        count = len(shown)
        if f": {count} tap{'' if count == 1 else 's'} of " not in title:
            self.fail(f"the title {title!r} with {count} taps in the table")

    # --- acting ---

    async def press(self, *names: str) -> None:
        screen = self.app.screen
        said = f" ({screen.message[:160]!r})" if isinstance(screen, Dialog) else ""
        self.log.append(f"{self.step}: {type(screen).__name__}{said}: press {' '.join(names)}")
        await self.pilot.press(*names)

    async def run_step(self) -> None:
        self.step += 1
        actions = self.actions()
        names = list(actions)
        name = self.rng.choices(names, weights=[actions[name][0] for name in names])[0]
        await actions[name][1]()
        await self.pilot.pause()
        await self._no_hang()
        await self.check()

    def busy(self) -> bool:
        """Whether the robot may move (a robot call, the automatic taps) or a solve runs."""
        screen = self.app.screen
        return self.app.motion_running() or (isinstance(screen, SolveScreen) and screen.running)

    async def _no_hang(self) -> None:
        """Now and then the operator waits a moment for what runs; whatever runs ends within ``BUSY_LIMIT_S``."""
        if not self.busy():
            self.busy_since = None
            return
        self.busy_since = self.busy_since or time.monotonic()
        if time.monotonic() - self.busy_since > BUSY_LIMIT_S:
            self.fail(f"still busy after {BUSY_LIMIT_S:.0f} s on {type(self.app.screen).__name__}")
        if self.rng.random() < 0.3:
            await self.wait(1.0)

    def key(self, *names: str) -> Callable[[], Awaitable[None]]:
        return lambda: self.press(*names)

    def actions(self) -> dict[str, tuple[float, Callable[[], Awaitable[None]]]]:
        """What the operator may do next, with weights: the screen's keys, the global ones and the world's events."""
        app, screen = self.app, self.app.screen
        actions = self.world_actions()
        focused = app.focused
        if isinstance(focused, SelectOverlay):
            presses = {"escape": 2.0, "enter": 1.0, "up": 1.0, "down": 1.0}
        elif isinstance(screen, TooSmall):
            presses = {"escape": 0.3, "t": 0.2}
            actions["resize-back"] = (5.0, self.resize_back)
        else:
            presses, extra = self.screen_keys(screen)
            actions.update(extra)
        for name, weight in presses.items():
            actions[name] = (weight, self.key(name))
        return actions

    def world_actions(self) -> dict[str, tuple[float, Callable[[], Awaitable[None]]]]:
        """The global keys and the world's events, with weights."""
        app = self.app
        return {
            "stop": (0.25, self.key("f12")),
            "stop-x": (0.05, self.key("ctrl+x")),
            "rearm": (4.0 if app.stopped else 0.1, self.rearm),
            "help": (0.3, self.key("question_mark")),
            "ctrl+c": (0.05, self.key("ctrl+c")),
            "resize": (0.3, self.resize),
            "wait": (1.0, self.wait),
            "fault": (0.1, self.fault),
            "pendant": (1.0 if self.robot.status().protective_stop else 0.0, self.pendant_unlock),
            "quit": (0.005, self.quit_now),
        }

    def screen_keys(self, screen) -> tuple[dict[str, float], dict]:
        """The keys of ``screen`` (weights; those that go on weigh most) and its composite steps."""
        noise = {"escape": 0.3, "enter": 0.2, "tab": 0.3, "shift+tab": 0.1}
        if isinstance(screen, ErrorModal):
            return {"enter": 2.0, "escape": 1.0, "n": 0.5, "tab": 0.5, "down": 0.2}, {
                "recover": (3.0, self.recover)}
        if isinstance(screen, Confirm):
            return {"y": 3.0, "n": 1.5, "escape": 0.5, "enter": 0.5, "tab": 0.3, "question_mark": 0.2}, {}
        if isinstance(screen, HelpScreen):
            return {"escape": 4.0, "down": 0.3, "pagedown": 0.2, "question_mark": 0.1}, {}
        if isinstance(screen, Dialog):
            return {"escape": 2.0, "enter": 2.0, "down": 0.3}, {}
        if isinstance(screen, StartScreen):
            return {**noise, "escape": 0.2, "down": 0.2, "up": 0.1}, {
                "continue": (4.0, self.start_continue), "check": (0.3, lambda: self.press_button("#check"))}
        if isinstance(screen, PivotScreen):
            return {**noise, "m": 5.0, "n": 2.0, "space": 0.5, "f": 0.3}, {}
        if isinstance(screen, TablePointsScreen):
            return {**noise, "m": 4.0, "n": 2.0, "t": 0.8, "f": 0.3}, {}
        if isinstance(screen, AutoTapsScreen):
            return {**noise, "escape": 0.5, "g": 4.0, "n": 2.0, "m": 0.3, "f": 0.3}, {
                "hands": (0.0 if self.app.motion_running() else 0.3, self.hands_above_corner)}
        if isinstance(screen, CalibrationResultScreen):
            return {**noise, "backspace": 0.1}, {"accept": (4.0, self.accept_calibration),
                                                 "redo": (0.2, self.redo_calibration)}
        if isinstance(screen, SamplingScreen):
            return self.sampling_keys(screen), {}
        if isinstance(screen, SolveScreen):
            return {"escape": 0.3, "o": 0.3, "t": 0.2}, {"wait": (5.0, self.wait)}
        if isinstance(screen, ResultsScreen):
            return {**noise, "escape": 0.5, "w": 3.0, "v": 1.0, "q": 3.0, "r": 0.5, "d": 1.0, "down": 0.3,
                    "up": 0.2, "e": 0.2}, {}
        if isinstance(screen, CheckScreen):
            return {**noise, "escape": 3.0, "m": 1.0, "t": 1.0, "u": 0.5, "c": 0.5}, {}
        return noise, {}

    def sampling_keys(self, screen: SamplingScreen) -> dict[str, float]:
        taps = len(screen.session.taps)
        enough = taps >= 6 + self.seed % 5
        unlock = screen.check_action(keys.UNLOCK.action, ())
        return {"escape": 0.2, "tab": 0.1, "enter": 0.1, "m": 4.0, "t": 4.0, "u": 0.8, "s": 6.0 if enough else 0.2,
                "g": 0.8, "o": 0.3, "f": 0.3, "k": 2.0 if unlock else 0.1, "i": 0.05}

    # --- composite steps ---

    async def press_button(self, selector: str) -> None:
        """Focus a button of the screen on top and press Enter on it, as Tab and Enter would."""
        screen = self.app.screen
        buttons = screen.query(selector)
        if not buttons:
            return
        button = buttons.first(Button)
        button.focus()
        await self.pilot.pause()
        if button.has_focus and self.app.screen is screen:
            await self.press("enter")

    async def start_continue(self) -> None:
        screen = self.app.screen
        units = screen.query_one("#units", Select)
        if start_fixture(self.app) is None and units.value != "mm":
            self.log.append(f"{self.step}: StartScreen: units back to mm")
            units.value = "mm"
            return
        await self.press_button("#continue")

    async def accept_calibration(self) -> None:
        """Name the calibration anew (names taken in an earlier minute stay) and accept it."""
        screen = self.app.screen
        if not screen.query("#name"):
            return
        self.names += 1
        screen.query_one("#name", Input).value = f"monkey-{self.names}"
        if self.rng.random() < 0.8:
            screen.query_one("#ball-diameter", Input).value = "3"
        await self.press_button("#accept")

    async def redo_calibration(self) -> None:
        await self.press_button("#redo")

    async def recover(self) -> None:
        """Press the error's recovery button (reconnect, unlock) if it has one."""
        for selector in ("#reconnect", "#unlock"):
            if self.app.screen.query(selector):
                await self.press_button(selector)
                return
        await self.press("enter")

    async def hands_above_corner(self) -> None:
        """The operator brings the ball above the table corner B by hand: back there from the pivot, the automatic
        taps refuse to start, and the screen's own keys for it (f, m) are disabled unless the calibration was
        continued."""
        self.log.append(f"{self.step}: the operator's hands bring the ball above B")
        self.app.cell.simulated_hands().table_point("B")

    async def rearm(self) -> None:
        await self.press("ctrl+r")

    async def resize(self) -> None:
        size = self.rng.choice(SIZES)
        self.log.append(f"{self.step}: resize to {size[0]}x{size[1]}")
        await self.pilot.resize_terminal(*size)

    async def resize_back(self) -> None:
        self.log.append(f"{self.step}: resize to {SIZE[0]}x{SIZE[1]}")
        await self.pilot.resize_terminal(*SIZE)

    async def wait(self, at_most_s: float = 5.0) -> None:
        """The operator waits for the robot and the solve, for ``at_most_s`` at most."""
        self.log.append(f"{self.step}: wait")
        started = time.monotonic()
        while self.busy() and time.monotonic() - started < at_most_s:
            await self.pilot.pause(0.05)

    async def fault(self) -> None:
        fault = self.rng.choice(FAULTS)
        self.log.append(f"{self.step}: the next tap fails: {fault}")
        self.robot.inject_fault(fault)

    async def pendant_unlock(self) -> None:
        self.log.append(f"{self.step}: the teach pendant unlocks the protective stop")
        self.robot.unlock()

    async def quit_now(self) -> None:
        self.log.append(f"{self.step}: quit")
        self.quit = True

    # --- the end ---

    async def finish(self) -> dict[Path, list]:
        """Let the robot come to rest, check once more and quit (answering yes if asked); what each session held."""
        started = time.monotonic()
        while self.app.motion_running():
            if time.monotonic() - started > BUSY_LIMIT_S:
                self.fail("the robot did not come to rest")
            await self.pilot.pause(0.05)
        await self.pilot.pause()
        await self.check()
        held = {path: session.taps for path, session in self.sessions.items()}
        self.log.append("end: press ctrl+q")
        await self.pilot.press("ctrl+q")
        await until(self.pilot, lambda: not self.app.is_running or (isinstance(self.app.screen, Confirm)
                                                                     and self.app.screen.title_text.startswith("Quit")))
        if self.app.is_running:  # something started meanwhile
            await self.pilot.press("y")
            await until(self.pilot, lambda: not self.app.is_running)
        return held


@contextlib.contextmanager
def no_frozen_loop(seconds: float) -> Iterator[None]:
    """A run whose event loop stops for ``seconds`` (no step ends) dumps every thread's stack and ends the process, so
    that a freeze fails CI instead of holding it to its time limit (a toast froze Textual's loop once: see
    ``fixwizard.tui.toasts``)."""
    faulthandler.dump_traceback_later(seconds, exit=True, file=sys.__stderr__)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


async def monkey_run(seed: int, folder: Path, steps: int, saved: bool) -> Monkey:
    """``steps`` random steps of a tired operator from the start screen with a fresh folder (with a saved tip
    calibration of this robot if ``saved``); the run's record."""
    rng = random.Random(seed)
    cell, robot = monkey_cell(seed, folder, rng.choice(PACES_S))
    if saved:
        save_truth_calibration(cell, robot)
    app = WatchedApp(cell)
    async with app.run_test(size=SIZE, notifications=True) as pilot:
        monkey = Monkey(seed, app, pilot, robot, folder, rng)
        await until(pilot, lambda: isinstance(app.screen, StartScreen) and start_fixture(app) is not None)
        for _ in range(steps):
            with no_frozen_loop(FROZEN_S):
                await monkey.run_step()
            if monkey.quit:
                break
        held = await monkey.finish()
    for path, taps in held.items():
        on_disk = resumed_taps(path, monkey)
        if not same_taps(on_disk, taps):
            monkey.fail(f"the journal {path.name} resumed holds taps {[tap.id for tap in on_disk]}, the wizard had "
                        f"{[tap.id for tap in taps]}")
    return monkey


def resumed_taps(path: Path, monkey: Monkey) -> list:
    """The taps of the session journal at ``path`` resumed after the wizard quit. A session the start screen had
    resumed under a dialog when the wizard quit is still held by this process (the end of the process lets it go):
    noted, and a copy of it resumed."""
    try:
        session = SamplingSession.open(path)
    except SessionError:
        monkey.left_held.append(path.name)
        return journal_taps(path, monkey.folder / "scratch")
    try:
        return session.taps
    finally:
        session.release()


def report(monkey: Monkey, elapsed_s: float) -> str:
    unsettled = [motion for motion in monkey.motions if motion.stopped or motion.error_open]
    return (f"monkey seed {monkey.seed}: {monkey.step} steps in {elapsed_s:.0f} s, screens "
            f"{sorted(monkey.screens_seen)}, {len(monkey.motions)} motions, sessions "
            f"{[len(session.taps) for session in monkey.sessions.values()]} taps; motions as a STOP or an error "
            f"came: {unsettled}; left held: {monkey.left_held}")


def run_seed(seed: int, folder: Path, saved: bool) -> Monkey:
    print(f"\nmonkey seed {seed}, {'a saved' if saved else 'no'} tip calibration (replay: MONKEY_SEED={seed})")
    started = time.monotonic()
    monkey = asyncio.run(monkey_run(seed, folder, STEPS, saved))
    print(report(monkey, time.monotonic() - started))
    return monkey


@pytest.mark.slow
@pytest.mark.parametrize("seed, saved", CASES)
def test_a_tired_operator_crashes_nothing_moves_nothing_when_stopped_and_loses_no_tap(tmp_path, monkeypatch, seed,
                                                                                       saved):
    monkeypatch.chdir(tmp_path)  # a report path typed at random is written relative to the working folder
    run_seed(int(os.environ.get("MONKEY_SEED", seed)), tmp_path, saved)


@pytest.mark.slow
@pytest.mark.skipif(EXTRA_RUNS == 0, reason="MONKEY_RUNS=N runs N more random seeds")
def test_more_tired_operators(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for run in range(EXTRA_RUNS):
        seed = random.SystemRandom().randrange(1 << 31)
        run_seed(seed, tmp_path / str(run), saved=seed % 2 == 0)
