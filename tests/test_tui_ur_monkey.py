"""A tired operator at the wizard on a UR arm: the real app (Pilot) drives the real ur_rtde client in its link process
against the loopback controller, opened straight into sampling (as ``--robot HOST --resume`` does). The controller's
arm holds the demo cell's tip and ball, and the demo bracket stands on its table where the demo cell has it; the
session resumed holds taps the controller made before (``EARLIER_TAPS``), so the pose is pinned down from the start
and ``g`` takes the arm above the suggested point by itself. From a seeded RNG: the operator's keys (t, f, g, often
once the suggestion is shown, and y, u, F12, Ctrl+R, Esc, the dialogs' Reconnect, Unlock and OK), hands that guide
the ball above the fixture (now and then above the table beside it) in freedrive, random waits, and the cell's faults
at random moments, now or on the controller's next event (protective, emergency and safeguard stops, a dropped,
reset or frozen link, remote control off, pause on the pendant, the link process stalled or killed), and the
operator's fixes on the pendant (unlock, release and power on, play, remote control on, the network back). After
every step, from the controller's own state:

- the app runs, no exception escaped it, no traceback text is on screen or in a notification, the status bar says
  STOPPED exactly when the wizard is (``test_tui_monkey``'s checks);
- once STOPPED for as long as the arm takes to stop at the latest (``STOP_BOUND_S``: the watchdog's periods, the
  wizard's margin and the loopback's scheduling grace), no tap or move program runs, none starts until re-armed,
  no freedrive starts unless the operator pressed f, and the flange does not move but by the operator's hands;
- from the moment an error dialog is shown until it is closed the flange does not move but by the operator's hands
  and no tap or move program starts;
- every tap the sampling screen shows is in its session journal, and each is a contact the controller made;
- no move the wizard planned (above a suggested point) meets the fixture or the table on its way;
- at most one link process is alive, none once the wizard quit;
- F12 puts the wizard in STOPPED within ``F12_BOUND_S``.

CI runs the seeds of ``CASES`` (about half a minute each); ``UR_MONKEY_RUNS=N`` runs N more random seeds (each
printed), ``UR_MONKEY_SEED=S`` replays one, ``UR_MONKEY_STEPS`` sets the steps of a run. As for ``test_tui_monkey``,
a replay makes the same choices only while the robot's pace leads the wizard where it did."""

import asyncio
import os
import random
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from textual.widgets import Button

from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.ur import WATCHDOG_HZ, WATCHDOG_MARGIN_S, WATCHDOG_PERIODS, URRobot
from fixwizard.tui.results.screen import ResultsScreen
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.solve.screen import SolveScreen
from fixwizard.tui.start.screen import StartScreen
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.dialog import Dialog
from fixwizard.tui.widgets.errors import ErrorModal
from fixwizard.tui.widgets.help import HelpScreen
from pilot_wait import until
from test_tui_monkey import Monkey, WatchedApp, no_frozen_loop, resumed_taps, same_taps
from tui_cell import cell_of, sampling_of, wizard_context
from ur_loopback import private_loopback_host
from ur_loopback.arm import FixtureBody
from ur_loopback.controller import SCHEDULING_GRACE_S
from ur_loopback.link_faults import stall_link

pytestmark = pytest.mark.slow
HOST = private_loopback_host()
CASES = (11,)
STEPS = int(os.environ.get("UR_MONKEY_STEPS", "70"))
EXTRA_RUNS = int(os.environ.get("UR_MONKEY_RUNS", "0"))
SIZE = (80, 24)
UNLOCK_DELAY_S = 1.0  # the loopback's "5 s after the stop" rule, shortened
# The latest a STOP (or a stop of the controller's) has stopped the arm: the watchdog's periods (a frozen link loses the
# stop request and the dashboard's stop), the margin the wizard waits beyond them, the loopback's scheduling grace.
STOP_BOUND_S = WATCHDOG_PERIODS / WATCHDOG_HZ + WATCHDOG_MARGIN_S + SCHEDULING_GRACE_S
F12_BOUND_S = 1.0  # F12 pressed to the wizard's STOP action run
MOTIONS = ("tap", "move")  # the programs that move the arm by themselves
FAULTS = ("protective_stop", "emergency_stop", "system_emergency_stop", "safeguard_stop", "go_offline",
          "drop_connections", "freeze_link", "remote_control_off", "pause_on_pendant", "stall", "kill_link",
          "crash_link", "slow_slider")
EVENT_FAULTS = ("protective_stop", "emergency_stop", "safeguard_stop", "go_offline", "drop_connections",
                "freeze_link", "pause_on_pendant")
EVENTS = ("contact", "movel", "settled", "watchdog_check", "back_off")
HOVER_M = (0.002, 0.026)  # the tip's height above the surface where the hands leave it: some beyond a tap's 20 mm
EARLIER_TAPS = 12  # the session resumed holds these taps, made on this arm before: spread enough to pin the pose down
SUGGESTION_WAIT_S = 30.0
ON_FIXTURE = 0.97  # how often the hands bring the ball above the fixture (else above the table beside it)
MAX_TILT_RAD = np.radians(15.0)  # the tool's tilt away from the face's normal where the hands leave it
CLEAR_M = 0.001  # the ball clears everything by this where the hands leave it


@dataclass
class LoopbackCell:
    """The demo cell's truth as the loopback controller holds it (the bracket where the demo cell has it on the table,
    the demo tip and ball), and where the operator's hands can leave the ball in it."""

    base_T_cad: np.ndarray
    cad_p_vertices: np.ndarray  # m
    faces: np.ndarray
    flange_p_tip_m: np.ndarray
    ball_radius_m: float

    @classmethod
    def of(cls, cell: SimulatedCell) -> "LoopbackCell":
        mesh = cell.fixture.mesh
        return cls(cell.truth.base_T_cad, np.asarray(mesh.vertices, float), np.asarray(mesh.faces),
                   np.asarray(cell.truth.tcp_p_tip_m, float), cell.truth.ball_diameter_m / 2.0)

    def __post_init__(self) -> None:
        self._body = FixtureBody(self.cad_p_vertices, self.faces, self.base_T_cad)
        triangles = self.cad_p_vertices[self.faces]
        self._cad_n_faces = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        self._areas = np.linalg.norm(self._cad_n_faces, axis=1)
        self._cad_n_faces /= np.where(self._areas > 0.0, self._areas, 1.0)[:, None]

    def controller_options(self) -> dict:
        """What ``start_controller`` takes to hold this cell; the flange starts above the table beside the fixture."""
        return {"ball_radius_m": self.ball_radius_m, "flange_p_tip_m": self.flange_p_tip_m.tolist(),
                "fixture": (self.cad_p_vertices, self.faces, self.base_T_cad),
                "base_T_flange": self.above_table(random.Random(0), 0.01)}

    def _flange_at(self, base_p_ball: np.ndarray, base_d_tool: np.ndarray, spin_rad: float) -> np.ndarray:
        """The flange pose that holds the ball at ``base_p_ball`` with the tool's z axis along ``base_d_tool``."""
        base_R_down = Rotation.align_vectors([base_d_tool], [[0.0, 0.0, 1.0]])[0] * Rotation.from_euler("z", spin_rad)
        return make_transform(base_R_down, base_p_ball - base_R_down.apply(self.flange_p_tip_m))

    def above_table(self, rng: random.Random, hover_m: float) -> np.ndarray:
        """The ball ``hover_m`` above the table beside the fixture, the tool pointing down."""
        base_p_ball = [0.4 + rng.uniform(-0.05, 0.05), -0.1 + rng.uniform(-0.05, 0.05), self.ball_radius_m + hover_m]
        return self._flange_at(np.array(base_p_ball), np.array([0.0, 0.0, -1.0]), rng.uniform(-np.pi, np.pi))

    def above_fixture(self, rng: random.Random, hover_m: float) -> np.ndarray | None:
        """The ball ``hover_m`` off a random point of a fixture face the tool reaches (its normal not pointing down),
        the tool along the face's normal tilted up to ``MAX_TILT_RAD``; None where no such point leaves the ball
        clear of the fixture and the table after a few tries."""
        base_R_cad = self.base_T_cad[:3, :3]
        reachable = (self._cad_n_faces @ base_R_cad.T)[:, 2] >= -0.2
        weights = np.where(reachable, self._areas, 0.0)
        for _ in range(10):
            face = rng.choices(range(len(self.faces)), weights=weights.tolist())[0]
            u, v = rng.random(), rng.random()
            u, v = (1.0 - u, 1.0 - v) if u + v > 1.0 else (u, v)
            corner, *others = self.cad_p_vertices[self.faces[face]]
            cad_p_point = corner + u * (others[0] - corner) + v * (others[1] - corner)
            base_n = base_R_cad @ self._cad_n_faces[face]
            base_p_ball = transform_points(self.base_T_cad, cad_p_point[None])[0] + \
                (self.ball_radius_m + hover_m) * base_n
            tilt = Rotation.from_rotvec(rng.uniform(0.0, MAX_TILT_RAD) * _unit_across(base_n, rng))
            clear = self._body.penetration(base_p_ball, self.ball_radius_m + CLEAR_M)[0] == 0.0
            if clear and base_p_ball[2] > self.ball_radius_m + CLEAR_M:
                return self._flange_at(base_p_ball, tilt.apply(-base_n), rng.uniform(-np.pi, np.pi))
        return None

    def on_fixture(self, base_T_flange: np.ndarray) -> bool:
        """Whether the ball at flange pose ``base_T_flange`` touches the fixture (within 0.1 mm)."""
        base_p_ball = base_T_flange[:3, :3] @ self.flange_p_tip_m + base_T_flange[:3, 3]
        return self._body.penetration(base_p_ball, self.ball_radius_m + 1e-4)[0] > 0.0


def _unit_across(base_n: np.ndarray, rng: random.Random) -> np.ndarray:
    """A random unit vector at right angles to the unit vector ``base_n``."""
    across = np.cross(base_n, [rng.gauss(0.0, 1.0) for _ in range(3)])
    return across / np.linalg.norm(across)


class URWatchedApp(WatchedApp):
    """The wizard, noting when each STOP came and, for every error dialog it shows, what the controller did then."""

    def __init__(self, *args, controller: Any, **options) -> None:
        super().__init__(*args, **options)
        self.controller = controller
        self.stop_at = 0.0  # time.monotonic() of the latest STOP key
        self.shown: dict[int, ArmAt] = {}  # by id() of the ErrorModal

    def action_stop_robot(self) -> None:
        self.stop_at = time.monotonic()
        super().action_stop_robot()

    def _error_modal(self, error, reconnect=False):
        modal = super()._error_modal(error, reconnect)
        if modal is not None:
            self.shown[id(modal)] = ArmAt.now(self.controller, f"the error {str(error)[:200]!r}")
        return modal


@dataclass
class ArmAt:
    """The controller's flange pose and programs at a moment the arm must stand from (an error shown, STOPPED)."""

    what: str
    pose: np.ndarray
    programs: int

    @classmethod
    def now(cls, controller, what: str) -> "ArmAt":
        return cls(what, controller.flange_pose(), len(controller.programs()))


@dataclass
class URMonkey(Monkey):
    """One run on the UR arm: ``Monkey``'s checks and steps with the loopback controller's faults and the checks of
    the controller's own state."""

    controller: Any = None
    cell: "LoopbackCell | None" = None
    stopped_since: float | None = None  # when the wizard became STOPPED (the STOP key, or seen)
    stood: ArmAt | None = None  # STOPPED for STOP_BOUND_S: the arm stands from here
    freedrive_asked_at: float = 0.0  # the latest f
    link_pids: set[int] = field(default_factory=set)
    faults: list[str] = field(default_factory=list)
    stop_keys_s: list[float] = field(default_factory=list)  # F12 to STOPPED shown, each
    _last_check_at: float = 0.0

    def __post_init__(self) -> None:
        pass  # no simulated motions to watch: the controller's state is the judge

    @property
    def ur(self) -> URRobot:
        return self.robot

    # --- checks ---

    async def check(self) -> None:
        await super().check()
        if isinstance(self.app.screen, StartScreen):
            return
        self._check_stopped()
        self._check_errors_shown()
        self._check_contacts()
        self._check_moves()
        await self._check_link_processes()

    def _programs_since(self, at: ArmAt) -> list[str]:
        return [name for name, _, _ in self.controller.programs()[at.programs:]]

    def _moved(self, at: ArmAt) -> bool:
        return not np.allclose(self.controller.flange_pose(), at.pose, atol=1e-9)

    def _check_stopped(self) -> None:
        app, controller, now = self.app, self.controller, time.monotonic()
        if not app.stopped:
            self.stopped_since = self.stood = None
            return
        if self.stopped_since is None:
            self.stopped_since = app.stop_at if app.stop_at > self._last_check_at else now
        if now - self.stopped_since < STOP_BOUND_S:
            return
        programs = controller.programs()
        if controller.program_running() and programs[-1][0] in MOTIONS and not controller.program_paused():
            self.fail(f"the {programs[-1][0]} program runs {now - self.stopped_since:.1f} s after STOPPED")
        if self.stood is None:
            self.stood = ArmAt.now(controller, "STOPPED")
            return
        started = self._programs_since(self.stood)
        if any(name in MOTIONS for name in started):
            self.fail(f"programs {started} started while STOPPED")
        if "freedrive" in started and self.freedrive_asked_at < self.stopped_since:
            self.fail(f"freedrive started while STOPPED without f ({started})")
        if self._moved(self.stood):
            self.fail("the arm moved while STOPPED")

    def _check_errors_shown(self) -> None:
        for screen in self.app.screen_stack:
            if not isinstance(screen, ErrorModal) or id(screen) not in self.app.shown:
                continue
            at = self.app.shown[id(screen)]
            started = [name for name in self._programs_since(at) if name in MOTIONS]
            if started:
                self.fail(f"programs {started} started after {at.what} was shown")
            if self._moved(at):
                self.fail(f"the arm moved after {at.what} was shown")

    def _check_contacts(self) -> None:
        """Every tap of the session is a contact the controller made (``Monkey._check_taps`` holds the journal to
        the screen)."""
        screen = sampling_of(self.app)
        if screen is None:
            return
        contacts = self.controller.contact_poses()
        for tap in screen.session.taps:
            if not any(np.allclose(tap.base_T_tcp, contact, atol=2e-6) for contact in contacts):
                self.fail(f"tap {tap.id} at {tap.base_T_tcp[:3, 3]} is no contact the controller made")

    def _check_moves(self) -> None:
        """No move program met anything: the monkey puts nothing in the arm's way, so a blocked move is one the wizard
        planned into the fixture or the table."""
        if blocked := self.controller.blocked_moves():
            self.fail(f"a move met something with the flange at {blocked[0][:3, 3]}: its way was planned into it")

    async def _check_link_processes(self) -> None:
        """At most one link process alive (an abandoned one is killed and joined within a moment)."""
        if self.ur.link_pid is not None:
            self.link_pids.add(self.ur.link_pid)
        alive = [pid for pid in self.link_pids if process_alive(pid)]
        if len(alive) > 1:
            await self.pilot.pause(3.0)
            alive = [pid for pid in self.link_pids if process_alive(pid)]
            if len(alive) > 1:
                self.fail(f"{len(alive)} link processes alive: {alive}")

    async def run_step(self) -> None:
        await super().run_step()
        self._last_check_at = time.monotonic()

    # --- what the operator and the cell may do ---

    def world_actions(self):
        app, controller = self.app, self.controller
        return {
            "stop": (0.4, self.stop),
            "rearm": (4.0 if app.stopped else 0.1, self.rearm),
            "help": (0.1, self.key("question_mark")),
            "resize": (0.05, self.resize),
            "wait": (1.0, self.wait_a_moment),
            "fault": (0.35, self.fault),
            "fault-on-event": (0.25, self.fault_on_event),
            "pendant": (3.0 if self.faults else 0.1, self.fix_on_pendant),
            "play": (0.1, self.play),
            "hands": (3.0 if controller.in_freedrive() else 0.0, self.hands),
            "tap-then-fault": (1.0 if isinstance(app.screen, SamplingScreen) else 0.0, self.tap_then_fault),
        }

    def screen_keys(self, screen) -> tuple[dict[str, float], dict]:
        if isinstance(screen, ErrorModal):
            return {"enter": 1.0, "escape": 0.5, "tab": 0.3}, {"recover": (3.0, self.recover)}
        if isinstance(screen, Confirm):
            leave = screen.title_text.startswith(("Leave", "Quit"))  # a run stays on its sampling session
            return {"y": 0.02 if leave else 3.0, "n": 1.5, "escape": 0.5, "enter": 0.1 if leave else 0.5}, {}
        if isinstance(screen, HelpScreen):
            return {"escape": 4.0, "down": 0.3}, {}
        if isinstance(screen, Dialog):
            return {"escape": 2.0, "enter": 2.0}, {}
        if isinstance(screen, SamplingScreen):
            taps = len(screen.session.taps)
            return {"t": 5.0, "f": 1.0, "g": 0.3, "u": 0.6, "escape": 0.2, "enter": 0.1, "tab": 0.1, "o": 0.1,
                    "s": 0.3 if taps >= 3 else 0.05, "k": 0.05}, {"follow": (2.0, self.follow_suggestion)}
        if isinstance(screen, SolveScreen):
            return {"escape": 1.0}, {"wait": (2.0, self.wait_a_moment)}
        if isinstance(screen, ResultsScreen):
            return {"r": 3.0, "escape": 0.5, "v": 0.3}, {}
        return {"escape": 1.0}, {}

    async def stop(self) -> None:
        """F12 (or Ctrl+X): STOPPED is on screen within ``F12_BOUND_S``."""
        started = time.monotonic()
        await self.press(self.rng.choice(("f12", "f12", "ctrl+x")))
        while not (self.app.stopped and self.app.stop_at >= started):
            if time.monotonic() - started > F12_BOUND_S:
                self.fail(f"STOP not handled within {F12_BOUND_S} s")
            await self.pilot.pause(0.01)
        self.stop_keys_s.append(self.app.stop_at - started)
        if self.stop_keys_s[-1] > F12_BOUND_S:
            self.fail(f"STOP handled {self.stop_keys_s[-1]:.2f} s after F12")

    async def press(self, *names: str) -> None:
        if "f" in names:
            self.freedrive_asked_at = time.monotonic()
        await super().press(*names)

    async def hands(self) -> None:
        """The operator guides the ball above a point of the fixture, or of the table beside it (if freedrive is
        still on)."""
        hover_m = self.rng.uniform(*HOVER_M)
        where = "fixture" if self.rng.random() < ON_FIXTURE else "table"
        pose = self.cell.above_fixture(self.rng, hover_m) if where == "fixture" else None
        if pose is None:
            where, pose = "table", self.cell.above_table(self.rng, hover_m)
        try:
            self.controller.move_by_hand(pose)
        except RuntimeError:
            return  # freedrive ended meanwhile
        self.log.append(f"{self.step}: hands: the ball {hover_m * 1e3:.0f} mm above the {where}")
        for at in (self.stood, *self.app.shown.values()):  # the operator's hands, not the robot
            if at is not None:
                at.pose = self.controller.flange_pose()

    async def follow_suggestion(self) -> None:
        """The operator waits for the live check to suggest the next tap, or to end without a suggestion (at most
        ``SUGGESTION_WAIT_S``), and presses g."""
        started = time.monotonic()
        while (screen := sampling_of(self.app)) is not None and screen.hover_plan is None and screen.live_running \
                and time.monotonic() - started < SUGGESTION_WAIT_S and self.app.screen is screen:
            await self.pilot.pause(0.1)
        self.log.append(f"{self.step}: waited {time.monotonic() - started:.1f} s for a suggestion")
        await self.press("g")

    async def wait_a_moment(self) -> None:
        seconds = self.rng.choice((0.05, 0.2, 0.6, 1.5, 3.0))
        self.log.append(f"{self.step}: wait {seconds} s")
        await self.pilot.pause(seconds)

    async def fault(self) -> None:
        fault = self.rng.choice(FAULTS)
        self.log.append(f"{self.step}: fault now: {fault}")
        self.faults.append(fault)
        self.inject(fault)

    async def fault_on_event(self) -> None:
        fault, event = self.rng.choice(EVENT_FAULTS), self.rng.choice(EVENTS)
        self.log.append(f"{self.step}: fault on the controller's next {event}: {fault}")
        self.faults.append(fault)
        self.controller.when(event, fault)

    async def tap_then_fault(self) -> None:
        """t, and a fault (or STOP) a random moment later, while the tap runs."""
        await self.press("t")
        await self.pilot.pause(self.rng.uniform(0.0, 1.5))
        if self.rng.random() < 0.25:
            await self.stop()
        else:
            await self.fault()

    def inject(self, fault: str) -> None:
        controller, pid = self.controller, self.ur.link_pid
        if fault in ("stall", "kill_link", "crash_link") and pid is None:
            return
        if fault == "stall":
            threading.Thread(target=stall_link, args=(pid, self.rng.uniform(0.1, 1.5)), daemon=True).start()
        elif fault in ("kill_link", "crash_link"):
            os.kill(pid, signal.SIGKILL if fault == "kill_link" else signal.SIGSEGV)
        elif fault == "system_emergency_stop":
            controller.emergency_stop("system")
        elif fault == "remote_control_off":
            controller.set_remote_control(False)
        elif fault == "slow_slider":
            controller.set_speed_slider(0.1)
        else:
            getattr(controller, fault)()

    async def fix_on_pendant(self) -> None:
        """The operator fixes one thing of the cell: the network, the link, remote control, the e-stop, the
        protective stop, the speed slider."""
        controller = self.controller
        fix = self.rng.choice(("go_online", "thaw_link", "remote_control", "release", "unlock", "slider", "all"))
        self.log.append(f"{self.step}: the operator fixes the cell: {fix}")
        if fix in ("go_online", "all"):
            controller.go_online()
        if fix in ("thaw_link", "all"):
            controller.thaw_link()
        if fix in ("remote_control", "all"):
            controller.set_remote_control(True)
        if fix in ("release", "all"):
            controller.release_emergency_stop()
            controller.power_on()
        if fix in ("unlock", "all"):
            controller.unlock_on_pendant()
        if fix in ("slider", "all"):
            controller.set_speed_slider(1.0)
        if fix == "all":
            self.faults.clear()

    async def play(self) -> None:
        self.log.append(f"{self.step}: play on the teach pendant")
        self.controller.play_on_pendant()

    async def recover(self) -> None:
        """A button of the error dialog: Reconnect, Unlock or OK."""
        buttons = [button for button in self.app.screen.query(Button) if button.id in ("reconnect", "unlock", "ok")]
        if buttons:
            await self.press_button(f"#{self.rng.choice(buttons).id}")


def process_alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie does not)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


async def ur_monkey_run(seed: int, folder: Path, loopback, steps: int) -> URMonkey:
    """``steps`` random steps of a tired operator at sampling on a UR arm (a fresh loopback controller and session in
    ``folder``); the run's record."""
    rng = random.Random(seed)
    context = wizard_context(folder)
    cell = LoopbackCell.of(cell_of(context))
    controller = loopback.start_controller(host=HOST, unlock_delay_s=UNLOCK_DELAY_S, **cell.controller_options())
    tap_earlier(cell, controller, context.session, EARLIER_TAPS, rng)
    robot = URRobot(HOST)
    context.with_cell(robot=robot, robot_name=f"UR arm at {HOST}", simulated=False, hands=None)
    try:
        app = URWatchedApp(context.cell, sampling=context.sampling, controller=controller)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            monkey = URMonkey(seed, app, pilot, robot, folder, rng, controller=controller, cell=cell)
            await until(pilot, lambda: (screen := sampling_of(app)) is not None and screen.is_mounted
                        and not screen.busy and controller.in_freedrive())
            for _ in range(steps):
                with no_frozen_loop(300.0):
                    await monkey.run_step()
                if isinstance(app.screen, StartScreen):
                    monkey.log.append(f"{monkey.step}: left sampling: the run ends")
                    break
            held = await monkey.finish()
        for path, taps in held.items():
            if not same_taps(resumed_taps(path, monkey), taps):
                monkey.fail(f"the journal {path.name} resumed does not hold the taps the wizard had")
        robot.close()
        alive = [pid for pid in monkey.link_pids if process_alive(pid)]
        if alive:
            monkey.fail(f"link processes {alive} alive after the wizard quit")
        return monkey
    finally:
        robot.close()
        controller.close()
        if not context.session.closed:
            context.session.release()


def tap_earlier(cell: LoopbackCell, controller, session, count: int, rng: random.Random) -> None:
    """``count`` taps of the fixture on the controller, each above a random point of it, journaled in ``session``
    (a session taken earlier on this arm, resumed)."""
    robot = URRobot(HOST)
    robot.connect()
    try:
        while len(session.taps) < count:
            robot.freedrive(True)
            pose = cell.above_fixture(rng, 0.005)
            pose = cell.above_table(rng, 0.005) if pose is None else pose
            controller.move_by_hand(pose)
            deadline = time.monotonic() + 5.0  # the hands take a moment; the RTDE data shows where they left it
            while not np.allclose(robot.base_T_tcp(), pose, atol=1e-6) and time.monotonic() < deadline:
                time.sleep(0.01)
            robot.freedrive(False)
            contact = robot.tap()
            if cell.on_fixture(contact.base_T_tcp_contact):
                session.record_tap(contact.base_T_tcp_contact)
        robot.freedrive(True)
    finally:
        robot.close()


def run_seed(seed: int, folder: Path, loopback) -> URMonkey:
    print(f"\nUR monkey seed {seed} (replay: UR_MONKEY_SEED={seed})")
    started = time.monotonic()
    monkey = asyncio.run(ur_monkey_run(seed, folder, loopback, STEPS))
    taps = [len(held.taps) for held in monkey.sessions.values()]
    print(f"UR monkey seed {seed}: {monkey.step} steps in {time.monotonic() - started:.0f} s, screens "
          f"{sorted(monkey.screens_seen)}, taps {taps}, programs "
          f"{[name for name, _, _ in monkey.controller.programs()].count('tap')} taps and "
          f"{[name for name, _, _ in monkey.controller.programs()].count('move')} moves of "
          f"{len(monkey.controller.programs())}, faults {monkey.faults}, F12 at most "
          f"{max(monkey.stop_keys_s, default=0.0):.2f} s")
    return monkey


@pytest.mark.parametrize("seed", CASES)
def test_a_tired_operator_on_a_ur_arm_moves_nothing_after_stop_or_an_error_and_loses_no_tap(tmp_path, monkeypatch,
                                                                                             loopback, seed):
    monkeypatch.chdir(tmp_path)
    run_seed(int(os.environ.get("UR_MONKEY_SEED", seed)), tmp_path, loopback)


@pytest.mark.skipif(EXTRA_RUNS == 0, reason="UR_MONKEY_RUNS=N runs N more random seeds")
def test_more_tired_operators_on_a_ur_arm(tmp_path, monkeypatch, loopback):
    monkeypatch.chdir(tmp_path)
    for run in range(EXTRA_RUNS):
        seed = random.SystemRandom().randrange(1 << 31)
        run_seed(seed, tmp_path / str(run), loopback)
