"""What the wizard's phases hand each other. ``Cell`` is the robot cell and its folders (immutable: switching the
robot makes a new one); the rest are the values one step returns and the next takes: the start screen's choice
(``NewSession`` or ``Resumed``), a saved tip calibration, and ``Sampling`` (the open session with its fixture and
tip calibration) that sampling, solve and results work on. Screens hold no geometry of their own."""

from dataclasses import dataclass
from pathlib import Path

from fixwizard.calibration.store import TipCalibration
from fixwizard.fixture import Fixture
from fixwizard.robot.base import Robot
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.workflow.session import SamplingSession


@dataclass(frozen=True)
class Cell:
    """The robot cell of one wizard run. ``hands`` is set only for a simulated cell (it stands in for the
    operator's hands in freedrive); ``simulated`` marks everything shown and written as SIMULATED."""

    robot: Robot
    robot_name: str
    simulated: bool
    hands: SimulatedHands | None = None
    fixtures_dir: Path = Path("fixtures")
    calibrations_dir: Path = Path("calibrations")
    sessions_dir: Path = Path("sessions")
    reports_dir: Path = Path("reports")
    max_cells: float = 1e7

    def simulated_hands(self) -> SimulatedHands:
        """The simulated hands; only keys of a simulated cell call this (they are disabled on a real robot)."""
        if self.hands is None:
            raise RuntimeError("a real robot has no simulated hands")
        return self.hands


@dataclass(frozen=True)
class SavedCalibration:
    """A tip calibration and the file it is saved in (a session header names it, so that it can be resumed)."""

    calibration: TipCalibration
    path: Path


@dataclass(frozen=True)
class Sampling:
    """An open sampling session with the fixture and tip calibration it records taps of."""

    session: SamplingSession
    fixture: Fixture
    tip: SavedCalibration

    @property
    def calibration(self) -> TipCalibration:
        return self.tip.calibration


@dataclass(frozen=True)
class NewSession:
    """The start screen's choice of a new session: the fixture and a stored tip calibration, or None to calibrate
    the tip first (continuing the unfinished calibration journaled at ``unfinished_tip`` when given)."""

    fixture: Fixture
    tip: SavedCalibration | None
    unfinished_tip: Path | None = None


@dataclass(frozen=True)
class Resumed:
    """An unfinished session reopened, and what was opened in words."""

    sampling: Sampling
    opened: str


StartChoice = NewSession | Resumed
