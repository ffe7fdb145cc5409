"""Proposal of the sample error bound: 1.5 x largest fine residual + 0.2 mm, rounded up to 0.1 mm."""

import numpy as np
import pytest

from fixwizard.calibration.bound import propose_sample_bound


@pytest.mark.parametrize("largest_mm, bound_mm", [(0.34, 0.8), (0.4, 0.8), (0.41, 0.9), (0.0, 0.2), (1.1, 1.9)])
def test_bound_adds_half_the_largest_residual_and_0_2_mm_then_rounds_up(largest_mm, bound_mm):
    residuals_m = np.array([0.5, -1.0, 0.1]) * largest_mm * 1e-3
    assert propose_sample_bound(residuals_m).bound_m == pytest.approx(bound_mm * 1e-3, abs=1e-12)


def test_bound_is_explained_in_one_sentence():
    residuals_m = np.r_[0.34e-3, np.full(99, 0.1e-3)]
    assert propose_sample_bound(residuals_m).reason == (
        "0.8 mm: the largest of 100 fine-calibration residuals was 0.34 mm; the bound adds a 50% + 0.2 mm margin "
        "for the robot's repeatability across the workspace, rounded up to 0.1 mm.")
