"""The solver's own figures behind the plain words, for the wizard's details views (lengths in mm, angles in
degrees)."""

import numpy as np

from fixwizard.report import rounded_up_text
from fixwizard.solver.solve import Solution


def details_lines(solution: Solution) -> list[str]:
    """The solver's own figures, for the Details view: status, search, likelihood samples, the diagnosis."""
    stats = solution.stats
    lines = [f"Solver status: {solution.status}.",
             f"Search: {stats.cells:,} cells survive of a budget of {stats.max_cells:,.0f} (rotation level "
             f"{stats.rotation_level}, position level {stats.position_level}), {stats.elapsed_s:.1f} s.",
             f"Effective likelihood samples: {solution.effective_samples:,.0f}.",
             *(f"Mode {number}: probability {mode.probability:.1%}, within "
               f"{rounded_up_text(mode.bounds.position_m * 1e3, 2)} mm, "
               f"{rounded_up_text(np.degrees(mode.bounds.rotation_rad), 2)} deg"
               for number, mode in enumerate(solution.modes, start=1))]
    if solution.bounds is not None:
        bounds = solution.bounds
        lines.append(f"Bounds: position {rounded_up_text(bounds.position_m * 1e3, 3)} mm, rotation "
                     f"{rounded_up_text(np.degrees(bounds.rotation_rad), 3)} deg, "
                     f"any point {rounded_up_text(bounds.max_point_displacement_m * 1e3, 3)} mm.")
    diagnosis = solution.diagnosis
    if diagnosis is not None:
        if diagnosis.smallest_bound_m is not None:
            low, high = diagnosis.smallest_bound_m
            lines.append(f"Smallest sample bound that explains the taps: between {low * 1e3:.2f} and {high * 1e3:.2f} "
                         "mm.")
        if diagnosis.ball_diameter_m is not None:
            lines.append(f"Ball diameter fitted with the pose: {diagnosis.ball_diameter_m * 1e3:.2f} mm.")
        lines += [f"Cause {cause.code}: {cause.message}" for cause in diagnosis.causes]
    return lines
