"""Shared helpers of the tool-tip calibration tests: the real data folder and a simulated tapping robot."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.calibration.plans import grid_hover_poses, tilted_hover_poses
from fixwizard.calibration.taps import PoseSeries, ball_centres_m
from fixwizard.geometry.se3 import make_transform

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "matlab-logo"

TCP_P_TIP_M = np.array([0.0012, -0.0008, 0.0495])
BASE_T_TABLE = make_transform(Rotation.from_rotvec([0.02, -0.01, 0.7]), [0.4, -0.1, 0.02])


def real_calib_dir() -> Path:
    """The ``calib`` folder of the real MATLAB-logo data; skips the test when the data is absent."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"the real data folder {REAL_DATA} is absent (it lives next to the project, not in it)")
    return REAL_DATA / "calib"


def tap(hover_base_T_tcp: np.ndarray, noise_m: float = 0.0, seed: int = 0,
        tcp_p_tip_m: np.ndarray = TCP_P_TIP_M) -> np.ndarray:
    """Flange poses after moving each hover pose along tool z until the ball centre (at ``tcp_p_tip_m``)
    reaches the table plane of ``BASE_T_TABLE`` (z = 0), plus uniform noise in [-noise_m, noise_m] along
    the table normal."""
    base_n_table = BASE_T_TABLE[:3, 2]
    heights_m = (ball_centres_m(hover_base_T_tcp, tcp_p_tip_m) - BASE_T_TABLE[:3, 3]) @ base_n_table
    travel_m = heights_m / -(hover_base_T_tcp[:, :3, 2] @ base_n_table)
    noise = np.random.default_rng(seed).uniform(-noise_m, noise_m, len(hover_base_T_tcp))
    tapped = hover_base_T_tcp.copy()
    tapped[:, :3, 3] += travel_m[:, None] * hover_base_T_tcp[:, :3, 2] + noise[:, None] * base_n_table
    return tapped


def pivot_poses(rotvecs_rad: np.ndarray, noise_m: float = 0.0, seed: int = 0) -> np.ndarray:
    """Flange poses with the tool pointing down, turned by ``rotvecs_rad`` (N, 3) about the ball centre held
    on one point, plus uniform noise in [-noise_m, noise_m] on every flange coordinate."""
    base_p_pivot = np.array([0.4, -0.1, 0.03])
    base_R_tcp = (Rotation.from_rotvec(rotvecs_rad) * Rotation.from_rotvec([np.pi, 0, 0])).as_matrix()
    noise = np.random.default_rng(seed).uniform(-noise_m, noise_m, (len(base_R_tcp), 3))
    return np.array([make_transform(rotation, base_p_pivot - rotation @ TCP_P_TIP_M + offset)
                     for rotation, offset in zip(base_R_tcp, noise, strict=True)])


def abc_taps() -> np.ndarray:
    """Taps at A (x = 80 mm), B (the table origin) and C (y = 60 mm) of BASE_T_TABLE, tool straight down."""
    corner = grid_hover_poses(BASE_T_TABLE, TCP_P_TIP_M, 1, 1, 0.0, 0.0)[0]
    return np.array([make_transform(corner[:3, :3], corner[:3, 3] + BASE_T_TABLE[:3, :3] @ offset)
                     for offset in ([0.08, 0, 0], [0, 0, 0], [0, 0.06, 0])])


def synthetic_steps() -> dict[str, PoseSeries]:
    """Every step of a calibration of TCP_P_TIP_M on the table BASE_T_TABLE, with tenth-millimetre noise."""
    return {"pivot": PoseSeries(pivot_poses(np.radians(25) * np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0],
                                                                           [-0.7, -0.7, 0]]), 0.05e-3)),
            "table": PoseSeries(tap(grid_hover_poses(BASE_T_TABLE, TCP_P_TIP_M, 5, 5, 0.01, 0.01), 0.03e-3)),
            "tilted": PoseSeries(tap(tilted_hover_poses(BASE_T_TABLE, TCP_P_TIP_M, 0.005, 0.01), 0.1e-3, seed=1)),
            "table_coarse": PoseSeries(abc_taps())}
