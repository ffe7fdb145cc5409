"""Hierarchical branch-and-bound over SE(3): every pose that explains the taps survives.

A pose ``base_T_fix = (R, t)`` explains tap ``p_i`` (base frame) when the ball centre lies
at the ball radius from the surface: ``|s(R^T (p_i - t)) - r_ball| <= b_s`` with ``s`` the
signed distance (unsigned for an open mesh). A cell with centre ``(R_c, t_c)``, position
bound ``b_p`` and rotation bound ``gamma`` is rejected only if some tap violates
``|s(x_i) - r_ball| <= b_s + b_p + b_r,i`` for every value ``s(x_i)`` can take at the
centre's query point ``x_i = R_c^T (p_i - t_c)`` (an interval that holds the float32 error
``b_eps``), with lever-arm term ``b_r,i = min(|x_i| + b_p, r + r_ball + b_s) * 2 sin(gamma / 2)``.
The distance is 1-Lipschitz, so no pose inside a rejected cell can explain all taps.

Each surviving cell keeps, per tap, an interval holding ``s`` at its query point and a mesh face.
A child's query point lies ``|x_child - x_parent|`` from its parent's, so the parent's interval
widened by that much holds the child's value; the distance from the child's query point to the
parent's face (any single face) bounds ``|s|`` from above, and a precomputed distance lattice
(``distance_grid``) narrows the interval further. This cheap test runs compiled (``interval_kernel``)
for every tap, the tap that rejected most at the previous level first; exact queries of the float64 mesh
hierarchy then settle the intervals that still straddle a band's edge, tap by tap, for the cells no tap
rejected, in the same compiled pass, and need no inside test where the interval already proves the point
outside. The few whose sign that pass cannot tell (closest point on an edge or a corner) go to the oracle.

``add_taps`` goes on from an earlier set when taps are added: a new tap can only remove poses.
"""

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from fixwizard.fixture import DistanceOracle
from fixwizard.geometry.octree import MAX_LEVEL as POSITION_MAX_LEVEL
from fixwizard.geometry.octree import PositionGrid
from fixwizard.geometry.so3_grid import MAX_LEVEL as ROTATION_MAX_LEVEL
from fixwizard.geometry.so3_grid import chord
from fixwizard.geometry.socp_box import ball_intersection_box
from fixwizard.solver.cells import CellSet, root_cells
from fixwizard.solver.distance_grid import DistanceGrid, distance_grid_for
from fixwizard.solver.interval_kernel import NOT_REJECTED, filter_pass, query_band

QUERY_CHUNK = 1 << 17  # cells per batch (a multiple of 8: whole families); a cancel is seen between batches
CHUNK_CELL_TAPS = 1 << 23  # at most this many cell-tap pairs per batch (~100 MB of per-tap arrays), any tap count
RESTART_ROOT_SHRINK = 0.95
# The uniform descent stops before a level would evaluate more than UNIFORM_SHARE of the cell budget
# (refining the hull takes over from there), unless its cells are still coarse (a cell spans more than
# COARSE_FRACTION of the fixture radius): such a level may use the whole budget, since stopping there would leave
# bounds of centimetres (or sets spanning every rotation) that the next few levels shrink to millimetres. An
# exhaustive search (to prove a set empty) descends as long as its levels together stay within the budget; a quick
# one (the live check after each tap) goes on at coarse levels only while the taps still prune hard (under
# PRUNING_RATIO of a level's cells survive): a set of a few taps, which they barely prune, is then answered in
# seconds, as undetermined. ``no_deeper`` adds new taps to a previous search without a level below it (the live
# check's first look after a tap: the previous set filtered against the new tap); a search from scratch then
# descends as a quick one.
UNIFORM_SHARE = 1 / 12
COARSE_FRACTION = 0.05
PRUNING_RATIO = 0.25
Descent = Literal["thorough", "quick", "exhaustive", "no_deeper"]


class SearchCancelled(Exception):
    """The caller asked the search to stop."""


@dataclass(frozen=True)
class SearchProblem:
    """Inputs of the search. Taps ``base_p_taps`` (N, 3) in m; radii and bounds in m."""

    oracle: DistanceOracle
    fixture_radius_m: float
    base_p_taps: np.ndarray
    ball_radius_m: float
    sample_bound_m: float

    @property
    def tap_bound_m(self) -> float:
        """How far a tap's ball centre may lie off ``ball_radius_m`` from the oracle's surface: the sample bound,
        plus how far that surface may lie from the exported one (``DistanceOracle.surface_offset_m``)."""
        return self.sample_bound_m + self.oracle.surface_offset_m

    @property
    def lever_cap_m(self) -> float:
        """Largest distance from the fixture centre to any tap: ``r + r_ball + b_s`` (``tap_bound_m``)."""
        return self.fixture_radius_m + self.ball_radius_m + self.tap_bound_m


@dataclass(frozen=True)
class SearchProgress:
    """One finished level of the search, for progress displays."""

    rotation_level: int
    position_level: int
    evaluated: int
    survivors: int
    elapsed_s: float
    final: bool = False


def start_position_grid(problem: SearchProblem) -> PositionGrid | None:
    """Root cube around the SOCP box of possible fixture centres; None if no centre is possible."""
    box = ball_intersection_box(problem.base_p_taps, problem.lever_cap_m)
    if box is None:
        return None
    low, high = box
    side = float(np.max(high - low))
    return PositionGrid(corner_m=0.5 * (low + high) - 0.5 * side, side_m=side)


def _round_down_f32(values: np.ndarray) -> np.ndarray:
    """float32 values no larger than the float64 ones (a cast errs by at most |v| 2^-24)."""
    return (values - np.abs(values) * 2.0**-23).astype(np.float32)


def _round_up_f32(values: np.ndarray) -> np.ndarray:
    return (values + np.abs(values) * 2.0**-23).astype(np.float32)


def exact_distance_interval_m(oracle: DistanceOracle, fix_p_query: np.ndarray, outside: np.ndarray | None = None,
                              hint_faces: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interval (m) holding the signed distance of each query point (unsigned for open meshes), and the face
    closest to each point. ``outside``: points already known to lie outside the solid, whose signed distance is
    the unsigned one (no inside test needed). ``hint_faces``: a face near each point (-1 for none), for speed."""
    return oracle.distance_interval_m(fix_p_query, None if outside is None else ~outside, hint_faces)


class _Frames:
    """Centre frames of a CellSet's cells: ``R_c^T`` per distinct rotation, and ``chord(gamma)`` of each."""

    def __init__(self, cells: CellSet, fix_R_base: np.ndarray | None = None, chords: np.ndarray | None = None):
        if fix_R_base is None or chords is None:  # both or neither are given
            base_R_fix, gammas_rad = cells.distinct_rotation_matrices()
            fix_R_base = np.ascontiguousarray(np.swapaxes(base_R_fix, 1, 2))
            chords = chord(gammas_rad)
        self.fix_R_base = fix_R_base
        self.chords = chords
        self.rotation_index = cells.rotation_index
        self.cells = cells

    @staticmethod
    def concatenate(parts: list["_Frames"]) -> "_Frames":
        """The frames of ``CellSet.concatenate`` of the parts' cells."""
        return _Frames(CellSet.concatenate([part.cells for part in parts]),
                       np.concatenate([part.fix_R_base for part in parts]),
                       np.concatenate([part.chords for part in parts]))

    def subset(self, alive: np.ndarray) -> "_Frames":
        """The frames of the cells where ``alive`` is true (same compaction as ``CellSet.subset``)."""
        used = np.zeros(len(self.fix_R_base), bool)
        used[self.rotation_index[alive]] = True
        return _Frames(self.cells.subset(alive), self.fix_R_base[used], self.chords[used])


@dataclass
class Survivors:
    """Cells that passed every tap, with ``R_c^T t_c`` (m) and, per tap, an interval (m, float32, shape
    (cells, taps)) holding the signed distance at the cell centre's query point and a face whose distance
    bounds it from above. ``tap_order``: the taps that rejected most cells first, the order the next level
    tests them in. ``parent_index``: each cell's parent, a row of the previous level's survivors (-1 where
    there is none)."""

    frames: _Frames
    rotated_positions: np.ndarray
    low_m: np.ndarray
    high_m: np.ndarray
    faces: np.ndarray
    tap_order: np.ndarray
    parent_index: np.ndarray

    @property
    def cells(self) -> CellSet:
        return self.frames.cells

    def __len__(self) -> int:
        return len(self.frames.cells)

    @staticmethod
    def concatenate(parts: list["Survivors"]) -> "Survivors":
        """One set of the survivors of several sets at the same levels (searched with the same taps); their
        parents are not one level, so none is recorded."""
        return Survivors(_Frames.concatenate([part.frames for part in parts]),
                         np.concatenate([part.rotated_positions for part in parts]),
                         np.concatenate([part.low_m for part in parts]),
                         np.concatenate([part.high_m for part in parts]),
                         np.concatenate([part.faces for part in parts]), parts[0].tap_order,
                         np.full(sum(len(part) for part in parts), -1))

    def subset(self, mask: np.ndarray) -> "Survivors":
        """The survivors where ``mask`` is true, with their intervals."""
        return Survivors(self.frames.subset(mask), self.rotated_positions[mask], self.low_m[mask], self.high_m[mask],
                         self.faces[mask], self.tap_order, self.parent_index[mask])

    def without_intervals(self) -> "Survivors":
        """The same cells without their per-tap intervals (a level a search has gone below)."""
        empty = np.zeros((len(self), 0), np.float32)
        return Survivors(self.frames, self.rotated_positions, empty, empty, empty.astype(np.int32), self.tap_order,
                         self.parent_index)


def _filter_chunk(problem: SearchProblem, frames: _Frames, first: int, count: int, parents: Survivors | None,
                  parent_index: np.ndarray, grid: DistanceGrid, tap_order: np.ndarray,
                  cancel: threading.Event | None) -> tuple[np.ndarray, ...]:
    """Survivor mask; ``R_c^T t_c``, distance intervals and faces of the survivors among cells
    ``first .. first + count``; the tap that rejected each cell (``NOT_REJECTED`` for survivors).

    One compiled pass (``interval_kernel.filter_pass``): per cell, every tap first rejects what the inherited
    intervals and the lattice decide, then exact queries settle the intervals still straddling the band, tap by
    tap, if no tap has rejected the cell. The few the compiled pass cannot sign (closest point on an edge or a
    corner) are then settled by the oracle, tap by tap, for the cells still alive.
    """
    if cancel is not None and cancel.is_set():
        raise SearchCancelled
    chunk = slice(first, first + count)
    taps = len(problem.base_p_taps)
    rotation_index = frames.rotation_index[chunk]
    rotated_positions = np.empty((count, 3))
    low = np.empty((count, taps), np.float32)  # the kernel sets every tap of the cells no tap rejects
    high = np.empty_like(low)
    faces = np.empty((count, taps), np.int32)
    straddling = np.zeros((count, taps), bool)
    deferred = np.zeros((count, taps), bool)
    rejected_by = np.empty(count, np.int64)
    if parents is None:
        parent_arrays = (np.zeros((0, 3, 3)), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, taps), np.float32),
                         np.zeros((0, taps), np.float32), np.zeros((0, taps), np.int32))
    else:
        parent_arrays = (parents.frames.fix_R_base, parents.frames.rotation_index, parents.rotated_positions,
                         parents.low_m, parents.high_m, parents.faces)
    band_figures = (problem.ball_radius_m, problem.tap_bound_m, frames.cells.position_bound_m, problem.lever_cap_m)
    position_grid, position_level = frames.cells.position_grid, frames.cells.position_level
    cells = (frames.fix_R_base, rotation_index, frames.cells.position_cells[chunk], frames.chords,
             np.append(position_grid.corner_m, position_grid.cell_side_m(position_level)))
    filter_pass(cells, (problem.base_p_taps, np.asarray(tap_order, np.int64)), band_figures, parent_index[chunk],
                parent_arrays, grid.kernel_arguments, problem.oracle.kernel_arguments,
                (rotated_positions, low, high, faces, straddling, rejected_by, deferred))
    for tap_index in tap_order:
        if cancel is not None and cancel.is_set():
            raise SearchCancelled
        rows = np.flatnonzero((rejected_by == NOT_REJECTED) & deferred[:, tap_index])
        if len(rows) == 0:
            continue
        queries, band_low, band_high = query_band(cells, rotated_positions, rows, np.full(len(rows), tap_index),
                                                  problem.base_p_taps, band_figures)
        interval_low, interval_high, closest_faces = exact_distance_interval_m(problem.oracle, queries,
                                                                               low[rows, tap_index] > 0.0,
                                                                               faces[rows, tap_index])
        keep = (interval_high >= band_low) & (interval_low <= band_high)
        rejected_by[rows[~keep]] = tap_index
        rows = rows[keep]
        low[rows, tap_index] = _round_down_f32(interval_low[keep])
        high[rows, tap_index] = _round_up_f32(interval_high[keep])
        faces[rows, tap_index] = closest_faces[keep]
    alive = rejected_by == NOT_REJECTED
    return alive, rotated_positions[alive], low[alive], high[alive], faces[alive], rejected_by


def _filter(problem: SearchProblem, frames: _Frames, parents: Survivors | None, tap_order: np.ndarray,
            cancel: threading.Event | None, parent_index: np.ndarray | None = None) -> tuple[np.ndarray, Survivors]:
    """Which cells (of ``frames``) survive the taps of ``tap_order``, and the survivors (their intervals are set
    for those taps; the next level tests the taps that rejected most first). ``parent_index``: each cell's row in
    ``parents`` (default: eight children per parent, in order)."""
    cells = frames.cells
    grid = distance_grid_for(problem.oracle)
    if parent_index is None:
        parent_index = np.arange(len(cells)) // 8 if parents is not None else np.full(len(cells), -1)
    chunk = max(8, min(QUERY_CHUNK, CHUNK_CELL_TAPS // len(problem.base_p_taps)) // 8 * 8)
    starts = range(0, len(cells), chunk)
    parts = [_filter_chunk(problem, frames, first, min(chunk, len(cells) - first), parents, parent_index,
                           grid, tap_order, cancel) for first in starts]
    alive, rotated_positions, low, high, faces, rejected_by = (np.concatenate([part[i] for part in parts])
                                                               for i in range(6))
    rejected = np.bincount(rejected_by[rejected_by != NOT_REJECTED], minlength=len(problem.base_p_taps))
    order = np.asarray(tap_order)[np.argsort(-rejected[tap_order], kind="stable")]
    return alive, Survivors(frames.subset(alive), rotated_positions, low, high, faces, order, parent_index[alive])


def rotation_splits_first(cells: CellSet, problem: SearchProblem) -> bool:
    """Split rotations when their largest displacement at the fixture radius exceeds the position bound (and they
    are not at the grid's finest level)."""
    if cells.rotation_level >= ROTATION_MAX_LEVEL:
        return False
    if cells.position_level >= POSITION_MAX_LEVEL:
        return True
    gamma = float(np.max(cells.rotation_grid.gamma(cells.rotation_level, cells.rotation_ids)))
    rotation_bound = problem.fixture_radius_m * chord(gamma)
    return rotation_bound >= cells.position_bound_m


def splittable(cells: CellSet) -> bool:
    """Whether the cells can be split once more (both grids have a finest level)."""
    return cells.rotation_level < ROTATION_MAX_LEVEL or cells.position_level < POSITION_MAX_LEVEL


def split(survivors: Survivors, problem: SearchProblem) -> CellSet:
    """The next level below the survivors: their rotations or positions split, eight children per survivor."""
    cells = survivors.cells
    return cells.split_rotations() if rotation_splits_first(cells, problem) else cells.split_positions()


def filter_cells(problem: SearchProblem, cells: CellSet, parents: Survivors | None = None,
                 cancel: threading.Event | None = None) -> Survivors:
    """The cells of a set that no tap rejects. ``parents``: the survivors the cells are children of
    (eight per parent, in order), whose intervals then decide most children without a query, and whose centre
    rotations children split in position share."""
    tap_order = np.arange(len(problem.base_p_taps)) if parents is None else parents.tap_order
    if parents is not None and cells.rotation_ids is parents.cells.rotation_ids:  # split in position
        frames = _Frames(cells, parents.frames.fix_R_base, parents.frames.chords)
    else:
        frames = _Frames(cells)
    return _filter(problem, frames, parents, tap_order, cancel)[1]


@dataclass
class SearchTree:
    """The survivors of every level of a search, coarse to fine; only the finest keep their intervals.
    ``evaluated``: the cells the finest level was chosen from (the children of the level above); ``spent``: the
    cells evaluated by all levels so far."""

    levels: list[Survivors]
    evaluated: int
    spent: int = 0

    @property
    def final(self) -> Survivors:
        return self.levels[-1]


def search_budget(max_cells: float) -> float:
    """The cells a level of the uniform descent may evaluate once its cells are fine (see UNIFORM_SHARE)."""
    return max_cells * UNIFORM_SHARE


def _descends(problem: SearchProblem, tree: SearchTree, max_cells: float, descent: Descent) -> bool:
    """Whether the uniform descent splits the finest survivors once more within the cell budget (see ``Descent``)."""
    cells = tree.final.cells
    if len(cells) == 0 or not splittable(cells) or descent == "no_deeper":
        return False
    if descent == "exhaustive":  # as long as the budget allows, as a total over the levels
        return tree.spent + 8 * len(cells) <= max_cells
    if 8 * len(cells) > max_cells:
        return False
    if 8 * len(cells) <= search_budget(max_cells):
        return True
    gamma = float(np.max(cells.rotation_grid.gamma(cells.rotation_level, cells.rotation_ids)))
    span_m = cells.position_bound_m + problem.fixture_radius_m * chord(gamma)
    coarse = span_m > COARSE_FRACTION * problem.fixture_radius_m
    return coarse and (descent == "thorough" or len(cells) < PRUNING_RATIO * tree.evaluated)


def _descend(problem: SearchProblem, tree: SearchTree, max_cells: float, started: float,
             progress: Callable[[SearchProgress], None] | None, cancel: threading.Event | None,
             descent: Descent = "thorough") -> SearchTree:
    """Split and filter level after level while ``_descends`` says so; reports every level."""
    while True:
        descends = _descends(problem, tree, max_cells, descent)
        _report(progress, tree.evaluated, tree.final, started, final=not descends)
        if not descends:
            return tree
        cells = split(tree.final, problem)
        survivors = filter_cells(problem, cells, tree.final, cancel)
        tree.levels[-1] = tree.final.without_intervals()
        tree.levels.append(survivors)
        tree.evaluated = len(cells)
        tree.spent += len(cells)


def _report(progress: Callable[[SearchProgress], None] | None, evaluated: int, survivors: Survivors,
            started: float, final: bool) -> None:
    if progress is not None:
        cells = survivors.cells
        progress(SearchProgress(cells.rotation_level, cells.position_level, evaluated, len(cells),
                                time.perf_counter() - started, final))


def search(problem: SearchProblem, max_cells: float = 1e7,
           progress: Callable[[SearchProgress], None] | None = None,
           cancel: threading.Event | None = None, descent: Descent = "thorough") -> SearchTree | None:
    """Survivors of every level down to the finest the cell budget allows (the finest empty if no pose fits).
    ``descent``: how far to go (see ``Descent`` above UNIFORM_SHARE).

    Returns None when the taps are too far apart for any pose (no possible fixture centre).
    """
    started = time.perf_counter()
    position_grid = start_position_grid(problem)
    if position_grid is None:
        return None
    cells = root_cells(position_grid)
    survivors = filter_cells(problem, cells, cancel=cancel)
    return _descend(problem, SearchTree([survivors], len(cells), len(cells)), max_cells, started, progress, cancel,
                    "quick" if descent == "no_deeper" else descent)


def descend(problem: SearchProblem, tree: SearchTree, max_cells: float = 1e7,
            progress: Callable[[SearchProgress], None] | None = None,
            cancel: threading.Event | None = None, descent: Descent = "thorough") -> SearchTree:
    """``tree``, searched for ``problem``'s taps, taken further down as ``descent`` says (e.g. after a ``no_deeper``
    first look); ``tree`` itself is left as it was."""
    return _descend(problem, SearchTree(list(tree.levels), tree.evaluated, tree.spent), max_cells,
                    time.perf_counter(), progress, cancel, descent)


def worth_extending(problem: SearchProblem, previous: SearchTree) -> bool:
    """Whether ``add_taps`` should go on from ``previous``: not when the new taps shrink the root cube of
    possible fixture centres below ``RESTART_ROOT_SHRINK`` of its side, since a search from that smaller
    root reaches finer cells for the same budget."""
    position_grid = start_position_grid(problem)
    return position_grid is not None and (position_grid.side_m
                                          >= RESTART_ROOT_SHRINK * previous.final.cells.position_grid.side_m)


def _add_taps_to_finest(new_problem: SearchProblem, previous: SearchTree, new_taps: np.ndarray, started: float,
                        progress: Callable[[SearchProgress], None] | None,
                        cancel: threading.Event | None) -> SearchTree:
    """``previous`` with its finest level filtered against ``new_problem``'s taps (those it was not searched with),
    every cell from the lattice and exact queries (no parent's intervals: the level above is not filtered against
    them)."""
    final = previous.final
    if len(final) == 0:
        return previous
    known = final.low_m.shape[1]
    alive, new = _filter(new_problem, final.frames, None, new_taps, cancel)
    kept = Survivors(new.frames, new.rotated_positions, np.hstack([final.low_m[alive], new.low_m]),
                     np.hstack([final.high_m[alive], new.high_m]), np.hstack([final.faces[alive], new.faces]),
                     np.concatenate([known + new.tap_order, final.tap_order]), final.parent_index[alive])
    _report(progress, len(final), kept, started, final=True)
    return SearchTree(previous.levels[:-1] + [kept], previous.evaluated, previous.spent)


def add_taps(problem: SearchProblem, previous: SearchTree, max_cells: float = 1e7,
             progress: Callable[[SearchProgress], None] | None = None,
             cancel: threading.Event | None = None, descent: Descent = "thorough") -> SearchTree:
    """The search tree for ``problem``, whose taps extend those ``previous`` was searched with.

    New taps can only remove poses: level by level from the root, the previous survivors whose parent
    still survives are filtered against the new taps alone (intervals of those taps only, until the finest
    level takes the previous intervals beside them). With fewer survivors, the finest level may then be
    split further within the cell budget: the same set a search from scratch reaches, for a fraction of the
    work. ``no_deeper`` filters the finest level alone (the levels above stay as they were: they hold every
    pose still, and more), for an answer in a fraction of the time where the coarse levels are large.
    """
    started = time.perf_counter()
    known = previous.final.low_m.shape[1]
    new_problem = replace(problem, base_p_taps=problem.base_p_taps[known:])
    new_taps = np.arange(len(new_problem.base_p_taps))
    if descent == "no_deeper":
        return _add_taps_to_finest(new_problem, previous, new_taps, started, progress, cancel)
    levels: list[Survivors] = []
    level_alive = np.zeros(0, bool)
    for depth, level in enumerate(previous.levels):
        candidates = np.ones(len(level), bool) if depth == 0 else level_alive[level.parent_index]
        if not np.any(candidates):
            return SearchTree(levels + [previous.final.subset(np.zeros(len(previous.final), bool))], 0)
        parent_index = None if depth == 0 else (np.cumsum(level_alive) - 1)[level.parent_index[candidates]]
        alive, survivors = _filter(new_problem, level.frames.subset(candidates), levels[-1] if levels else None,
                                   new_taps, cancel, parent_index)
        level_alive = np.zeros(len(level), bool)
        level_alive[np.flatnonzero(candidates)[alive]] = True
        if levels:
            levels[-1] = levels[-1].without_intervals()
        levels.append(survivors)
        if depth < len(previous.levels) - 1:
            _report(progress, int(np.count_nonzero(candidates)), survivors, started, final=False)
    new = levels[-1]
    levels[-1] = Survivors(new.frames, new.rotated_positions,
                           np.hstack([previous.final.low_m[level_alive], new.low_m]),
                           np.hstack([previous.final.high_m[level_alive], new.high_m]),
                           np.hstack([previous.final.faces[level_alive], new.faces]),
                           np.concatenate([known + new.tap_order, previous.final.tap_order]), new.parent_index)
    evaluated = 8 * len(levels[-2]) if len(levels) > 1 else len(levels[0])  # the children a search tests
    # what a search from scratch with every tap would have evaluated to reach these levels
    spent = len(previous.levels[0]) + 8 * sum(len(level) for level in levels[:-1])
    return _descend(problem, SearchTree(levels, evaluated, spent), max_cells, started, progress, cancel, descent)
