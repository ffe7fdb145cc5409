"""Which tap makes a set of taps inconsistent: leave each out and see whether the rest fit."""

from dataclasses import dataclass, replace

import numpy as np

from fixwizard.solver.search import SearchProblem, search

DIAGNOSIS_MAX_CELLS = 5e4


@dataclass(frozen=True)
class SuspectTap:
    """Tap ``index`` (0-based) is off the surface by at least ``distance_m`` under every pose the others allow."""

    index: int
    distance_m: float


def _smallest_violation_m(problem: SearchProblem, index: int, cells) -> float:
    """Smallest ``|d(x) - r_ball|`` of tap ``index`` over the cell centres (m)."""
    tap = problem.base_p_taps[index]
    rotations, _, rotation_index = cells.distinct_rotations()
    queries = np.einsum("nij,nj->ni", rotations.inv().as_matrix()[rotation_index], tap - cells.positions_m())
    residual = problem.oracle.signed_distance_m(queries) - problem.ball_radius_m
    return float(np.min(np.abs(residual)))


def find_suspect_tap(problem: SearchProblem, max_cells: float) -> SuspectTap | None:
    """The tap whose removal leaves the others consistent and which lies farthest from the surface; None if none."""
    budget = min(max_cells, DIAGNOSIS_MAX_CELLS)
    taps = problem.base_p_taps
    best: SuspectTap | None = None
    for index in range(len(taps)):
        others = replace(problem, base_p_taps=np.delete(taps, index, axis=0))
        if len(others.base_p_taps) < 3:
            return None
        cells = search(others, budget)
        if cells is None or len(cells) == 0:
            continue
        violation = _smallest_violation_m(problem, index, cells)
        if best is None or violation > best.distance_m:
            best = SuspectTap(index, violation)
    return best
