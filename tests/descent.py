"""Following the true pose's cell down the search's levels: the test of every bound a rejection uses."""

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.solver.cells import root_cells
from fixwizard.solver.search import SearchProblem, filter_cells, split, splittable, start_position_grid


def level_losing_the_true_cell(problem: SearchProblem, base_T_fix: np.ndarray, finest_m: float) -> int | None:
    """Descend from the root keeping only the cell holding ``base_T_fix``, until its cells' position bound and
    rotation chord at the fixture's radius are both below ``finest_m`` (or neither grid splits further): the level
    at which no cell holds it any more, or None."""
    cells, parents = root_cells(start_position_grid(problem)), None
    for level in range(200):
        parents = filter_cells(problem, cells, parents)
        rotation = cells.rotation_grid.cell_of(parents.cells.rotation_level, Rotation.from_matrix(base_T_fix[:3, :3]))
        position = parents.cells.position_grid.cell_of(parents.cells.position_level, base_T_fix[:3, 3])
        mask = (parents.cells.rotation_cells == rotation[0]) & np.all(parents.cells.position_cells == position, axis=1)
        if not np.any(mask):
            return level
        parents = parents.subset(mask)
        family = parents.cells
        chord_m = problem.fixture_radius_m * 2 * np.sin(float(np.max(family.distinct_rotations()[1])) / 2)
        if (family.position_bound_m < finest_m and chord_m < finest_m) or not splittable(family):
            return None
        cells = split(parents, problem)
    raise AssertionError("the descent did not reach cells that fine")
