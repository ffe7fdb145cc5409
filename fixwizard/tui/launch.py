"""Starting the wizard: the context for the simulated demo cell or a UR arm, switching between them, and the
session to resume."""

from pathlib import Path

from fixwizard.demo import demo_cell
from fixwizard.robot.base import Robot
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.tui.context import WizardContext
from fixwizard.tui.start.sessions import newest_unfinished

# Seconds per simulated tap or move: slow enough to watch the progress, fast enough not to bore.
SIMULATED_PACE_S = 0.05


def simulated_context(seed: int = 0, pace_s: float = SIMULATED_PACE_S, folder: Path = Path(".")) -> WizardContext:
    """The bundled demo cell (fixture at a hidden pose drawn from ``seed``) with simulated hands; the
    fixtures, calibrations, sessions and reports folders under ``folder``."""
    cell, name, hands = _simulated_cell(seed, pace_s)
    return WizardContext(robot=cell, robot_name=name, simulated=True, hands=hands, **_folders(folder))


def ur_context(host: str, folder: Path = Path(".")) -> WizardContext:
    """A Universal Robots arm at ``host``; the app connects to it when it starts."""
    robot, name = _ur_arm(host)
    return WizardContext(robot=robot, robot_name=name, simulated=False, **_folders(folder))


def use_simulated_cell(context: WizardContext, seed: int = 0, pace_s: float = SIMULATED_PACE_S) -> None:
    """Make the demo cell of ``seed`` the context's robot, with simulated hands (the old robot is closed)."""
    context.robot.close()
    context.robot, context.robot_name, context.hands = _simulated_cell(seed, pace_s)
    context.simulated = True


def use_ur_arm(context: WizardContext, host: str) -> None:
    """Make the UR arm at ``host`` the context's robot (the old robot is closed); connecting comes next."""
    context.robot.close()
    context.robot, context.robot_name = _ur_arm(host)
    context.simulated, context.hands = False, None


def session_to_resume(context: WizardContext, requested: str) -> Path:
    """The session ``--resume`` asks for: the newest unfinished one (empty string) or the given path."""
    return newest_unfinished(context.sessions_dir) if requested == "" else Path(requested).expanduser()


def _simulated_cell(seed: int, pace_s: float) -> tuple[SimulatedCell, str, SimulatedHands]:
    """The demo cell of ``seed`` moving at ``pace_s`` per motion, its name, and the hands that stand in for
    the operator's."""
    cell = demo_cell(seed)
    cell.pace_s = pace_s
    return cell, f"SIMULATED demo cell (seed {seed})", SimulatedHands(cell, seed=seed)


def _ur_arm(host: str) -> tuple[Robot, str]:
    """The (not yet connected) UR arm at ``host`` and its name; ur_rtde is imported only when one is used."""
    from fixwizard.robot.ur import URRobot

    return URRobot(host), f"UR arm at {host}"


def _folders(folder: Path) -> dict[str, Path]:
    return {"fixtures_dir": folder / "fixtures", "calibrations_dir": folder / "calibrations",
            "sessions_dir": folder / "sessions", "reports_dir": folder / "reports"}
