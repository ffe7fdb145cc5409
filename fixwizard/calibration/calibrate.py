"""A whole tool-tip calibration from recorded flange poses: pivot, table plane, fine tip, sample bound.

The robot-driven steps and the command line both end here, with the poses of every step in hand.
"""

from dataclasses import replace
from datetime import UTC, datetime

import numpy as np

from fixwizard.calibration.bound import propose_sample_bound
from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.pivot import fit_pivot
from fixwizard.calibration.store import TipCalibration
from fixwizard.calibration.table import coarse_table_frame, fit_table_plane, table_frame
from fixwizard.calibration.taps import PoseSeries, ball_centres_m
from fixwizard.calibration.tip import fit_fine_tip

MAX_BALL_DIAMETER_M = 0.05


def calibrate_tip(pivot: PoseSeries, table: PoseSeries, tilted: PoseSeries, ball_diameter_m: float,
                  table_coarse: PoseSeries | None = None, name: str = "tip",
                  robot: str | None = None) -> TipCalibration:
    """Calibrate the tip from pivot poses, table taps at one orientation, tilted table taps and optionally
    three coarse table taps A, B, C; ``ball_diameter_m`` in metres.

    The pivot tip orients and places the table plane, whose normal the fine tip is fitted against. The
    stored table frame has z along the fine normal (towards the flange); with A, B, C its origin is the
    ball centre at B and x points towards A, without them its origin is the centroid of the table taps
    and x follows the base x axis (base y for a table standing on edge). Ball centres use the fine tip.
    """
    if not 0 < ball_diameter_m <= MAX_BALL_DIAMETER_M:
        raise CalibrationError(f"a ball diameter of {ball_diameter_m * 1e3:g} mm is implausible: give it with its "
                               "unit, for example 3mm")
    pivot_fit = fit_pivot(pivot.base_T_tcp)
    plane = fit_table_plane(table.base_T_tcp, pivot_fit.tcp_p_tip_m, table.files)
    fine = fit_fine_tip(tilted.base_T_tcp, plane.base_n_table, tilted.files)
    if table_coarse is None:
        base_p_origin = ball_centres_m(table.base_T_tcp[plane.inliers], fine.tcp_p_tip_m).mean(axis=0)
        base_v_x = np.eye(3)[0 if abs(plane.base_n_table[0]) < 0.9 else 1]
        base_T_table = table_frame(plane.base_n_table, base_p_origin, base_v_x)
    else:
        base_T_table = coarse_table_frame(table_coarse.base_T_tcp, fine.tcp_p_tip_m, plane.base_n_table)
    bound = propose_sample_bound(fine.residuals_m[fine.inliers])
    steps = {"pivot": pivot, "table": replace(table, excluded=plane.excluded),
             "tilted": replace(tilted, excluded=fine.excluded)}
    if table_coarse is not None:
        steps["table_coarse"] = table_coarse
    return TipCalibration(
        name=name, created=datetime.now(UTC).isoformat(timespec="seconds"), robot=robot,
        tcp_p_tip_m=fine.tcp_p_tip_m, ball_diameter_m=float(ball_diameter_m), sample_bound_m=bound.bound_m,
        sample_bound_reason=bound.reason, base_T_table=base_T_table, pivot_tcp_p_tip_m=pivot_fit.tcp_p_tip_m,
        pivot_residuals=pivot_fit.stats, table_residuals=plane.stats, tip_residuals=fine.stats,
        tip_condition_number=fine.condition_number, tip_standard_error_m=fine.standard_error_m, steps=steps)
