"""Turn recorded flange poses into measured ball centres (the POINTS of ``fixwizard solve``)."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fixwizard.calibration.store import load_calibration
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.errors import InputError
from fixwizard.geometry.se3 import read_pose_dir, read_pose_file


@dataclass(frozen=True)
class Tip:
    """Ball centre in the flange frame (m); diameter and sample bound (m) when a calibration gives them."""

    tcp_p_tip_m: np.ndarray
    ball_diameter_m: float | None = None
    sample_bound_m: float | None = None


def load_tip(path: str | Path) -> Tip:
    """Tip from a ``.pose`` file (its translation) or a ``fixwizard.tip/1`` calibration YAML."""
    path = Path(path)
    if path.suffix.lower() == ".pose":
        return Tip(read_pose_file(path)[:3, 3])
    if path.suffix.lower() in (".yaml", ".yml"):
        calibration = load_calibration(path)
        return Tip(np.asarray(calibration.tcp_p_tip_m, float), calibration.ball_diameter_m,
                   calibration.sample_bound_m)
    raise InputError(f"{path} is neither a .pose file nor a tip calibration (.yaml); give one of those")


def import_pose_dir(directory: str | Path, tip: Tip) -> tuple[list[Path], np.ndarray]:
    """Pose files of a folder (natural order) and their ball centres (N, 3) in metres."""
    paths, base_T_tcp = read_pose_dir(directory)
    return paths, ball_centres_m(base_T_tcp, tip.tcp_p_tip_m)
