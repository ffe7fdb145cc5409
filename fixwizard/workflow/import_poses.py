"""Turn recorded flange poses into measured ball centres (the POINTS of ``fixwizard solve``)."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fixwizard.calibration.store import load_calibration
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.errors import InputError
from fixwizard.geometry.se3 import read_pose_dir, read_pose_file
from fixwizard.units import MAX_REACH_M, MAX_TOOL_M


@dataclass(frozen=True)
class Tip:
    """Ball centre in the flange frame (m); diameter and sample bound (m) when a calibration gives them."""

    tcp_p_tip_m: np.ndarray
    ball_diameter_m: float | None = None
    sample_bound_m: float | None = None


def load_tip(path: str | Path) -> Tip:
    """Tip from a ``.pose`` file (its translation) or a ``fixwizard.tip/1`` calibration YAML; ``InputError`` for a
    ball farther from the flange than any tool holds it (``MAX_TOOL_M``: millimetres read as metres)."""
    path = Path(path)
    if path.suffix.lower() == ".pose":
        tip = Tip(read_pose_file(path)[:3, 3])
    elif path.suffix.lower() in (".yaml", ".yml"):
        calibration = load_calibration(path)
        tip = Tip(np.asarray(calibration.tcp_p_tip_m, float), calibration.ball_diameter_m,
                  calibration.sample_bound_m)
    else:
        raise InputError(f"{path} is neither a .pose file nor a tip calibration (.yaml); give one of those")
    with np.errstate(over="ignore"):  # an absurd tip is inf m long
        length_m = float(np.linalg.norm(tip.tcp_p_tip_m))
    if not length_m <= MAX_TOOL_M:
        raise InputError(f"{path} puts the ball {length_m:.3g} m from the flange, farther than any tool holds it: "
                         "a tip holds metres (as UR writes them); if it is in millimetres, divide x y z by 1000")
    return tip


def import_pose_dir(directory: str | Path, tip: Tip,
                    tip_path: str | Path | None = None) -> tuple[list[Path], np.ndarray]:
    """Pose files of a folder (natural order) and their ball centres (N, 3) in metres; ``tip_path``, the tip's own
    .pose file, is no tap when it lies in the folder. ``InputError`` for a flange farther from the base than any
    robot reaches (poses in millimetres: .pose files are in metres)."""
    paths, base_T_tcp = read_pose_dir(directory)
    if tip_path is not None:
        taps = np.array([path.resolve() != Path(tip_path).resolve() for path in paths])
        if not np.any(taps):
            raise InputError(f"the only *.pose file in {directory} is the tip's; give the folder of the tapped poses")
        paths, base_T_tcp = [path for path, tap in zip(paths, taps, strict=True) if tap], base_T_tcp[taps]
    reach_m = np.linalg.norm(base_T_tcp[:, :3, 3], axis=1)
    if np.any(reach_m > MAX_REACH_M):
        far = int(np.argmax(reach_m))
        raise InputError(f"{paths[far].name} puts the flange {reach_m[far]:.3g} m from the robot base, beyond any "
                         "robot's reach: .pose files hold metres and radians (as UR writes them); these look like "
                         "millimetres, so divide their x y z by 1000")
    return paths, ball_centres_m(base_T_tcp, tip.tcp_p_tip_m)
