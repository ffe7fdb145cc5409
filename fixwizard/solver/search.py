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


def discretisation_bound_m(problem: SearchProblem, fix_p_query: np.ndarray, chords: np.ndarray,
                           position_bound_m: float) -> np.ndarray:
    """``b_p + b_r,i`` (m): how far a query point can move within its cell; ``chords = 2 sin(gamma / 2)``."""
    lever = np.minimum(np.sqrt(np.einsum("ij,ij->i", fix_p_query, fix_p_query)) + position_bound_m,
                       problem.lever_cap_m)
    return position_bound_m + lever * chords


def _round_down_f32(values: np.ndarray) -> np.ndarray:
    """float32 values no larger than the float64 ones (a cast errs by at most |v| 2^-24)."""
    return (values - np.abs(values) * 2.0**-23).astype(np.float32)


def _round_up_f32(values: np.ndarray) -> np.ndarray:
    return (values + np.abs(values) * 2.0**-23).astype(np.float32)


def exact_distance_interval_m(oracle: DistanceOracle, fix_p_query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interval (m) holding the signed distance of each query point (unsigned for open meshes), float32 error included."""
    distance = oracle.signed_distance_m(fix_p_query)
    error = oracle.error_bound_m(fix_p_query)
    return distance - error, distance + error


class _Frames:
    """Centre frames of a CellSet's cells, for query points ``x = R_c^T p - R_c^T t_c``."""

    def __init__(self, cells: CellSet, fix_R_base: np.ndarray | None = None, gammas_rad: np.ndarray | None = None):
        if fix_R_base is None:
            rotations, gammas_rad, _ = cells.distinct_rotations()
            fix_R_base = rotations.inv().as_matrix().reshape(-1, 3, 3)
        self.fix_R_base = fix_R_base
        self.gammas_rad = gammas_rad
        self.rotation_index = cells.rotation_index
        self.cells = cells

    def subset(self, alive: np.ndarray) -> "_Frames":
        """The frames of the cells where ``alive`` is true (same compaction as ``CellSet.subset``)."""
        used = np.zeros(len(self.fix_R_base), bool)
        used[self.rotation_index[alive]] = True
        return _Frames(self.cells.subset(alive), self.fix_R_base[used], self.gammas_rad[used])

    def rotated_positions(self, indices: np.ndarray | slice) -> np.ndarray:
        """``R_c^T t_c`` (m) for the given cells."""
        return np.einsum("nij,nj->ni", self.fix_R_base[self.rotation_index[indices]],
                         self.cells.positions_m(indices))

    def rotated_tap(self, tap: np.ndarray) -> np.ndarray:
        """``R_u^T p`` (m) for every distinct rotation."""
        return self.fix_R_base @ tap


@dataclass
class Survivors:
    """Cells that passed every tap, with ``R_c^T t_c`` and, per tap, an interval (m, float32, shape
    (taps, cells)) holding the signed distance at the cell centre's query point."""

    frames: _Frames
    rotated_positions: np.ndarray
    low_m: np.ndarray
    high_m: np.ndarray

    @property
    def cells(self) -> CellSet:
        return self.frames.cells

    def subset(self, mask: np.ndarray) -> "Survivors":
        """The survivors where ``mask`` is true, with their intervals."""
        return Survivors(self.frames.subset(mask), self.rotated_positions[mask], self.low_m[:, mask],
                         self.high_m[:, mask])


def _straddles(low: np.ndarray, high: np.ndarray, band_low: np.ndarray, band_high: np.ndarray) -> np.ndarray:
    """Intervals that meet the band without lying inside it: only an exact value decides those."""
    return (high >= band_low) & (low <= band_high) & ((low < band_low) | (high > band_high))


def _filter_chunk(problem: SearchProblem, frames: _Frames, first: int, count: int, parents: Survivors | None,
                  grid: DistanceGrid, tap_order: np.ndarray, rejected: np.ndarray,
                  cancel: threading.Event | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Survivor mask, ``R_c^T t_c`` and distance intervals of the survivors among cells ``first .. first + count``.

    Two passes: every tap first rejects what the inherited intervals and the lattice decide, then exact
    queries settle the intervals still straddling the band, only for cells no tap has rejected yet.
    """
    chunk = slice(first, first + count)
    rotated_positions = frames.rotated_positions(chunk)
    rotation_index = frames.rotation_index[chunk]
    chords = chord(frames.gammas_rad[rotation_index])
    alive = np.ones(count, bool)
    low = np.zeros((len(problem.base_p_taps), count), np.float32)
    high = np.zeros_like(low)
    straddling = np.zeros((len(problem.base_p_taps), count), bool)

    def band(tap_index: int, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Query points (m) of the cells ``local`` for a tap, and the band their distance must meet (m)."""
        queries = frames.rotated_tap(problem.base_p_taps[tap_index])[rotation_index[local]] - rotated_positions[local]
        tolerance = problem.sample_bound_m + discretisation_bound_m(problem, queries, chords[local],
                                                                    frames.cells.position_bound_m)
        return queries, problem.ball_radius_m - tolerance, problem.ball_radius_m + tolerance

    def settle(tap_index: int, local: np.ndarray, interval_low: np.ndarray, interval_high: np.ndarray,
               band_low: np.ndarray, band_high: np.ndarray) -> np.ndarray:
        """Reject the cells whose interval misses the band; keep the others' intervals; the kept mask."""
        keep = (interval_high >= band_low) & (interval_low <= band_high)
        alive[local[~keep]] = False
        rejected[tap_index] += int(np.count_nonzero(~keep))
        low[tap_index, local[keep]] = _round_down_f32(interval_low[keep])
        high[tap_index, local[keep]] = _round_up_f32(interval_high[keep])
        return keep

    for tap_index in tap_order:
        if cancel is not None and cancel.is_set():
            raise SearchCancelled
        local = np.flatnonzero(alive)
        queries, band_low, band_high = band(tap_index, local)
        if parents is None:
            interval_low = np.full(len(local), -np.inf)
            interval_high = np.full(len(local), np.inf)
        else:
            interval_low, interval_high = _inherited_interval(problem, parents, tap_index, first + local, queries)
        undecided = _straddles(interval_low, interval_high, band_low, band_high)
        if np.any(undecided):
            grid_low, grid_high = grid.interval_m(queries[undecided])
            interval_low[undecided] = np.maximum(interval_low[undecided], grid_low)
            interval_high[undecided] = np.minimum(interval_high[undecided], grid_high)
            undecided &= _straddles(interval_low, interval_high, band_low, band_high)
        keep = settle(tap_index, local, interval_low, interval_high, band_low, band_high)
        straddling[tap_index, local[keep & undecided]] = True
    for tap_index in tap_order:
        if cancel is not None and cancel.is_set():
            raise SearchCancelled
        local = np.flatnonzero(alive & straddling[tap_index])
        if len(local) == 0:
            continue
        queries, band_low, band_high = band(tap_index, local)
        interval_low, interval_high = exact_distance_interval_m(problem.oracle, queries)
        settle(tap_index, local, interval_low, interval_high, band_low, band_high)
    return alive, rotated_positions[alive], low[:, alive], high[:, alive]


def _inherited_interval(problem: SearchProblem, parents: Survivors, tap_index: int, cells: np.ndarray,
                        queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The parents' intervals (m) for one tap, widened by how far each child's query point lies from its
    parent's (``cells`` are level indices; eight children per parent, in order)."""
    parent = cells // 8
    parent_queries = (parents.frames.rotated_tap(problem.base_p_taps[tap_index])[parents.frames.rotation_index[parent]]
                      - parents.rotated_positions[parent])
    shift = np.linalg.norm(queries - parent_queries, axis=1)
    return parents.low_m[tap_index, parent] - shift, parents.high_m[tap_index, parent] + shift


def _filter(problem: SearchProblem, cells: CellSet, parents: Survivors | None, grid: DistanceGrid,
            tap_order: np.ndarray, cancel: threading.Event | None) -> tuple[Survivors, np.ndarray]:
    """Survivors of a level, and the number of cells each tap rejected."""
    frames = _Frames(cells)
    starts = range(0, len(cells), QUERY_CHUNK)
    rejected = np.zeros((len(starts), len(problem.base_p_taps)), np.int64)
    with ThreadPoolExecutor(max_workers=WORKERS) as pool:
        parts = list(pool.map(lambda job: _filter_chunk(problem, frames, job[1], min(QUERY_CHUNK, len(cells) - job[1]),
                                                        parents, grid, tap_order, rejected[job[0]], cancel),
                              enumerate(starts)))
    alive, rotated_positions = (np.concatenate(part) for part in list(zip(*parts))[:2])
    low, high = (np.concatenate(part, axis=1) for part in list(zip(*parts))[2:])
    return Survivors(frames.subset(alive), rotated_positions, low, high), rejected.sum(axis=0)


def rotation_splits_first(cells: CellSet, problem: SearchProblem) -> bool:
    """Split rotations when their largest displacement at the fixture radius exceeds the position bound."""
    gamma = float(np.max(cells.rotation_grid.gamma(cells.rotation_level, cells.rotation_ids)))
    rotation_bound = problem.fixture_radius_m * chord(gamma)
    return rotation_bound >= cells.position_bound_m


def filter_cells(problem: SearchProblem, cells: CellSet, parents: Survivors | None = None,
                 cancel: threading.Event | None = None) -> Survivors:
    """The cells of a set that no tap rejects. ``parents``: the survivors the cells are children of
    (eight per parent, in order), whose intervals then decide most children without a query."""
    return _filter(problem, cells, parents, distance_grid_for(problem.oracle), np.arange(len(problem.base_p_taps)),
                   cancel)[0]


def search(problem: SearchProblem, max_cells: float = 1e7,
           progress: Callable[[SearchProgress], None] | None = None,
           cancel: threading.Event | None = None) -> CellSet | None:
    """Surviving cells at the finest levels the cell budget allows; an empty CellSet if no pose fits.

    Returns None when the taps are too far apart for any pose (no possible fixture centre).
    """
    started = time.perf_counter()
    position_grid = start_position_grid(problem)
    if position_grid is None:
        return None
    cells = root_cells(position_grid)
    grid = distance_grid_for(problem.oracle)
    tap_order = np.arange(len(problem.base_p_taps))
    parents = None
    while True:
        evaluated = len(cells)
        parents, rejected = _filter(problem, cells, parents, grid, tap_order, cancel)
        cells = parents.cells
        tap_order = np.argsort(-rejected, kind="stable")
        if progress is not None:
            progress(SearchProgress(cells.rotation_level, cells.position_level, evaluated, len(cells),
                                    time.perf_counter() - started))
        if len(cells) == 0 or 8 * len(cells) > max_cells:
            return cells
        cells = cells.split_rotations() if rotation_splits_first(cells, problem) else cells.split_positions()
