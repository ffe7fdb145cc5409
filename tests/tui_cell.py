"""Test helpers for the wizard's sampling, solve and results screens: the demo cell with its hidden truth, a
tip calibration taken from that truth, what the wizard's flow would hand those screens, a solver that stays solving,
and a small app hosting one screen."""

import dataclasses
import datetime as dt
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from textual.app import App
from textual.screen import Screen

from fixwizard.calibration.residuals import ResidualStats
from fixwizard.calibration.store import TipCalibration
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.demo import demo_cell
from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import rotation_angle_rad, transform_points
from fixwizard.report import Report
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.solver.search import SearchProgress
from fixwizard.solver.solve import Solution
from fixwizard.tui.app import CSS_FILE
from fixwizard.tui.cell import Cell, Sampling, SavedCalibration
from fixwizard.tui.results.screen import ResultsScreen
from fixwizard.tui.sampling.screen import SamplingScreen
from fixwizard.tui.solve.screen import SolveScreen
from fixwizard.tui.start.screen import StartScreen
from fixwizard.workflow.session import SamplingSession
from fixwizard.workflow.solver_process import Progress, SolverProcess

CELL_SEED = 0
HANDS_SEED = 1
# The cell's forward-kinematics error bound (0.3 mm) with a margin, as a tip calibration would propose.
SAMPLE_BOUND_M = 0.00035
TEST_MAX_CELLS = 8e6
ROBOT_NAME = "simulated cell"  # the robot the test cell is named and its tip calibrated on


def truth_calibration(cell: SimulatedCell) -> TipCalibration:
    """A tip calibration holding the cell's hidden tip and ball, as if calibrated perfectly."""
    no_residuals = ResidualStats(0.0, 0.0)
    return TipCalibration(
        name="truth", created=dt.datetime.now(dt.UTC).isoformat(), robot=ROBOT_NAME,
        tcp_p_tip_m=cell.truth.tcp_p_tip_m, ball_diameter_m=cell.truth.ball_diameter_m,
        sample_bound_m=SAMPLE_BOUND_M, sample_bound_reason="the simulated cell's error bound with a margin",
        base_T_table=np.eye(4), pivot_tcp_p_tip_m=cell.truth.tcp_p_tip_m, pivot_residuals=no_residuals,
        table_residuals=no_residuals, tip_residuals=no_residuals, tip_condition_number=1.0,
        tip_standard_error_m=np.zeros(3), steps={})


@dataclass
class WizardParts:
    """What the wizard's flow hands the sampling, solve and results screens, as a test sets it up: the cell, the
    session with its fixture and tip calibration, and the fixture's solver process (started on first use). Tests
    change a part (``dataclasses.replace`` for the cell) before making a screen."""

    cell: Cell
    session: SamplingSession
    fixture: Fixture
    calibration: TipCalibration
    calibration_path: Path
    solution: Solution | None = None  # a test's own solve, for the results screen
    _solver: SolverProcess | None = None

    @property
    def robot(self):
        return self.cell.robot

    @property
    def hands(self) -> SimulatedHands | None:
        return self.cell.hands

    @property
    def reports_dir(self) -> Path:
        return self.cell.reports_dir

    @property
    def max_cells(self) -> float:
        return self.cell.max_cells

    def with_cell(self, **changes) -> None:
        self.cell = dataclasses.replace(self.cell, **changes)

    @property
    def sampling(self) -> Sampling:
        return Sampling(self.session, self.fixture, SavedCalibration(self.calibration, self.calibration_path))

    def solver(self) -> SolverProcess:
        """The solver process of the fixture, as the wizard's flow owns it."""
        if self._solver is None or self._solver.fixture is not self.fixture:
            self._solver = SolverProcess(self.fixture)
        return self._solver

    def sampling_screen(self, opened: str = "") -> SamplingScreen:
        return SamplingScreen(self.cell, self.sampling, self.solver(), opened)

    def solve_screen(self, solver: SolverProcess | None = None) -> SolveScreen:
        return SolveScreen(self.cell, self.sampling, solver or self.solver())

    def results_screen(self) -> ResultsScreen:
        assert self.solution is not None, "solve first"
        return ResultsScreen(self.cell, self.sampling, self.solution)


def start_fixture(app: App):
    """The fixture loaded on the start screen shown, if any."""
    return app.screen.fixture if isinstance(app.screen, StartScreen) else None


def sampling_of(app: App) -> SamplingScreen | None:
    """The sampling screen on the app's stack, if any."""
    return next((screen for screen in app.screen_stack if isinstance(screen, SamplingScreen)), None)


def wizard_context(folder: Path, cell_seed: int = CELL_SEED, max_cells: float = TEST_MAX_CELLS,
                   cell: SimulatedCell | None = None) -> WizardParts:
    """A simulated demo cell (connected; or ``cell``), the operator's hands, a truth calibration and a new
    session in ``folder``."""
    cell = demo_cell(cell_seed) if cell is None else cell
    cell.connect()
    calibration = truth_calibration(cell)
    session = SamplingSession.create(folder / "sessions" / "demo.jsonl",
                                     {"mesh": str(cell.fixture.path), "units": cell.fixture.units},
                                     {"tcp_p_tip_m": calibration.tcp_p_tip_m.tolist(),
                                      "ball_diameter_m": calibration.ball_diameter_m,
                                      "sample_bound_m": calibration.sample_bound_m}, robot="simulated")
    wizard_cell = Cell(robot=cell, robot_name=ROBOT_NAME, simulated=True,
                       hands=SimulatedHands(cell, seed=HANDS_SEED), reports_dir=folder / "reports", max_cells=max_cells)
    return WizardParts(wizard_cell, session, cell.fixture, calibration, folder / "calibrations" / "truth.yaml")


def symmetric_cell() -> SimulatedCell:
    """A cell holding a plain brick: spread taps cannot tell its 180-degree turns apart."""
    from shapes import as_fixture

    return SimulatedCell.with_fixture(as_fixture("brick"), seed=CELL_SEED)


def cell_of(context: WizardParts) -> SimulatedCell:
    return context.hands.cell


def spread_taps(cell: SimulatedCell, count: int, seed: int = HANDS_SEED) -> np.ndarray:
    """Ball centres (count, 3, base frame, m) of ``count`` spread taps, computed with the true tip."""
    hands = SimulatedHands(cell, seed=seed)
    poses = []
    for index in range(count):
        hands.near_spread_point(index)
        poses.append(cell.tap().base_T_tcp_contact)
    return ball_centres_m(np.array(poses), cell.truth.tcp_p_tip_m)


def record_spread_taps(context: WizardParts, count: int) -> None:
    """Tap ``count`` spread points without the UI and journal them in the context's session."""
    hands = context.hands
    for index in range(count):
        hands.near_spread_point(index)
        context.session.record_tap(cell_of(context).tap().base_T_tcp_contact)


def point_above_fixture_m(context: WizardParts, height_m: float) -> np.ndarray:
    """A ball centre (base frame, m) ``height_m`` above the fixture's highest vertex."""
    cell = cell_of(context)
    base_p_vertices = cell.fixture.mesh.vertices @ cell.truth.base_T_cad[:3, :3].T + cell.truth.base_T_cad[:3, 3]
    return base_p_vertices[np.argmax(base_p_vertices[:, 2])] + [0.0, 0.0, height_m]


def bounds_contain(report: Report, cell: SimulatedCell, base_T_cad: np.ndarray) -> bool:
    """Whether a loaded report's guaranteed bounds hold ``base_T_cad``: CAD origin, rotation and every vertex
    of the fixture within their bounds of the centre pose (1 nm and 1e-9 deg of float slack)."""
    centre = report.center_base_T_cad
    vertices = cell.fixture.mesh.vertices
    displacement_m = np.linalg.norm(transform_points(base_T_cad, vertices) - transform_points(centre, vertices), axis=1)
    return bool(np.linalg.norm(base_T_cad[:3, 3] - centre[:3, 3]) <= report.position_bound_m + 1e-9
                and np.degrees(rotation_angle_rad(centre[:3, :3].T @ base_T_cad[:3, :3]))
                <= report.rotation_bound_deg + 1e-9
                and displacement_m.max() <= report.max_point_displacement_m + 1e-9)


class PausedSolver:
    """The solver process's side the solve screen uses, paused after one search level: the solve runs on."""

    latest_request = 1

    def submit(self, request, on_event):  # answers come from another thread, as the reader's do
        threading.Thread(target=on_event, args=(Progress(search=SearchProgress(
            rotation_level=3, position_level=4, evaluated=663_552, survivors=41_317, elapsed_s=2.0)),)).start()
        return self.latest_request

    def stop(self):
        self.latest_request = 0


class ScreenHost(App):
    """An app that shows one screen on start and keeps what it dismisses with in ``results`` and the errors it is
    asked to show in ``errors``; like the wizard, with its style sheet and without the command palette."""

    CSS_PATH = CSS_FILE
    ENABLE_COMMAND_PALETTE = False

    def __init__(self, make_screen: Callable[[], Screen]) -> None:
        super().__init__()
        self.make_screen = make_screen
        self.results: list = []
        self.errors: list[Exception] = []  # what the wizard would show in its error dialog (``show_error``)
        self.robot_status = None  # the wizard's latest robot status: unknown here
        self.stopped = False  # the wizard is not STOPPED here
        self.motion_cancels: set[threading.Event] = set()  # what STOP would set (``cancel_on_stop``)

    def cancel_on_stop(self, cancel: threading.Event) -> None:
        self.motion_cancels.add(cancel)

    def forget_cancel(self, cancel: threading.Event) -> None:
        self.motion_cancels.discard(cancel)

    def show_error(self, error: Exception, reconnect: bool = False) -> None:
        self.errors.append(error)

    def on_mount(self) -> None:
        self.push_screen(self.make_screen(), self.results.append)
