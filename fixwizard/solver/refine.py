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

Two stages share the budget. The joint rounds (all three figures, ``1 - DISPLACEMENT_SHARE`` of it) are spent
mostly on the CAD-origin distance: many cells lie within a few per cent of its maximum (on the user study's
student 2, 85 % of the cells they split were there for it alone). The point displacement's maximum lies on a
few cells, so its rounds are cheap, but they stop with the joint budget. Rounds on the displacement alone then
spend the rest (``DISPLACEMENT_SHARE``): on the four real runs the displacement bound shrinks by another 2-11 % in
them (student 2's from 1.37 to 1.22 times its reach), while splitting a cell can only tighten the other two.
(A tighter per-cell displacement bound, exact for the cell's rotation ball and position cube, gained only 0.2 %:
the looseness is in the cells' size, not in the per-cell bound.)
"""

import threading
from collections.abc import Callable

import numpy as np

from fixwizard.solver.estimates import BoundCentre, cell_bound_figures
from fixwizard.solver.search import SearchProblem, Survivors, filter_cells, split, splittable

OUTER_FRACTION = 0.97
MAX_ROUNDS = 40  # per stage
MIN_GAIN = 0.003
DISPLACEMENT_SHARE = 1 / 5
ALL_FIGURES = (0, 1, 2)
DISPLACEMENT = (2,)  # the row of the point displacement in the figures


def _outermost(ratios: list[np.ndarray], outer: list[np.ndarray], count: int) -> list[np.ndarray]:
    """At most ``count`` of the ``outer`` cells, those with the largest ratios (figure / current maximum), ties
    broken arbitrarily: a set that spans every rotation has thousands of cells at the largest angle, pi, and a
    threshold between ratios chose none of them, so the refinement stopped before its first round."""
    every = np.concatenate([ratio[mask] for ratio, mask in zip(ratios, outer, strict=True)])
    if count >= len(every):
        return [mask.copy() for mask in outer]
    chosen = np.zeros(len(every), bool)
    if count > 0:
        chosen[np.argpartition(-every, count - 1)[:count]] = True
    picked, start = [], 0
    for mask in outer:
        indices = np.flatnonzero(mask)
        cells = np.zeros_like(mask)
        cells[indices[chosen[start:start + len(indices)]]] = True
        picked.append(cells)
        start += len(indices)
    return picked


Pool = tuple[Survivors, np.ndarray]


class _Refinement:
    """The pools of cells (each with its figures (3, N)) that hold the set, and the rounds that split them."""

    def __init__(self, problem: SearchProblem, survivors: Survivors, centre: BoundCentre, fix_p_origin: np.ndarray,
                 cancel: threading.Event | None, rounds: Callable[[int], None] | None):
        self.problem, self.centre, self.fix_p_origin = problem, centre, fix_p_origin
        self.cancel, self.rounds, self.number = cancel, rounds, 0
        self.pools = [self.pool_of(survivors)]

    def pool_of(self, cells: Survivors) -> Pool:
        """Cells and their figures (3, N); a refined cell's figures are set to zero (its children hold it)."""
        return cells, cell_bound_figures(cells.cells, self.centre, self.fix_p_origin,
                                         self.problem.oracle.hull_cover)

    def largest(self) -> np.ndarray:
        return np.max([figures.max(axis=1) for _, figures in self.pools], axis=0)

    def stage(self, budget: float, rows: tuple[int, ...]) -> None:
        """Rounds on the figures ``rows`` until ``budget`` cells are spent, ``MAX_ROUNDS`` have run or a round
        tightens none of them by ``MIN_GAIN``."""
        largest = self.largest()
        chosen = list(rows)
        for _ in range(MAX_ROUNDS):
            ratios = [np.where(splittable(cells.cells),
                               np.max(figures[chosen] / np.maximum(largest[chosen, None], 1e-300), axis=0), 0.0)
                      for cells, figures in self.pools]
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
            self.number += 1
            if self.rounds is not None:
                self.rounds(self.number)
            self.split(outer)
            tightened = self.largest()
            gain = np.max(1.0 - tightened[chosen] / np.maximum(largest[chosen], 1e-300))
            largest = tightened
            if gain < MIN_GAIN:
                break

    def split(self, outer: list[np.ndarray]) -> None:
        """Replace the ``outer`` cells of each pool by their children that no tap rejects."""
        by_level: dict[tuple[int, int], list[Survivors]] = {}
        for (cells, figures), mask in zip(self.pools, outer, strict=True):
            if np.any(mask):
                level = (cells.cells.rotation_level, cells.cells.position_level)
                by_level.setdefault(level, []).append(cells.subset(mask))
                figures[:, mask] = 0.0
        for parts in by_level.values():
            parents = Survivors.concatenate(parts)
            children = filter_cells(self.problem, split(parents, self.problem), parents, self.cancel)
            if len(children):
                self.pools.append(self.pool_of(children))


def refined_largest_figures(problem: SearchProblem, survivors: Survivors, centre: BoundCentre, fix_p_origin: np.ndarray,
                            budget: float, cancel: threading.Event | None = None,
                            rounds: Callable[[int], None] | None = None) -> np.ndarray | None:
    """Largest (CAD-origin distance, rotation angle, point displacement) over the set, refined (see module doc);
    None when refinement rejects every pose of the set. ``rounds``: called with each round's number (1-based) as it
    starts, for progress displays."""
    refinement = _Refinement(problem, survivors, centre, fix_p_origin, cancel, rounds)
    refinement.stage((1.0 - DISPLACEMENT_SHARE) * budget, ALL_FIGURES)
    refinement.stage(DISPLACEMENT_SHARE * budget, DISPLACEMENT)
    largest = refinement.largest()
    return largest if np.all(largest > 0.0) else None
