"""What the wizard's screens share: the robot, the chosen fixture and tip calibration, the open sampling
session and the latest solution. Screens read and fill it; they hold no geometry of their own."""

from dataclasses import dataclass
from pathlib import Path

from fixwizard.calibration.store import TipCalibration
from fixwizard.fixture import Fixture
from fixwizard.robot.base import Robot
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.solver.solve import Solution
from fixwizard.workflow.session import SamplingSession
from fixwizard.workflow.solver_process import SolverProcess


@dataclass
class WizardContext:
    """State of one wizard run. ``hands`` is set only for a simulated cell (it stands in for the operator's
    hands in freedrive); ``simulated`` marks everything shown and written as SIMULATED. ``calibration_path`` is
    the saved file of ``calibration`` (a session header names it, so that the session can be resumed). ``solver``:
    the worker process that solves for ``fixture`` (``solver_process``)."""

    robot: Robot
    robot_name: str
    simulated: bool
    hands: SimulatedHands | None = None
    fixtures_dir: Path = Path("fixtures")
    calibrations_dir: Path = Path("calibrations")
    sessions_dir: Path = Path("sessions")
    reports_dir: Path = Path("reports")
    fixture: Fixture | None = None
    calibration: TipCalibration | None = None
    calibration_path: Path | None = None
    session: SamplingSession | None = None
    solution: Solution | None = None
    report_path: Path | None = None
    max_cells: float = 1e7
    solver: SolverProcess | None = None

    def solver_process(self) -> SolverProcess:
        """The solver process holding ``fixture``: started on first use, replaced when the fixture changes."""
        if self.solver is not None and self.solver.fixture is not self.fixture:
            self.solver.close()
            self.solver = None
        if self.solver is None:
            self.solver = SolverProcess(self.fixture)
        return self.solver
