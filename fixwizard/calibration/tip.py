"""Fine tip from taps on the table at varied tilts.

Every ball centre lies on the table plane: ``n . (base_R_tcp_i tcp_p_tip + base_p_tcp_i) = k`` with the
known table normal ``n``. Unknowns: the tip (3) and the plane offset ``k`` (m), found by linear least
squares on the taps that belong (see ``robust``).

Conditioning: only the variation of ``u_i = base_R_tcp_i^T n`` (the table normal seen from the tool)
determines the tip. The singular values of the deviations ``u_i - mean(u)``, divided by sqrt(N), are the
RMS spread of the tilts along each tool direction (dimensionless; about sin(tilt) sideways, the variation
of cos(tilt) along the tool axis); a tap error of e mm moves the tip by about e / spread / sqrt(N) mm. The
condition number is the largest spread over the smallest.

The tip must not depend on how the flange is spun about the tool axis: ``spin`` fits the inliers of each
spin separately and refuses when two such tips disagree (two series mixed in one folder).
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.residuals import ExcludedTap, ResidualStats
from fixwizard.calibration.robust import robust_inliers
from fixwizard.calibration.spin import check_spin_consistency

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

    def fit_spin_group(indices: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        if len(indices) < MIN_TILTED_TAPS or _tilt_spread(tcp_n_table[indices])[-1] < MIN_SPREAD:
            return None
        solution, covariance = _least_squares(design[indices], target[indices])
        return solution[:3], covariance[:3, :3]

    inliers, excluded = robust_inliers(count, 4, fit, lambda solution: design @ solution - target, "tilted taps",
                                       files)
    spread = _check_spread(tcp_n_table[inliers], "the tilted taps left after excluding those that do not belong")
    check_spin_consistency(base_T_tcp, base_n_table, inliers, fit_spin_group, files)
    solution, covariance = _least_squares(design[inliers], target[inliers])
    residuals_m = design @ solution - target
    return FineTipFit(solution[:3], float(solution[3]), residuals_m, inliers, excluded,
                      ResidualStats.of(residuals_m[inliers]), spread, float(spread[0] / spread[-1]),
                      np.sqrt(np.diag(covariance)[:3]))


def _least_squares(design: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares solution and its covariance, scaled by the residual variance."""
    solution = np.linalg.lstsq(design, target, rcond=None)[0]
    residuals = design @ solution - target
    variance = residuals @ residuals / (len(target) - design.shape[1])
    return solution, variance * np.linalg.inv(design.T @ design)


def _tilt_spread(tcp_n_table: np.ndarray) -> np.ndarray:
    """RMS spread (3, descending) of the table normals seen from the tool."""
    deviations = tcp_n_table - tcp_n_table.mean(axis=0)
    return np.linalg.svd(deviations, compute_uv=False) / np.sqrt(len(tcp_n_table))


def _check_spread(tcp_n_table: np.ndarray, which: str) -> np.ndarray:
    """Tilt spread (3, descending) of the table normals seen from the tool; refuses one too small."""
    spread = _tilt_spread(tcp_n_table)
    if spread[-1] < MIN_SPREAD:
        raise CalibrationError(
            f"{which} do not vary their tilt enough to determine the tip (spread {spread[-1]:.3f} in the weakest "
            f"direction, at least {MIN_SPREAD} needed): tap the table at tilts from 10 to 30 degrees, each tilt "
            "in at least three directions around the tool axis")
    return spread
