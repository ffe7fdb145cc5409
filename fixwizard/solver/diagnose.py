"""Which tap makes a set of taps inconsistent: leave each out and see whether the rest fit.

Each leave-one-out search runs at the cell budget it is given: while the suspect tap is still
in, the search empties early and costs little; only the removal that restores consistency runs
to the end.
"""

import threading
from dataclasses import dataclass, replace

import numpy as np

from fixwizard.solver.cells import CellSet
from fixwizard.solver.search import SearchProblem, search


@dataclass(frozen=True)
class SuspectTap:
    """Tap ``index`` (0-based) lies about ``distance_m`` off the ball-offset surface under the poses
    the other taps allow (the smallest residual over their cells' centres)."""

    index: int
    distance_m: float


def _smallest_residual_m(problem: SearchProblem, index: int, cells: CellSet) -> float:
    """Smallest ``|s(x) - r_ball|`` (m) of tap ``index`` over the cells' centre poses."""
    rotations, _, rotation_index = cells.distinct_rotations()
    tap = problem.base_p_taps[index]
    queries = np.einsum("nij,nj->ni", rotations.inv().as_matrix()[rotation_index], tap - cells.positions_m())
    return float(np.min(np.abs(problem.oracle.signed_distance_m(queries) - problem.ball_radius_m)))


def find_suspect_tap(problem: SearchProblem, max_cells: float,
                     cancel: threading.Event | None = None) -> SuspectTap | None:
    """The tap whose removal leaves the others consistent (the farthest off if several); None if none."""
    taps = problem.base_p_taps
    if len(taps) <= 3:
        return None
    best: SuspectTap | None = None
    for index in range(len(taps)):
        others = replace(problem, base_p_taps=np.delete(taps, index, axis=0))
        tree = search(others, max_cells, cancel=cancel)
        survivors = None if tree is None else tree.final
        if survivors is None or len(survivors) == 0:
            continue
        residual = _smallest_residual_m(problem, index, survivors.cells)
        if best is None or residual > best.distance_m:
            best = SuspectTap(index, residual)
    return best
