"""Figures about residuals: RMS and largest value, and the taps a robust fit left out."""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ResidualStats:
    """Root mean square and largest magnitude of residuals (m)."""

    rms_m: float
    max_m: float

    @classmethod
    def of(cls, residuals_m: np.ndarray) -> "ResidualStats":
        """Statistics of scalar residuals (N,) in metres."""
        residuals_m = np.abs(np.asarray(residuals_m, dtype=float))
        return cls(float(np.sqrt(np.mean(residuals_m**2))), float(residuals_m.max()))


@dataclass(frozen=True)
class ExcludedTap:
    """A tap left out of a fit: its index in the step, file name (None when unknown), residual against the
    fit of the others and the rejection threshold it exceeded (m)."""

    index: int
    file: str | None
    residual_m: float
    threshold_m: float

    def describe(self) -> str:
        """One line for people, in mm."""
        name = f"tap {self.index}" + (f" ({self.file})" if self.file else "")
        return (f"{name}: {self.residual_m * 1e3:+.2f} mm from the fit of the others "
                f"(rejection threshold {self.threshold_m * 1e3:.2f} mm)")
