"""Tighter bounds for the same cell budget: refine only the cells that decide the bounds.

The bounds are maxima over cells, so only the outermost cells matter. Those within
``OUTER_FRACTION`` of a maximum (the outermost ones only, if the budget cannot take them all) are
split once more and their children filtered against every tap; the bounds are then the maxima over
the untouched cells and the surviving children. Every pose of the consistent set lies in one of
those, so the bounds stay guaranteed. Repeated for a few rounds within the unused part of the cell
budget.
"""

import numpy as np

from fixwizard.solver.estimates import BoundCentre, cell_bound_figures
from fixwizard.solver.search import SearchProblem, Survivors, filter_cells, split

OUTER_FRACTION = 0.9
ROUNDS = 3


def refined_largest_figures(problem: SearchProblem, survivors: Survivors, centre: BoundCentre, fix_p_origin: np.ndarray,
                            budget: float) -> np.ndarray:
    """Largest (CAD-origin distance, rotation angle, point displacement) over the set, refined; see module doc."""
    figures = cell_bound_figures(survivors.cells, centre, fix_p_origin, problem.fixture_radius_m)
    settled = np.zeros(3)
    for _ in range(ROUNDS):
        largest = np.maximum(settled, figures.max(axis=1))
        score = np.max(figures / np.maximum(largest[:, None], 1e-300), axis=0)
        outer = score > OUTER_FRACTION
        if 8 * np.count_nonzero(outer) > budget:
            outer = score >= np.sort(score)[-int(budget // 8)] if budget >= 8 else np.zeros(len(score), bool)
        if not np.any(outer):
            break
        if np.any(~outer):
            settled = np.maximum(settled, figures[:, ~outer].max(axis=1))
        parents = survivors.subset(outer)
        children = split(parents, problem)
        budget -= len(children)
        survivors = filter_cells(problem, children, parents)
        if len(survivors) == 0:
            return settled
        figures = cell_bound_figures(survivors.cells, centre, fix_p_origin, problem.fixture_radius_m)
    return np.maximum(settled, figures.max(axis=1))
