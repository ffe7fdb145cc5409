"""Starting the wizard: the context for the simulated demo cell or a UR arm, and the session to resume."""

from pathlib import Path

from fixwizard.demo import demo_cell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.tui.context import WizardContext
from fixwizard.tui.sessions import newest_unfinished

# Seconds per simulated tap or move: slow enough to watch the progress, fast enough not to bore.
SIMULATED_PACE_S = 0.05


def simulated_context(seed: int = 0, pace_s: float = SIMULATED_PACE_S, folder: Path = Path(".")) -> WizardContext:
    """The bundled demo cell (fixture at a hidden pose drawn from ``seed``) with simulated hands; the
    fixtures, calibrations, sessions and reports folders under ``folder``."""
    cell = demo_cell(seed)
    cell.pace_s = pace_s
    return WizardContext(robot=cell, robot_name=f"SIMULATED demo cell (seed {seed})", simulated=True,
                         hands=SimulatedHands(cell, seed=seed), **_folders(folder))


def ur_context(host: str, folder: Path = Path(".")) -> WizardContext:
    """A Universal Robots arm at ``host``; the app connects to it when it starts."""
    from fixwizard.robot.ur import URRobot

    return WizardContext(robot=URRobot(host), robot_name=f"UR arm at {host}", simulated=False, **_folders(folder))


def session_to_resume(context: WizardContext, requested: str | None) -> Path | None:
    """The session ``--resume`` asks for: none, the newest unfinished one (empty string) or the given path."""
    if requested is None:
        return None
    return newest_unfinished(context.sessions_dir) if requested == "" else Path(requested)


def _folders(folder: Path) -> dict[str, Path]:
    return {"fixtures_dir": folder / "fixtures", "calibrations_dir": folder / "calibrations",
            "sessions_dir": folder / "sessions", "reports_dir": folder / "reports"}
