"""Table plane and table frame from taps of the ball on a flat table.

Orientation rule: the table normal, the z axis of the table frame, points from the table towards the
flange, the side the tool taps from (for a robot standing on the floor: towards positive base z).
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.residuals import ExcludedTap, ResidualStats
from fixwizard.calibration.robust import robust_inliers
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.geometry.se3 import make_transform, rotation_angle_rad

MIN_TABLE_TAPS = 6
MAX_TURN_DEG = 2.0
MIN_SPREAD_M = 0.01
MIN_EDGE_M = 0.01
MIN_CORNER_DEG = 30.0
MAX_NORMAL_MISMATCH_DEG = 5.0


@dataclass(frozen=True, eq=False)
class TablePlane:
    """Unit normal (towards the flange) and centroid (m) of the ball centres of the inlier taps, in the base
    frame; every tap's signed distance (m) from the plane, the inlier mask and the excluded taps."""

    base_n_table: np.ndarray
    base_p_centroid_m: np.ndarray
    residuals_m: np.ndarray
    inliers: np.ndarray
    excluded: tuple[ExcludedTap, ...]
    stats: ResidualStats


def fit_table_plane(base_T_tcp: np.ndarray, tcp_p_tip_m: np.ndarray, files: Sequence[str] = ()) -> TablePlane:
    """Table plane from taps (N, 4, 4) at one fixed tool orientation: normal by SVD, taps off the table excluded.

    With a fixed orientation an error in the tip shifts every ball centre by the same vector, so the
    coarse (pivot) tip gives the exact normal; only the plane's offset depends on it.
    """
    count = len(base_T_tcp)
    if count < MIN_TABLE_TAPS:
        raise CalibrationError(f"the table plane needs at least {MIN_TABLE_TAPS} taps spread over the table; "
                               f"got {count}")
    turned_deg = np.degrees(rotation_angle_rad(base_T_tcp[0, :3, :3].T @ base_T_tcp[:, :3, :3]))
    if turned_deg.max() > MAX_TURN_DEG:
        worst = int(np.argmax(turned_deg))
        raise CalibrationError(
            f"the table taps must all keep one tool orientation, but tap {worst}"
            f"{f' ({files[worst]})' if files else ''} is turned by {turned_deg[worst]:.1f} degrees against the "
            "first. Record the table taps again without turning the tool (tilted taps belong to the fine tip step).")
    base_p_ball = ball_centres_m(base_T_tcp, tcp_p_tip_m)
    inliers, excluded = robust_inliers(count, 3, lambda indices: _plane(base_p_ball[indices]),
                                       lambda plane: (base_p_ball - plane[0]) @ plane[1], "table taps", files)
    centroid, normal, spread_m = _plane(base_p_ball[inliers])
    if spread_m < MIN_SPREAD_M:
        raise CalibrationError(
            f"the table taps lie almost on a line (spread {spread_m * 1e3:.1f} mm across it, at least "
            f"{MIN_SPREAD_M * 1e3:.0f} mm needed): spread them over an area, e.g. a grid of 50 x 50 mm or more")
    if np.mean(base_T_tcp[:, :3, 3] - base_p_ball, axis=0) @ normal < 0:
        normal = -normal
    residuals_m = (base_p_ball - centroid) @ normal
    return TablePlane(normal, centroid, residuals_m, inliers, excluded, ResidualStats.of(residuals_m[inliers]))


def _plane(base_p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Centroid, unit normal (either sign) and RMS spread (m) along the narrower in-plane direction."""
    centroid = base_p.mean(axis=0)
    _, singular, directions = np.linalg.svd(base_p - centroid, full_matrices=False)
    return centroid, directions[2], float(singular[1] / np.sqrt(len(base_p)))


def table_frame(base_n_table: np.ndarray, base_p_origin_m: np.ndarray, base_v_x: np.ndarray) -> np.ndarray:
    """``base_T_table``: z the table normal, origin given (m), x along ``base_v_x`` projected onto the table."""
    z = base_n_table / np.linalg.norm(base_n_table)
    x = base_v_x - (base_v_x @ z) * z
    x = x / np.linalg.norm(x)
    return make_transform(np.column_stack([x, np.cross(z, x), z]), base_p_origin_m)


def coarse_table_frame(base_T_tcp_abc: np.ndarray, tcp_p_tip_m: np.ndarray,
                       base_n_table: np.ndarray | None = None) -> np.ndarray:
    """``base_T_table`` from three taps A, B, C on the table (3, 4, 4): origin the ball centre at the corner B,
    x towards A, z along ``(A - B) x (C - B)`` so that C lies on the positive y side.

    A given fine normal ``base_n_table`` replaces that z (the two must agree within 5 degrees). The taps
    must run counter-clockwise seen from the tool, so that z points towards the flange.
    """
    if len(base_T_tcp_abc) != 3:
        raise CalibrationError(f"the coarse table frame needs exactly 3 taps A, B (the corner), C; got "
                               f"{len(base_T_tcp_abc)}")
    base_p_a, base_p_b, base_p_c = ball_centres_m(base_T_tcp_abc, tcp_p_tip_m)
    edges = np.array([base_p_a - base_p_b, base_p_c - base_p_b])
    lengths = np.linalg.norm(edges, axis=1)
    if lengths.min() < MIN_EDGE_M:
        raise CalibrationError(f"taps A and C must be at least {MIN_EDGE_M * 1e3:.0f} mm from the corner B; they "
                               f"are {lengths[0] * 1e3:.1f} and {lengths[1] * 1e3:.1f} mm away")
    normal = np.cross(edges[0], edges[1])
    corner_deg = np.degrees(np.arcsin(min(np.linalg.norm(normal) / lengths.prod(), 1.0)))
    if corner_deg < MIN_CORNER_DEG:
        raise CalibrationError(f"taps A, B, C lie nearly on one line ({corner_deg:.0f} degrees from it): tap a "
                               "corner, A and C about 90 degrees apart as seen from B")
    normal = normal / np.linalg.norm(normal)
    if np.mean(base_T_tcp_abc[:, :3, 3] - np.array([base_p_a, base_p_b, base_p_c]), axis=0) @ normal < 0:
        raise CalibrationError("taps A, B, C run clockwise seen from the tool, which would put the table frame "
                               "upside down: tap them counter-clockwise (or swap the files of A and C)")
    if base_n_table is not None:
        mismatch_deg = np.degrees(np.arccos(np.clip(normal @ base_n_table, -1.0, 1.0)))
        if mismatch_deg > MAX_NORMAL_MISMATCH_DEG:
            raise CalibrationError(
                f"taps A, B, C and the table taps describe different planes ({mismatch_deg:.1f} degrees apart): "
                "check that both folders hold taps on the same table")
        normal = base_n_table
    return table_frame(normal, base_p_b, edges[0])
