"""Proposal of the sample error bound from the fine-calibration residuals.

Rule: ``bound = 1.5 x largest residual + 0.2 mm``, rounded up to the next 0.1 mm. The fine residuals show
how well single taps agree across tilts at one spot; the margin covers the robot's repeatability across
the rest of the workspace. The operator may override the proposal.
"""

import math
from dataclasses import dataclass

import numpy as np

BOUND_FACTOR = 1.5
BOUND_MARGIN_M = 0.2e-3
BOUND_STEP_M = 0.1e-3


@dataclass(frozen=True)
class SampleBound:
    """Proposed bound (m) on a tap's error, and one sentence for people saying where it comes from."""

    bound_m: float
    reason: str


def propose_sample_bound(residuals_m: np.ndarray) -> SampleBound:
    """Bound from the residuals (m) of the taps the fine tip was fitted to."""
    largest_m = float(np.max(np.abs(residuals_m)))
    steps = math.ceil(round((BOUND_FACTOR * largest_m + BOUND_MARGIN_M) / BOUND_STEP_M, 6))
    bound_m = round(steps * BOUND_STEP_M, 10)
    reason = (f"{bound_m * 1e3:.1f} mm: the largest of {len(residuals_m)} fine-calibration residuals was "
              f"{largest_m * 1e3:.2f} mm; the bound adds a {BOUND_FACTOR - 1:.0%} + {BOUND_MARGIN_M * 1e3:.1f} mm "
              "margin for the robot's repeatability across the workspace, rounded up to "
              f"{BOUND_STEP_M * 1e3:.1f} mm.")
    return SampleBound(bound_m, reason)
