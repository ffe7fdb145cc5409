"""Hierarchical branch-and-bound over SE(3): every pose that explains the taps survives.

A pose ``base_T_fix = (R, t)`` explains tap ``p_i`` (base frame) when the ball centre lies
at the ball radius from the surface: ``|s(R^T (p_i - t)) - r_ball| <= b_s`` with ``s`` the
signed distance (unsigned for an open mesh). A cell with centre ``(R_c, t_c)``, position
bound ``b_p`` and rotation bound ``gamma`` is rejected only if some tap violates
``|s(x_i) - r_ball| <= b_s + b_p + b_r,i`` for every value ``s(x_i)`` can take at the
centre's query point ``x_i = R_c^T (p_i - t_c)`` (an interval that holds the float32 error
``b_eps``), with lever-arm term ``b_r,i = min(|x_i| + b_p, r + r_ball + b_s) * 2 sin(gamma / 2)``.
The distance is 1-Lipschitz, so no pose inside a rejected cell can explain all taps.

Each surviving cell keeps, per tap, an interval holding ``s`` at its query point. A child's
query point lies ``|x_child - x_parent|`` from its parent's, so the parent's interval widened
by that much holds the child's value: most children are accepted or rejected from it, and
then a precomputed distance lattice (``distance_grid``) narrows the interval. Taps are tested
one at a time over the cells still alive, the tap that rejected most at the previous level first;
only after every tap has had its cheap test do Open3D queries settle the intervals that still
straddle a band's edge, for the cells no tap rejected.
"""

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fixwizard.fixture import DistanceOracle
from fixwizard.geometry.octree import PositionGrid
from fixwizard.geometry.so3_grid import chord
from fixwizard.geometry.socp_box import ball_intersection_box
from fixwizard.solver.cells import CellSet, root_cells
from fixwizard.solver.distance_grid import DistanceGrid, distance_grid_for
from fixwizard.solver.interval_kernel import NOT_REJECTED, cheap_pass, query_band

QUERY_CHUNK = 1 << 17  # cells per batch; a multiple of 8 so batches hold whole families
WORKERS = 2  # batches run in threads: numpy and Open3D release the GIL for their array work


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
    def lever_cap_m(self) -> float:
        """Largest distance from the fixture centre to any tap: ``r + r_ball + b_s``."""
        return self.fixture_radius_m + self.ball_radius_m + self.sample_bound_m


@dataclass(frozen=True)
class SearchProgress:
    """One finished level of the search, for progress displays."""

    rotation_level: int
    position_level: int
    evaluated: int
    survivors: int
    elapsed_s: float


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


def exact_distance_interval_m(oracle: DistanceOracle, fix_p_query: np.ndarray,
                              outside: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Interval (m) holding the signed distance of each query point (unsigned for open meshes), float32 error
    included. ``outside``: points already known to lie outside the solid, whose signed distance is the unsigned
    one (no inside test needed)."""
    distance = np.empty(len(fix_p_query))
    outside = np.zeros(len(fix_p_query), bool) if outside is None else outside
    distance[outside] = oracle.unsigned_distance_m(fix_p_query[outside])
    distance[~outside] = oracle.signed_distance_m(fix_p_query[~outside])
    error = oracle.error_bound_m(fix_p_query)
    return distance - error, distance + error


class _Frames:
    """Centre frames of a CellSet's cells: ``R_c^T`` per distinct rotation, and ``chord(gamma)`` of each."""

    def __init__(self, cells: CellSet, fix_R_base: np.ndarray | None = None, chords: np.ndarray | None = None):
        if fix_R_base is None:
            rotations, gammas_rad, _ = cells.distinct_rotations()
            fix_R_base = np.ascontiguousarray(rotations.inv().as_matrix().reshape(-1, 3, 3))
            chords = chord(gammas_rad)
        self.fix_R_base = fix_R_base
        self.chords = chords
        self.rotation_index = cells.rotation_index
        self.cells = cells

    def subset(self, alive: np.ndarray) -> "_Frames":
        """The frames of the cells where ``alive`` is true (same compaction as ``CellSet.subset``)."""
        used = np.zeros(len(self.fix_R_base), bool)
        used[self.rotation_index[alive]] = True
        return _Frames(self.cells.subset(alive), self.fix_R_base[used], self.chords[used])


@dataclass
class Survivors:
    """Cells that passed every tap, with ``R_c^T t_c`` (m) and, per tap, an interval (m, float32, shape
    (cells, taps)) holding the signed distance at the cell centre's query point. ``tap_order``: the taps
    that rejected most cells first, the order the next level tests them in."""

    frames: _Frames
    rotated_positions: np.ndarray
    low_m: np.ndarray
    high_m: np.ndarray
    tap_order: np.ndarray

    @property
    def cells(self) -> CellSet:
        return self.frames.cells

    def __len__(self) -> int:
        return len(self.frames.cells)

    def subset(self, mask: np.ndarray) -> "Survivors":
        """The survivors where ``mask`` is true, with their intervals."""
        return Survivors(self.frames.subset(mask), self.rotated_positions[mask], self.low_m[mask], self.high_m[mask],
                         self.tap_order)


def _filter_chunk(problem: SearchProblem, frames: _Frames, first: int, count: int, parents: Survivors | None,
                  grid: DistanceGrid, tap_order: np.ndarray,
                  cancel: threading.Event | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Survivor mask, ``R_c^T t_c`` and distance intervals of the survivors among cells ``first .. first + count``,
    and the tap that rejected each cell (``NOT_REJECTED`` for survivors).

    Two passes: every tap first rejects what the inherited intervals and the lattice decide (compiled), then exact
    queries settle the intervals still straddling the band, only for cells no tap has rejected yet.
    """
    if cancel is not None and cancel.is_set():
        raise SearchCancelled
    chunk = slice(first, first + count)
    taps = len(problem.base_p_taps)
    rotation_index = frames.rotation_index[chunk]
    rotated_positions = np.empty((count, 3))
    low = np.zeros((count, taps), np.float32)
    high = np.zeros_like(low)
    straddling = np.zeros((count, taps), bool)
    rejected_by = np.empty(count, np.int64)
    if parents is None:
        parent_frames = (np.zeros((0, 3, 3)), np.zeros(0, np.int64), np.zeros((0, 3)))
        parent_low = parent_high = np.zeros((0, taps), np.float32)
    else:
        parent_frames = (parents.frames.fix_R_base, parents.frames.rotation_index, parents.rotated_positions)
        parent_low, parent_high = parents.low_m, parents.high_m
    band_figures = (problem.ball_radius_m, problem.sample_bound_m, frames.cells.position_bound_m, problem.lever_cap_m)
    cheap_pass(frames.fix_R_base, rotation_index, frames.cells.positions_m(chunk), frames.chords, problem.base_p_taps,
               tap_order, *band_figures, first, *parent_frames, parent_low, parent_high, *grid.kernel_arguments,
               rotated_positions, low, high, straddling, rejected_by)
    for tap_index in tap_order:
        if cancel is not None and cancel.is_set():
            raise SearchCancelled
        local = np.flatnonzero((rejected_by == NOT_REJECTED) & straddling[:, tap_index])
        if len(local) == 0:
            continue
        queries, band_low, band_high = query_band(frames.fix_R_base, rotation_index, rotated_positions, frames.chords,
                                                  local, problem.base_p_taps[tap_index], *band_figures)
        interval_low, interval_high = exact_distance_interval_m(problem.oracle, queries, low[local, tap_index] > 0.0)
        keep = (interval_high >= band_low) & (interval_low <= band_high)
        rejected_by[local[~keep]] = tap_index
        low[local[keep], tap_index] = _round_down_f32(interval_low[keep])
        high[local[keep], tap_index] = _round_up_f32(interval_high[keep])
    alive = rejected_by == NOT_REJECTED
    return alive, rotated_positions[alive], low[alive], high[alive], rejected_by


def _filter(problem: SearchProblem, cells: CellSet, parents: Survivors | None, tap_order: np.ndarray,
            cancel: threading.Event | None) -> tuple[np.ndarray, Survivors]:
    """Which cells survive the taps of ``tap_order``, and the survivors (their intervals are set for those taps;
    the next level tests the taps that rejected most first)."""
    frames = _Frames(cells)
    grid = distance_grid_for(problem.oracle)
    starts = range(0, len(cells), QUERY_CHUNK)
    with ThreadPoolExecutor(max_workers=WORKERS) as pool:
        parts = list(pool.map(lambda first: _filter_chunk(problem, frames, first, min(QUERY_CHUNK, len(cells) - first),
                                                          parents, grid, tap_order, cancel), starts))
    alive, rotated_positions, low, high, rejected_by = (np.concatenate([part[i] for part in parts]) for i in range(5))
    rejected = np.bincount(rejected_by[rejected_by != NOT_REJECTED], minlength=len(problem.base_p_taps))
    order = np.asarray(tap_order)[np.argsort(-rejected[tap_order], kind="stable")]
    return alive, Survivors(frames.subset(alive), rotated_positions, low, high, order)


def rotation_splits_first(cells: CellSet, problem: SearchProblem) -> bool:
    """Split rotations when their largest displacement at the fixture radius exceeds the position bound."""
    gamma = float(np.max(cells.rotation_grid.gamma(cells.rotation_level, cells.rotation_ids)))
    rotation_bound = problem.fixture_radius_m * chord(gamma)
    return rotation_bound >= cells.position_bound_m


def split(survivors: Survivors, problem: SearchProblem) -> CellSet:
    """The next level below the survivors: their rotations or positions split, eight children per survivor."""
    cells = survivors.cells
    return cells.split_rotations() if rotation_splits_first(cells, problem) else cells.split_positions()


def filter_cells(problem: SearchProblem, cells: CellSet, parents: Survivors | None = None,
                 cancel: threading.Event | None = None) -> Survivors:
    """The cells of a set that no tap rejects. ``parents``: the survivors the cells are children of
    (eight per parent, in order), whose intervals then decide most children without a query."""
    tap_order = np.arange(len(problem.base_p_taps)) if parents is None else parents.tap_order
    return _filter(problem, cells, parents, tap_order, cancel)[1]


def _descend(problem: SearchProblem, survivors: Survivors, max_cells: float, started: float,
             progress: Callable[[SearchProgress], None] | None, cancel: threading.Event | None) -> Survivors:
    """Split and filter level after level while the next level fits the cell budget."""
    while len(survivors) and 8 * len(survivors) <= max_cells:
        cells = split(survivors, problem)
        survivors = filter_cells(problem, cells, survivors, cancel)
        _report(progress, len(cells), survivors, started)
    return survivors


def _report(progress: Callable[[SearchProgress], None] | None, evaluated: int, survivors: Survivors,
            started: float) -> None:
    if progress is not None:
        cells = survivors.cells
        progress(SearchProgress(cells.rotation_level, cells.position_level, evaluated, len(cells),
                                time.perf_counter() - started))


def search(problem: SearchProblem, max_cells: float = 1e7,
           progress: Callable[[SearchProgress], None] | None = None,
           cancel: threading.Event | None = None) -> Survivors | None:
    """Survivors at the finest levels the cell budget allows (none if no pose fits).

    Returns None when the taps are too far apart for any pose (no possible fixture centre).
    """
    started = time.perf_counter()
    position_grid = start_position_grid(problem)
    if position_grid is None:
        return None
    cells = root_cells(position_grid)
    survivors = filter_cells(problem, cells, cancel=cancel)
    _report(progress, len(cells), survivors, started)
    return _descend(problem, survivors, max_cells, started, progress, cancel)


def add_taps(problem: SearchProblem, previous: Survivors, max_cells: float = 1e7,
             progress: Callable[[SearchProgress], None] | None = None,
             cancel: threading.Event | None = None) -> Survivors:
    """Survivors for ``problem``, whose taps extend those ``previous`` was searched with.

    New taps can only remove poses: the previous survivors are filtered against the new taps alone,
    then split further while the cell budget allows.
    """
    started = time.perf_counter()
    known = previous.low_m.shape[1]
    new_taps = np.arange(known, len(problem.base_p_taps))
    alive, survivors = _filter(problem, previous.cells, None, new_taps, cancel)
    survivors.low_m[:, :known] = previous.low_m[alive]
    survivors.high_m[:, :known] = previous.high_m[alive]
    survivors.tap_order = np.concatenate([survivors.tap_order, previous.tap_order])
    _report(progress, len(previous), survivors, started)
    return _descend(problem, survivors, max_cells, started, progress, cancel)
