"""Fine tip from taps on the table at varied tilts.

Every ball centre lies on the table plane: ``n . (base_R_tcp_i tcp_p_tip + base_p_tcp_i) = k`` with the
known table normal ``n``. Unknowns: the tip (3) and the plane offset ``k`` (m), found by linear least
squares on the taps that belong (see ``robust``).

Conditioning: only the variation of ``u_i = base_R_tcp_i^T n`` (the table normal seen from the tool)
determines the tip. The singular values of the deviations ``u_i - mean(u)``, divided by sqrt(N), are the
RMS spread of the tilts along each tool direction (dimensionless; about sin(tilt) sideways, the variation
of cos(tilt) along the tool axis); a tap error of e mm moves the tip by about e / spread / sqrt(N) mm. The
condition number is the largest spread over the smallest.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.residuals import ExcludedTap, ResidualStats
from fixwizard.calibration.robust import robust_inliers

MIN_TILTED_TAPS = 8
MIN_SPREAD = 0.02


@dataclass(frozen=True, eq=False)
class FineTipFit:
    """Tip (m, flange frame) and plane offset k (m) fitted to the inliers; every tap's residual (m, signed,
    along the table normal), the inlier mask and excluded taps; residual statistics of the inliers; the
    tilt spread (3, descending), its condition number and the tip's standard error (m, per flange axis)."""

    tcp_p_tip_m: np.ndarray
    table_offset_m: float
    residuals_m: np.ndarray
    inliers: np.ndarray
    excluded: tuple[ExcludedTap, ...]
    stats: ResidualStats
    spread: np.ndarray
    condition_number: float
    standard_error_m: np.ndarray


def fit_fine_tip(base_T_tcp: np.ndarray, base_n_table: np.ndarray, files: Sequence[str] = ()) -> FineTipFit:
    """Fine tip from tilted taps (N, 4, 4) on the table with unit normal ``base_n_table`` (base frame)."""
    count = len(base_T_tcp)
    if count < MIN_TILTED_TAPS:
        raise CalibrationError(f"the fine tip needs at least {MIN_TILTED_TAPS} tilted taps on the table; got {count}")
    tcp_n_table = np.einsum("nji,j->ni", base_T_tcp[:, :3, :3], base_n_table)
    design = np.column_stack([tcp_n_table, -np.ones(count)])
    target = -(base_T_tcp[:, :3, 3] @ base_n_table)
    _check_spread(tcp_n_table, "the tilted taps")

    def fit(indices: np.ndarray) -> np.ndarray:
        return np.linalg.lstsq(design[indices], target[indices], rcond=None)[0]

    inliers, excluded = robust_inliers(count, 4, fit, lambda solution: design @ solution - target, "tilted taps",
                                       files)
    spread = _check_spread(tcp_n_table[inliers], "the tilted taps left after excluding those that do not belong")
    solution = fit(np.flatnonzero(inliers))
    residuals_m = design @ solution - target
    variance = residuals_m[inliers] @ residuals_m[inliers] / (inliers.sum() - 4)
    covariance = variance * np.linalg.inv(design[inliers].T @ design[inliers])
    return FineTipFit(solution[:3], float(solution[3]), residuals_m, inliers, excluded,
                      ResidualStats.of(residuals_m[inliers]), spread, float(spread[0] / spread[-1]),
                      np.sqrt(np.diag(covariance)[:3]))


def _check_spread(tcp_n_table: np.ndarray, which: str) -> np.ndarray:
    """Tilt spread (3, descending) of the table normals seen from the tool; refuses one too small."""
    deviations = tcp_n_table - tcp_n_table.mean(axis=0)
    spread = np.linalg.svd(deviations, compute_uv=False) / np.sqrt(len(tcp_n_table))
    if spread[-1] < MIN_SPREAD:
        raise CalibrationError(
            f"{which} do not vary their tilt enough to determine the tip (spread {spread[-1]:.3f} in the weakest "
            f"direction, at least {MIN_SPREAD} needed): tap the table at tilts from 10 to 30 degrees, each tilt "
            "in at least three directions around the tool axis")
    return spread
