"""Coarse tip by pivoting: flange poses that turn the tool about one fixed point give the ball centre.

For every pose ``base_T_tcp_i = (R_i, t_i)`` the ball centre sits on the pivot point:
``R_i tcp_p_tip + t_i = base_p_pivot``. Stacked, ``[R_i, -I] [tcp_p_tip; base_p_pivot] = -t_i`` is solved
by linear least squares.

Only the differences between the rotations determine the tip: rotations about one axis leave the tip
free along that axis, small ones amplify every millimetre of error. The singular values of the stacked
deviations ``R_i - mean(R)`` measure this; ``2 asin(s / sqrt(N))`` turns each into an equivalent tilt
(for two poses exactly the angle between them). The weakest must reach ``MIN_TILT_DEG``.
"""

from dataclasses import dataclass

import numpy as np

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.residuals import ResidualStats

MIN_POSES = 3
MIN_TILT_DEG = 10.0


@dataclass(frozen=True, eq=False)
class PivotFit:
    """Tip in the flange frame and pivot point in the base frame (m); per pose, the distance (m) of its ball
    centre from the pivot point; the equivalent tilts (deg, descending) of the pose spread."""

    tcp_p_tip_m: np.ndarray
    base_p_pivot_m: np.ndarray
    residuals_m: np.ndarray
    stats: ResidualStats
    tilt_spread_deg: np.ndarray


def fit_pivot(base_T_tcp: np.ndarray) -> PivotFit:
    """Least-squares tip and pivot point from N >= 3 flange poses (N, 4, 4) about one fixed point."""
    count = len(base_T_tcp)
    if count < MIN_POSES:
        raise CalibrationError(f"a pivot calibration needs at least {MIN_POSES} flange poses with the ball on one "
                               f"fixed point; got {count}")
    base_R_tcp, base_p_tcp = base_T_tcp[:, :3, :3], base_T_tcp[:, :3, 3]
    tilt_spread_deg = _tilt_spread_deg(base_R_tcp)
    if tilt_spread_deg[-1] < MIN_TILT_DEG:
        raise CalibrationError(
            f"the pivot poses cannot determine the tip: in their weakest direction the tool turned by only "
            f"{tilt_spread_deg[-1]:.1f} degrees (at least {MIN_TILT_DEG:.0f} needed). Keep the ball on the same "
            "point and tilt the tool in at least two different directions by 20 degrees or more (for example "
            "once forwards and once sideways), then record the poses again.")
    design = np.concatenate([base_R_tcp, np.broadcast_to(-np.eye(3), base_R_tcp.shape)], axis=2).reshape(-1, 6)
    solution = np.linalg.lstsq(design, -base_p_tcp.reshape(-1), rcond=None)[0]
    residuals_m = np.linalg.norm((design @ solution + base_p_tcp.reshape(-1)).reshape(-1, 3), axis=1)
    return PivotFit(solution[:3], solution[3:], residuals_m, ResidualStats.of(residuals_m), tilt_spread_deg)


def _tilt_spread_deg(base_R_tcp: np.ndarray) -> np.ndarray:
    """Equivalent tilt angles (deg, descending) of the rotations' spread along the three directions."""
    deviations = (base_R_tcp - base_R_tcp.mean(axis=0)).reshape(-1, 3)
    singular = np.linalg.svd(deviations, compute_uv=False) / np.sqrt(len(base_R_tcp))
    return np.degrees(2 * np.arcsin(np.minimum(singular, 1.0)))
