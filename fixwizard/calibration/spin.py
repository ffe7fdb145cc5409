"""Consistency of the fine tip with the flange's spin about the tool axis.

A rigidly mounted ball sits at one point of the flange frame however the flange is turned. Two tap
series recorded with the flange spun differently about the tool axis, with the tool remounted or the
flange offset changed in between, do not share that point; mixed, each series bends the fit by a
millimetre or two, too little for the residual test to pick one series out. So the fine tip groups its
inlier taps by spin, fits every group that determines the tip on its own, and refuses when two disagree.

Spin, robust to the tilt of every tap: turn the flange by the shortest rotation that takes its tool z
axis onto the downward table normal (undo the tilt along its great circle), then read the angle of its x
axis in the table plane, from the base x axis projected onto it (base y for a table on edge). Tilting a
tool leaves this heading unchanged, turning it about its own axis changes it by the same angle; it is
defined for any tilt below 180 degrees. Headings closer than ``SPIN_GAP_DEG`` to a neighbour (around
the circle) form one group.

Why refuse rather than drop the smaller group: the data cannot tell which mounting the fixture work
will use, and two series of similar size (as 89 and 100 taps) have no clear majority. Calibrating from
one series is a one-folder change for the operator; a silently chosen tip could be millimetres off.
"""

from collections.abc import Callable, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.calibration.errors import CalibrationError

SPIN_GAP_DEG = 30.0
MIN_DISAGREEMENT_M = 0.5e-3
MIN_DISAGREEMENT_SIGMAS = 5.0
_LISTED_RUNS = 4

GroupFit = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray] | None]


def spin_headings_rad(base_T_tcp: np.ndarray, base_n_table: np.ndarray) -> np.ndarray:
    """Heading (N,) in (-pi, pi] of each flange about the downward table normal once its tilt is undone."""
    base_z_tool = base_T_tcp[:, :3, 2]
    down = -np.asarray(base_n_table, dtype=float)
    cross = np.cross(base_z_tool, down)
    sine = np.linalg.norm(cross, axis=1)
    angle = np.arctan2(sine, base_z_tool @ down)
    scale = np.divide(angle, sine, out=np.zeros_like(angle), where=sine > 1e-12)
    base_x_untilted = Rotation.from_rotvec(cross * scale[:, None]).apply(base_T_tcp[:, :3, 0])
    base_e1 = np.eye(3)[0 if abs(down[0]) < 0.9 else 1]
    base_e1 = base_e1 - (base_e1 @ down) * down
    base_e1 /= np.linalg.norm(base_e1)
    base_e2 = np.cross(down, base_e1)
    return np.arctan2(base_x_untilted @ base_e2, base_x_untilted @ base_e1)


def spin_groups(headings_rad: np.ndarray, gap_rad: float = np.radians(SPIN_GAP_DEG)) -> list[np.ndarray]:
    """Indices of the headings split wherever neighbours around the circle are more than ``gap_rad`` apart."""
    order = np.argsort(headings_rad)
    sorted_rad = headings_rad[order]
    gaps = np.diff(np.append(sorted_rad, sorted_rad[0] + 2 * np.pi))
    cuts = np.flatnonzero(gaps > gap_rad)
    if len(cuts) == 0:
        return [np.sort(order)]
    start = cuts[-1] + 1
    order, gaps = np.roll(order, -start), np.roll(gaps, -start)
    return [np.sort(group) for group in np.split(order, np.flatnonzero(gaps[:-1] > gap_rad) + 1)]


def check_spin_consistency(base_T_tcp: np.ndarray, base_n_table: np.ndarray, inliers: np.ndarray,
                           fit_group: GroupFit, files: Sequence[str] = ()) -> None:
    """Refuse (CalibrationError) when inlier taps (mask ``inliers``) spun differently about the tool axis give
    different tips.

    ``fit_group(indices)`` returns the tip (3,) and its covariance (3, 3) fitted to those taps alone, or
    None when they cannot determine it (too few or too little tilt spread); such groups are not compared.
    Two tips disagree when they are more than ``MIN_DISAGREEMENT_M`` apart and more than
    ``MIN_DISAGREEMENT_SIGMAS`` combined standard errors (Mahalanobis distance under both covariances);
    the margin keeps small unmodelled robot errors from triggering it. The message also names the taps
    that are not inliers.
    """
    indices = np.flatnonzero(inliers)
    headings = spin_headings_rad(base_T_tcp[indices], base_n_table)
    fits = []
    for group in spin_groups(headings):
        fitted = fit_group(indices[group])
        if fitted is not None:
            fits.append((indices[group], np.degrees(np.median(headings[group])), *fitted))
    for first, (taps_a, heading_a, tip_a, covariance_a) in enumerate(fits):
        for taps_b, heading_b, tip_b, covariance_b in fits[first + 1:]:
            difference = tip_a - tip_b
            distance_m = np.linalg.norm(difference)
            if distance_m <= MIN_DISAGREEMENT_M:
                continue
            sigmas = _mahalanobis(difference, covariance_a + covariance_b)
            if sigmas > MIN_DISAGREEMENT_SIGMAS:
                raise CalibrationError(
                    "the tilted taps give a tip that depends on how the flange is turned about the tool axis, "
                    f"which a rigidly mounted tool cannot do: {_describe_group(taps_a, files)} (flange heading "
                    f"{heading_a:.0f} deg) give the tip {_mm(tip_a)} mm, {_describe_group(taps_b, files)} "
                    f"(heading {heading_b:.0f} deg) give {_mm(tip_b)} mm, {distance_m * 1e3:.2f} mm apart "
                    f"({sigmas:.0f} standard errors). They are probably two series with the tool remounted or the "
                    "flange offset changed between them: calibrate from one series only (put only its files in "
                    "the folder), the one recorded with the tool mounted as it will be used."
                    + _left_out(inliers, files))


def _mahalanobis(difference: np.ndarray, covariance: np.ndarray) -> float:
    """Length of ``difference`` in standard errors; infinite for noise-free fits (zero covariance)."""
    try:
        return float(np.sqrt(difference @ np.linalg.solve(covariance, difference)))
    except np.linalg.LinAlgError:
        return np.inf


def _left_out(inliers: np.ndarray, files: Sequence[str]) -> str:
    """' Already left out for their residuals: the 3 taps ...' or nothing when every tap is an inlier."""
    outliers = np.flatnonzero(~inliers)
    return f" Already left out for their residuals: {_describe_group(outliers, files)}." if len(outliers) else ""


def _describe_group(indices: np.ndarray, files: Sequence[str]) -> str:
    """'the 86 taps base_t_tcp_pt_11.pose to base_t_tcp_pt_96.pose' (runs of consecutive taps)."""
    starts = np.flatnonzero(np.diff(indices, prepend=-2) != 1)
    ends = np.append(starts[1:], len(indices)) - 1
    name = (lambda index: files[index]) if files else (lambda index: f"tap {index}")
    runs = [name(indices[start]) + ("" if start == end else f" to {name(indices[end])}")
            for start, end in zip(starts[:_LISTED_RUNS], ends, strict=False)]
    more = f" and {len(starts) - _LISTED_RUNS} more runs" if len(starts) > _LISTED_RUNS else ""
    return f"the {len(indices)} taps " + ", ".join(runs) + more


def _mm(values_m: np.ndarray) -> str:
    return "[" + ", ".join(f"{value * 1e3:.2f}" for value in values_m) + "]"
