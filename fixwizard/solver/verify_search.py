"""Has the fixture moved? New taps searched against only the poses an earlier guaranteed set allows.

An earlier result guarantees that every pose that explained its taps lies within its bounds: the CAD origin
within ``position_m`` of the centre's, the rotation within ``rotation_rad`` of the centre's (``AllowedRegion``).
This module searches exactly the cells that can hold such a pose, with the search's own filter
(``search.filter_cells`` and ``search.split``, level by level, each child tested against every tap): the start
cells are the rotation cells of the HealPix grid that overlap the rotation ball (a cell's rotations all lie
within its ``gamma`` of its centre) times one position cube holding every internal-frame origin the region
allows. They cover the region (a superset), so when no cell survives at some level no pose of the region
explains the new taps: the fixture has moved, or the taps are off, and that is a proof.

Frames: the region holds ``base_T_cad``; cells hold ``base_T_fix = base_T_cad @ cad_T_fix`` with the internal
origin at ``cad_p_center`` (CAD frame), which lies ``|cad_p_center| * 2 sin(a / 2)`` farther from the centre's
for a rotation by ``a``.
"""

import threading
import time
from dataclasses import dataclass

import numpy as np

from fixwizard.fixture import Fixture
from fixwizard.geometry.octree import PositionGrid
from fixwizard.geometry.se3 import rotation_angle_rad
from fixwizard.geometry.so3_grid import RotationGrid, chord
from fixwizard.solver.cells import CellSet
from fixwizard.solver.search import SearchProblem, Survivors, filter_cells, split

DEFAULT_MAX_CELLS = 1e6  # cells one level may test: about a second each
# Descend until a cell's slack (position bound plus rotation bound at the fixture radius) is this share of the
# sample bound: surviving cells then hold poses that explain the taps within very nearly the sample bound.
FINE_SHARE = 0.05
MAX_LEVELS = 40
MAX_START_LEVEL = 20  # rotation cells of about 1e-6 rad: finer start cells would gain nothing (and HealPix ends at 29)
MARGIN_M = 1e-9  # float slack on the start cube's half side and the rotation ball (1e-9 rad)
# The smallest sample bound that explains the taps within the region: doubled from the given one up to this,
# then bisected; each probe at a smaller budget (it only tells empty from not empty).
MAX_PROBE_BOUND_M = 0.02
PROBE_MAX_CELLS = 5e5
BISECTIONS = 2


@dataclass(frozen=True)
class AllowedRegion:
    """Every pose ``base_T_cad`` whose CAD origin lies within ``position_m`` of ``base_T_cad_center``'s and whose
    rotation lies within ``rotation_rad`` of its rotation."""

    base_T_cad_center: np.ndarray
    position_m: float
    rotation_rad: float


@dataclass(frozen=True)
class RegionSearch:
    """What the search of a region found. ``survivors``: the cells of the last level searched (empty: no pose of
    the region explains the taps, a proof); ``slack_m``: those cells' position bound plus their rotation bound at
    the fixture radius (a survivor's pose explains every tap within about the sample bound plus twice this);
    ``levels``: levels searched; ``evaluated``: cells tested in all. ``slack_m`` is of the last level tested."""

    survivors: Survivors
    slack_m: float
    levels: int
    evaluated: int
    elapsed_s: float

    @property
    def moved(self) -> bool:
        return len(self.survivors) == 0


def _rotation_cells(region: AllowedRegion, grid: RotationGrid) -> tuple[int, np.ndarray]:
    """The level and ids of the rotation cells that overlap the region's rotation ball: from level 0 down to the
    first level whose cells are no larger than the ball, keeping each cell whose centre lies within the ball's
    radius plus the cell's ``gamma`` of the ball's centre (no rotation of the other cells is within the ball); at
    most down to ``MAX_START_LEVEL``."""
    base_R_center = region.base_T_cad_center[:3, :3]
    level, ids = 0, np.arange(grid.n_cells(0), dtype=np.int64)
    while True:
        gammas = grid.gamma(level, ids)
        angles = rotation_angle_rad(base_R_center.T @ grid.center_matrices(level, ids))
        ids = ids[angles <= region.rotation_rad + gammas + MARGIN_M]
        if float(np.max(gammas)) <= region.rotation_rad or level >= MAX_START_LEVEL:
            return level, ids
        ids, level = grid.children(level, ids), level + 1


def start_cells(region: AllowedRegion, fixture: Fixture) -> CellSet:
    """Cells of ``base_T_fix`` that hold every pose of the region: overlapping rotation cells times one cube
    around the centre's internal origin, of half side ``position_m + |cad_p_center| * chord(rotation_rad)``."""
    grid = RotationGrid()
    level, ids = _rotation_cells(region, grid)
    centre = region.base_T_cad_center
    base_p_fix_center = centre[:3, :3] @ fixture.cad_p_center + centre[:3, 3]
    half_side = (region.position_m + float(np.linalg.norm(fixture.cad_p_center)) * float(chord(region.rotation_rad))
                 + MARGIN_M)
    cube = PositionGrid(corner_m=base_p_fix_center - half_side, side_m=2.0 * half_side)
    return CellSet(grid, cube, level, 0, ids, np.arange(len(ids)), np.zeros((len(ids), 3), np.int32))


def _slack_m(cells: CellSet, fixture_radius_m: float) -> float:
    """A cell's largest position bound plus its largest rotation bound at the fixture radius (m)."""
    gamma = float(np.max(cells.rotation_grid.gamma(cells.rotation_level, cells.rotation_ids), initial=0.0))
    return cells.position_bound_m + fixture_radius_m * float(chord(gamma))


def search_region(fixture: Fixture, region: AllowedRegion, base_p_taps: np.ndarray, ball_diameter_m: float,
                  sample_bound_m: float, max_cells: float = DEFAULT_MAX_CELLS,
                  cancel: threading.Event | None = None) -> RegionSearch:
    """Search the region for poses that explain the taps (N, 3, base frame, m), level by level, until no cell
    survives (moved), the cells are fine (``FINE_SHARE`` of the sample bound) or the next level would test more
    than ``max_cells``. Raises ``SearchCancelled`` when ``cancel`` is set meanwhile."""
    started = time.perf_counter()
    problem = SearchProblem(fixture.oracle, fixture.radius_m, np.asarray(base_p_taps, float).reshape(-1, 3),
                            ball_diameter_m / 2.0, sample_bound_m)
    tested = start_cells(region, fixture)
    survivors = filter_cells(problem, tested, cancel=cancel)
    evaluated, levels = len(tested), 1
    while (len(survivors) and levels < MAX_LEVELS and 8 * len(survivors) <= max_cells
           and _slack_m(tested, fixture.radius_m) > FINE_SHARE * sample_bound_m):
        tested = split(survivors, problem)
        survivors = filter_cells(problem, tested, survivors, cancel)
        evaluated, levels = evaluated + len(tested), levels + 1
    return RegionSearch(survivors, _slack_m(tested, fixture.radius_m), levels, evaluated, time.perf_counter() - started)


@dataclass(frozen=True)
class BoundBracket:
    """The smallest sample bound (m) with which some pose of the region explains the taps lies in
    ``(ruled_out_m, explained_m]``; ``explained_m`` is None when not even ``MAX_PROBE_BOUND_M`` does."""

    ruled_out_m: float
    explained_m: float | None


def smallest_sample_bound(fixture: Fixture, region: AllowedRegion, base_p_taps: np.ndarray, ball_diameter_m: float,
                          sample_bound_m: float, cancel: threading.Event | None = None) -> BoundBracket:
    """How far the taps are off the region's poses, as a sample bound: doubled from ``sample_bound_m`` (which is
    ruled out) until some pose is not ruled out, then bisected (geometrically) ``BISECTIONS`` times. The lower end
    is proved (an empty search); the upper end only not ruled out at ``PROBE_MAX_CELLS``."""

    def explained(bound_m: float) -> bool:
        return not search_region(fixture, region, base_p_taps, ball_diameter_m, bound_m, PROBE_MAX_CELLS,
                                 cancel).moved

    low, high = sample_bound_m, None
    while high is None:
        bound = min(2.0 * low, MAX_PROBE_BOUND_M)
        if explained(bound):
            high = bound
        elif bound >= MAX_PROBE_BOUND_M:
            return BoundBracket(bound, None)
        else:
            low = bound
    for _ in range(BISECTIONS):
        middle = float(np.sqrt(low * high))
        low, high = (low, middle) if explained(middle) else (middle, high)
    return BoundBracket(low, high)

