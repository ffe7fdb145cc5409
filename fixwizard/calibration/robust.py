"""Robust fitting of tap series: find the taps that do not belong before the final least-squares fit.

Least median of squares (Rousseeuw and Leroy, 1987) over random minimal subsets picks the model that
fits the majority. Its scale estimate ``sigma = 1.4826 (1 + 5 / (n - p)) sqrt(median r^2)`` sets the
rejection threshold ``2.5 sigma``, never below 1 mm, so honest sub-millimetre scatter is never rejected.
The inliers are refitted by least squares and reclassified until the set no longer changes. More than
a third of the taps rejected means the series itself is wrong: the fit refuses rather than guesses.
"""

from collections.abc import Callable, Sequence
from typing import TypeVar

import numpy as np

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.residuals import ExcludedTap

REJECT_SIGMAS = 2.5
REJECT_FLOOR_M = 1e-3
MAX_REJECTED_FRACTION = 1 / 3
_MEDIAN_TO_SIGMA = 1.4826
_SUBSETS = 300
_REFITS = 20
_LISTED = 12

Model = TypeVar("Model")


def robust_inliers(count: int, minimal: int, fit: Callable[[np.ndarray], Model],
                   residuals_m: Callable[[Model], np.ndarray], what: str,
                   files: Sequence[str] = ()) -> tuple[np.ndarray, tuple[ExcludedTap, ...]]:
    """Inlier mask (count,) and the excluded taps of a series of ``count`` taps.

    ``fit(indices)`` returns the least-squares model of those taps (at least ``minimal``; it must succeed
    for all taps), ``residuals_m(model)`` the signed residual (m) of every tap. ``what`` names the taps
    in messages ("tilted taps"), ``files`` their file names when known. Raises CalibrationError when
    more than a third of the taps disagree with the rest. Deterministic: the subsets use a fixed seed.
    """
    rng = np.random.default_rng(0)
    best = fit(np.arange(count))
    best_median = np.median(residuals_m(best) ** 2)
    for _ in range(_SUBSETS):
        model = fit(rng.choice(count, minimal, replace=False))
        median = np.median(residuals_m(model) ** 2)
        if median < best_median:
            best, best_median = model, median
    scale_m = _MEDIAN_TO_SIGMA * (1 + 5 / (count - minimal)) * np.sqrt(best_median)
    threshold_m = max(REJECT_SIGMAS * scale_m, REJECT_FLOOR_M)
    residuals = residuals_m(best)
    inliers = np.abs(residuals) <= threshold_m
    for _ in range(_REFITS):
        residuals = residuals_m(fit(np.flatnonzero(inliers)))
        refitted = np.abs(residuals) <= threshold_m
        if np.array_equal(refitted, inliers):
            break
        inliers = refitted
    excluded = tuple(ExcludedTap(int(index), files[int(index)] if files else None, float(residuals[index]),
                                 float(threshold_m)) for index in np.flatnonzero(~inliers))
    if len(excluded) > MAX_REJECTED_FRACTION * count:
        raise CalibrationError(
            f"{len(excluded)} of the {count} {what} disagree with the rest by more than "
            f"{threshold_m * 1e3:.1f} mm, more than a third, so no fit can be trusted: "
            f"{_describe_excluded(excluded)}. Check that every tap touched the table, with the same tool, "
            "and that the folder holds only this series; then record the taps again.")
    return inliers, excluded


def _describe_excluded(excluded: Sequence[ExcludedTap]) -> str:
    """Short list of excluded taps for a message: file names (or indices), the first few only."""
    names = [tap.file or f"tap {tap.index}" for tap in excluded[:_LISTED]]
    more = f" and {len(excluded) - _LISTED} more" if len(excluded) > _LISTED else ""
    return ", ".join(names) + more
