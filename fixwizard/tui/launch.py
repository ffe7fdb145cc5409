"""Starting the wizard: the cell of the simulated demo or of a UR arm, switching between them, and the session to
resume."""

import contextlib
import ipaddress
import os
import re
from dataclasses import replace
from pathlib import Path
from typing import TypedDict

from fixwizard.demo import demo_cell
from fixwizard.errors import InputError, quoted
from fixwizard.robot.base import Robot
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.tui.cell import Cell
from fixwizard.tui.start.sessions import newest_unfinished

# Seconds per simulated tap or move: slow enough to watch the progress, fast enough not to bore.
SIMULATED_PACE_S = 0.05
_HOST_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?")  # one part of a host name (RFC 1123)


def simulated_cell(seed: int = 0, pace_s: float = SIMULATED_PACE_S, folder: Path = Path(".")) -> Cell:
    """The bundled demo cell (fixture at a hidden pose drawn from ``seed``) with simulated hands; the
    fixtures, calibrations, sessions and reports folders under ``folder``."""
    robot, name, hands = _simulated_cell(seed, pace_s)
    return Cell(robot=robot, robot_name=name, simulated=True, hands=hands, **_folders(folder))


def robot_host(text: str) -> str:
    """``text`` as a robot's address: an IP address or a host name; InputError with an example otherwise (a
    mistyped address, 999.1.1.1, or anything pasted with it)."""
    host = text.strip()
    with contextlib.suppress(ValueError):
        return str(ipaddress.ip_address(host))
    labels = host.split(".")
    if len(host) <= 253 and all(_HOST_LABEL.fullmatch(label) for label in labels) and \
            not all(label.isdigit() for label in labels):
        return host
    raise InputError(f"{quoted(text)} is not the address of a robot: type its IP address (e.g. 192.168.0.10) or "
                     "its host name")


def ur_cell(host: str, folder: Path = Path(".")) -> Cell:
    """A Universal Robots arm at ``host``; the app connects to it when it starts."""
    robot, name = _ur_arm(robot_host(host))
    return Cell(robot=robot, robot_name=name, simulated=False, **_folders(folder))


def switch_to_simulated(cell: Cell, seed: int = 0, pace_s: float = SIMULATED_PACE_S) -> Cell:
    """``cell`` with the demo cell of ``seed`` as its robot, with simulated hands (the old robot is closed)."""
    cell.robot.close()
    robot, name, hands = _simulated_cell(seed, pace_s)
    return replace(cell, robot=robot, robot_name=name, hands=hands, simulated=True)


def switch_to_ur_arm(cell: Cell, host: str) -> Cell:
    """``cell`` with the UR arm at ``host`` as its robot (the old robot is closed); connecting comes next. A host
    that is no address is refused before anything changes."""
    host = robot_host(host)
    cell.robot.close()
    robot, name = _ur_arm(host)
    return replace(cell, robot=robot, robot_name=name, simulated=False, hands=None)


def session_to_resume(cell: Cell, requested: str) -> Path:
    """The session ``--resume`` asks for: the newest unfinished one (empty string) or the given path."""
    # an unknown ~user stays as typed, to be said missing (Path.expanduser raises)
    return newest_unfinished(cell.sessions_dir) if requested == "" else Path(os.path.expanduser(requested))


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


class _Folders(TypedDict):
    fixtures_dir: Path
    calibrations_dir: Path
    sessions_dir: Path
    reports_dir: Path


def _folders(folder: Path) -> _Folders:
    return {"fixtures_dir": folder / "fixtures", "calibrations_dir": folder / "calibrations",
            "sessions_dir": folder / "sessions", "reports_dir": folder / "reports"}
