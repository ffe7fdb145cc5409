"""Tighter bounds for the same cell budget: refine only the cells that decide the bounds.

The bounds are maxima over cells of per-cell figures (CAD-origin distance, rotation angle, point
displacement; see ``cell_bound_figures``), so only the outermost cells matter. Each round splits
the cells whose figures lie within ``OUTER_FRACTION`` of a current maximum and filters their
children against every tap (inheriting the parents' intervals); the children replace their
parents. Every pose of the consistent set stays in some kept cell, so the maxima stay guaranteed
while they shrink. Rounds go on, deeper and deeper on the hull only, until the cell budget is
spent (a last round then splits the outermost cells the rest affords), ``MAX_ROUNDS`` have run, or a round no
longer tightens any maximum by ``MIN_GAIN``. A refined
cell whose children all fail keeps figures of zero: when no cell is left, the set holds no pose.
"""

import threading
from collections.abc import Callable

import numpy as np

from fixwizard.solver.estimates import BoundCentre, cell_bound_figures
from fixwizard.solver.search import SearchProblem, Survivors, filter_cells, split, splittable

OUTER_FRACTION = 0.97
MAX_ROUNDS = 40
MIN_GAIN = 0.003


def _outermost(ratios: list[np.ndarray], outer: list[np.ndarray], count: int) -> list[np.ndarray]:
    """The ``outer`` cells whose ratio (figure / current maximum) exceeds that of all but at most ``count`` of them."""
    every = np.concatenate([ratio[mask] for ratio, mask in zip(ratios, outer, strict=True)])
    if count <= 0:
        return [np.zeros_like(mask) for mask in outer]
    threshold = np.partition(every, len(every) - count)[len(every) - count] if count < len(every) else -np.inf
    return [mask & (ratio > threshold) for ratio, mask in zip(ratios, outer, strict=True)]


def refined_largest_figures(problem: SearchProblem, survivors: Survivors, centre: BoundCentre, fix_p_origin: np.ndarray,
                            budget: float, cancel: threading.Event | None = None,
                            rounds: Callable[[int], None] | None = None) -> np.ndarray | None:
    """Largest (CAD-origin distance, rotation angle, point displacement) over the set, refined (see module doc);
    None when refinement rejects every pose of the set. ``rounds``: called with each round's number (1-based) as it
    starts, for progress displays."""
    def pool_of(cells: Survivors) -> tuple[Survivors, np.ndarray]:
        """Cells and their figures (3, N); a refined cell's figures are set to zero (its children hold it)."""
        return cells, cell_bound_figures(cells.cells, centre, fix_p_origin, problem.oracle.hull_vertices_m)

    pools = [pool_of(survivors)]
    largest = pools[0][1].max(axis=1)
    for number in range(1, MAX_ROUNDS + 1):
        ratios = [np.where(splittable(cells.cells), np.max(figures / np.maximum(largest[:, None], 1e-300), axis=0),
                           0.0) for cells, figures in pools]
        outer = [ratio > OUTER_FRACTION for ratio in ratios]
        wanted = 8 * sum(int(np.count_nonzero(mask)) for mask in outer)
        if wanted == 0:
            break
        if wanted > budget:  # a last round on the outermost cells the budget still affords
            outer = _outermost(ratios, outer, int(budget // 8))
            wanted = 8 * sum(int(np.count_nonzero(mask)) for mask in outer)
            if wanted == 0:
                break
        budget -= wanted
        if rounds is not None:
            rounds(number)
        by_level: dict[tuple[int, int], list[Survivors]] = {}
        for (cells, figures), mask in zip(pools, outer, strict=True):
            if np.any(mask):
                level = (cells.cells.rotation_level, cells.cells.position_level)
                by_level.setdefault(level, []).append(cells.subset(mask))
                figures[:, mask] = 0.0
        for parts in by_level.values():
            parents = Survivors.concatenate(parts)
            children = filter_cells(problem, split(parents, problem), parents, cancel)
            if len(children):
                pools.append(pool_of(children))
        tightened = np.max([figures.max(axis=1) for _, figures in pools], axis=0)
        gain = np.max(1.0 - tightened / np.maximum(largest, 1e-300))
        largest = tightened
        if gain < MIN_GAIN:
            break
    return largest if np.all(largest > 0.0) else None
