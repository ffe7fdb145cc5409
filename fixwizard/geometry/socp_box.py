"""Axis-aligned box around the intersection of equal balls, by six second-order cone programs (cvxopt).

The fixture centre lies within ``radius`` of every tap, so it lies in the intersection of
the balls ``|t - p_i| <= radius``; the box is that intersection's bounding box. Where cvxopt does not
converge or fails (it raises ``ValueError`` on a singular system when two balls barely touch), the box is
the intersection of the balls' own boxes instead: looser, still a superset.
"""

from typing import Any

import numpy as np
from cvxopt import matrix, solvers

# cvxopt's default tolerances are about 1e-7 on the problem scaled to unit radius; growing
# the box by 100 times that keeps it a superset whatever the solver's rounding.
SOLVER_MARGIN = 1e-5


def ball_intersection_box(centers_m: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(low, high) corners (m) of a box holding every point within ``radius_m`` of all centres; None if empty."""
    centers_m = np.asarray(centers_m, float)
    origin = centers_m.mean(axis=0)
    scaled = (centers_m - origin) / radius_m
    cone_matrix = matrix(np.vstack([np.zeros((1, 3)), np.eye(3)]))
    cone_matrices = [cone_matrix] * len(scaled)
    cone_offsets = [matrix(np.concatenate([[1.0], center])) for center in scaled]
    low, high = np.empty(3), np.empty(3)
    for axis in range(3):
        for sign, bound in ((1.0, low), (-1.0, high)):
            objective = np.zeros(3)
            objective[axis] = sign
            try:
                solution = _quiet_socp(matrix(objective), cone_matrices, cone_offsets)
            except (ValueError, ArithmeticError):
                return _fallback_box(scaled, origin, radius_m)
            if solution["status"] != "optimal":
                return _fallback_box(scaled, origin, radius_m)
            bound[axis] = solution["x"][axis]
    if np.any(low > high + 2 * SOLVER_MARGIN):
        return None
    return origin + (low - SOLVER_MARGIN) * radius_m, origin + (high + SOLVER_MARGIN) * radius_m


def _quiet_socp(objective: matrix, cone_matrices: list[matrix], cone_offsets: list[matrix]) -> dict[str, Any]:
    """cvxopt's SOCP without its progress printout (cvxopt reads that switch from a module global)."""
    previous = solvers.options.get("show_progress", True)
    solvers.options["show_progress"] = False
    try:
        return solvers.socp(objective, Gq=cone_matrices, hq=cone_offsets)
    finally:
        solvers.options["show_progress"] = previous


def _fallback_box(scaled: np.ndarray, origin: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Intersection of the balls' own boxes: a looser superset used when the cone programs do not converge."""
    low = np.max(scaled - 1.0, axis=0)
    high = np.min(scaled + 1.0, axis=0)
    if np.any(low > high + 2 * SOLVER_MARGIN):
        return None
    return origin + (low - SOLVER_MARGIN) * radius_m, origin + (high + SOLVER_MARGIN) * radius_m
