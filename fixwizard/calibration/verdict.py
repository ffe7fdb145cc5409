"""A plain verdict on a tool-tip calibration: good, usable or redo, with the reasons in the operator's words.

Everything is measured against the sample bound ``b`` the solver will use: the largest error of a tap's ball
centre it allows (``bound.propose_sample_bound``: 1.5 x the largest fine residual + 0.2 mm). The parts of a
tap's error the residuals do not show must fit in what ``b`` leaves:

- **The fine tip's uncertainty** ``s`` (length of its standard-error vector, from the scatter of the tilted taps).
  A tip off by ``e`` moves every ball centre by ``|e|``, in every tap, and the residuals cannot see it. The bound's
  margin above the largest fine residual, ``m = b - largest residual``, is what is left to cover it: good when
  ``s <= m`` (a one-standard-error tip error fits in the margin); usable when ``s <= b`` (it fits in the bound but
  eats into what covers the scatter: the bounds may be optimistic); redo when ``s > b``.
- **The two tips agree**: the pivot gives a coarse tip, the tilted taps the fine one (used), each measured
  independently. The pivot tip errs by about its residual over the sine of its tilt (20-30 degrees: up to 3x its
  largest residual ``p``), the fine tip by about ``2 s``; so they should differ by at most ``a = 3 p + 2 s``, and
  never less than ``MIN_AGREEMENT_M``: two tips measured on one robot differ by its repeatability (UR e-series
  +-0.03-0.1 mm) and a contact's detection even when every residual is near zero (an exact arm).
  Up to ``a``: they agree; up to ``2 a``: usable (the ball may have slipped in the pivot; the fine tip is used);
  beyond: redo (the ball may be loose).
- **Taps left out**: the fits leave out taps that do not belong. More than ``MAX_EXCLUDED_SHARE`` of a step left
  out means something moved during it: redo.
- **The size of the bound**: the fixture's bounds come out at 1.5-3.2x ``b`` on the paper's real runs (1 mm bound:
  1.5-3.2 mm). Above ``LOOSE_BOUND_M`` the result is usable but the fixture will only be known to a few mm.
"""

from dataclasses import dataclass
from typing import Literal

import numpy as np

from fixwizard.calibration.store import TipCalibration

Level = Literal["good", "usable", "redo"]
LEVELS: tuple[Level, ...] = ("good", "usable", "redo")
PIVOT_TILT_FACTOR = 3.0  # 1 / sin(20 deg), rounded: the pivot tip's error per unit of its largest residual
FINE_TIP_FACTOR = 2.0  # standard errors of the fine tip allowed in the agreement of the two tips
MIN_AGREEMENT_M = 0.1e-3  # tips this close agree, however small the residuals: a robot's repeatability
MAX_EXCLUDED_SHARE = 0.2
LOOSE_BOUND_M = 1.0e-3


@dataclass(frozen=True)
class TipVerdict:
    """The verdict and its reasons (plain sentences, the worst first)."""

    level: Level
    reasons: tuple[str, ...]

    def headline(self) -> str:
        return {"good": "GOOD: use this calibration.",
                "usable": "USABLE: it works, with a caveat.",
                "redo": "REDO: calibrate again (Redo from the pivot)."}[self.level]


def tip_verdict(calibration: TipCalibration) -> TipVerdict:
    """Good, usable or redo for ``calibration`` (see the module doc), with why."""
    bound_m = calibration.sample_bound_m
    bound_mm = bound_m * 1e3
    found: list[tuple[Level, str]] = []
    spread_m = float(np.linalg.norm(calibration.tip_standard_error_m))
    margin_m = bound_m - calibration.tip_residuals.max_m
    if spread_m > bound_m:
        found.append(("redo", f"the ball centre is only known to about {spread_m * 1e3:.2f} mm, more than the "
                              f"{bound_mm:.1f} mm each tap is trusted to"))
    elif spread_m > margin_m:
        found.append(("usable", f"the ball centre is known to about {spread_m * 1e3:.2f} mm, which uses up part of "
                                f"the {bound_mm:.1f} mm each tap is trusted to: the fixture's bounds may be a little "
                                "optimistic"))
    agreement_m = max(PIVOT_TILT_FACTOR * calibration.pivot_residuals.max_m + FINE_TIP_FACTOR * spread_m,
                      MIN_AGREEMENT_M)
    apart_m = float(np.linalg.norm(calibration.tcp_p_tip_m - calibration.pivot_tcp_p_tip_m))
    if apart_m > 2.0 * agreement_m:
        found.append(("redo", f"the pivot and the table taps put the ball {apart_m * 1e3:.2f} mm apart (up to "
                              f"{agreement_m * 1e3:.2f} mm is normal): check that the ball is tight"))
    elif apart_m > agreement_m:
        found.append(("usable", f"the pivot and the table taps put the ball {apart_m * 1e3:.2f} mm apart (up to "
                                f"{agreement_m * 1e3:.2f} mm is normal): the ball may have slipped in the pivot; the "
                                "table taps' value is used"))
    for step, series in calibration.steps.items():
        if len(series.base_T_tcp) and len(series.excluded) > MAX_EXCLUDED_SHARE * len(series.base_T_tcp):
            found.append(("redo", f"{len(series.excluded)} of {len(series.base_T_tcp)} {step} taps did not fit the "
                                  "others: something moved during that step (the ball, the table or the robot's base)"))
    if bound_m > LOOSE_BOUND_M:
        found.append(("usable", f"each tap is only trusted to {bound_mm:.1f} mm, so the fixture will be known to "
                                f"about {1.5 * bound_mm:.0f}-{3 * bound_mm:.0f} mm"))
    if not found:
        return TipVerdict("good", (f"the ball centre is known to about {spread_m * 1e3:.2f} mm and each tap is "
                                   f"trusted to {bound_mm:.1f} mm; the pivot and the table taps agree",))
    found.sort(key=lambda item: -LEVELS.index(item[0]))
    return TipVerdict(found[0][0], tuple(reason for _, reason in found))
