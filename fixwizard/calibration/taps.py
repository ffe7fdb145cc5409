"""Recorded flange poses of one calibration step, and the ball centres they give."""

from dataclasses import dataclass

import numpy as np

from fixwizard.calibration.residuals import ExcludedTap


@dataclass(frozen=True, eq=False)
class PoseSeries:
    """Flange poses ``base_T_tcp`` (N, 4, 4) of one step as recorded, with their file names when known
    (empty tuple otherwise), and the taps a fit left out."""

    base_T_tcp: np.ndarray
    files: tuple[str, ...] = ()
    excluded: tuple[ExcludedTap, ...] = ()

    def __post_init__(self) -> None:
        base_T_tcp = readonly_array(self.base_T_tcp)
        if base_T_tcp.ndim != 3 or base_T_tcp.shape[1:] != (4, 4):
            raise ValueError(f"base_T_tcp must have shape (N, 4, 4), not {base_T_tcp.shape}")
        if self.files and len(self.files) != len(base_T_tcp):
            raise ValueError(f"{len(self.files)} file names for {len(base_T_tcp)} poses")
        object.__setattr__(self, "base_T_tcp", base_T_tcp)
        object.__setattr__(self, "files", tuple(self.files))
        object.__setattr__(self, "excluded", tuple(self.excluded))


def ball_centres_m(base_T_tcp: np.ndarray, tcp_p_tip_m: np.ndarray) -> np.ndarray:
    """Ball centres (N, 3) in the base frame (m) of flange poses (N, 4, 4) and a tip (3,) in the flange frame."""
    return np.einsum("nij,j->ni", base_T_tcp[:, :3, :3], tcp_p_tip_m) + base_T_tcp[:, :3, 3]


def readonly_array(values: np.ndarray) -> np.ndarray:
    """A float64 copy that cannot be changed, for the arrays of frozen dataclasses."""
    array = np.array(values, dtype=float)
    array.setflags(write=False)
    return array
