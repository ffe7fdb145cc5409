"""The search's inner loop, compiled with Numba: per cell and tap, the band and the cheap interval test.

For cell ``c`` with centre frame ``(R_c, t_c)`` and tap ``p`` (base frame, m) the query point is
``x = R_c^T p - R_c^T t_c`` (fixture frame, m). The band its signed distance must meet is
``r_ball -/+ (b_s + b_p + min(|x| + b_p, lever_cap) * chord)`` (see ``search``). The cheap test
bounds the distance at ``x`` by the parent's interval widened by ``|x - x_parent|`` and by the
distance lattice (nearest vertex plus the offset to it); cells whose interval misses the band are
rejected, intervals that still straddle a band edge are flagged for an exact query.

Arithmetic is float64 without fast-math, so every value equals numpy's; the stored float32
interval ends are rounded outward.
"""

import math

import numba
import numpy as np

NOT_REJECTED = -1


@numba.njit(nogil=True, cache=True, inline="always")
def _round_down_f32(value: float) -> np.float32:
    return np.float32(value - abs(value) * 2.0**-23)


@numba.njit(nogil=True, cache=True, inline="always")
def _round_up_f32(value: float) -> np.float32:
    return np.float32(value + abs(value) * 2.0**-23)


@numba.njit(nogil=True, cache=True, inline="always")
def _tolerance_m(x0: float, x1: float, x2: float, chord: float, sample_bound_m: float, position_bound_m: float,
                 lever_cap_m: float) -> float:
    lever = min(math.sqrt(x0 * x0 + x1 * x1 + x2 * x2) + position_bound_m, lever_cap_m)
    return sample_bound_m + position_bound_m + lever * chord


@numba.njit(nogil=True, cache=True, inline="always")
def _straddles(low: float, high: float, band_low: float, band_high: float) -> bool:
    return high >= band_low and low <= band_high and (low < band_low or high > band_high)


@numba.njit(nogil=True, cache=True)
def _lattice_interval_m(x0: float, x1: float, x2: float, lattice_low_m: np.ndarray, spacing_m: float,
                        shape: np.ndarray, values_m: np.ndarray, value_error_m: float, mesh_low_m: np.ndarray,
                        mesh_high_m: np.ndarray) -> tuple[float, float]:
    """``DistanceGrid.interval_m`` for one point (m, fixture frame)."""
    point = (x0, x1, x2)
    flat = 0
    reach_sq = 0.0
    gap_sq = 0.0
    for axis in range(3):
        index = math.floor((point[axis] - lattice_low_m[axis]) / spacing_m + 0.5)
        index = min(max(index, 0), shape[axis] - 1)
        flat = flat * shape[axis] + index
        offset = point[axis] - (lattice_low_m[axis] + index * spacing_m)
        reach_sq += offset * offset
        gap = max(mesh_low_m[axis] - point[axis], point[axis] - mesh_high_m[axis], 0.0)
        gap_sq += gap * gap
    reach = math.sqrt(reach_sq) + value_error_m
    low = values_m[flat] - reach
    if gap_sq > 0.0:
        low = max(low, math.sqrt(gap_sq))
    return low, values_m[flat] + reach


@numba.njit(nogil=True, cache=True)
def lattice_intervals_m(points_m: np.ndarray, lattice_low_m: np.ndarray, spacing_m: float, shape: np.ndarray,
                        values_m: np.ndarray, value_error_m: float, mesh_low_m: np.ndarray,
                        mesh_high_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_lattice_interval_m`` of each (N, 3) point: the intervals' low and high ends (m)."""
    low = np.empty(len(points_m))
    high = np.empty(len(points_m))
    for row in range(len(points_m)):
        low[row], high[row] = _lattice_interval_m(points_m[row, 0], points_m[row, 1], points_m[row, 2], lattice_low_m,
                                                  spacing_m, shape, values_m, value_error_m, mesh_low_m, mesh_high_m)
    return low, high


@numba.njit(nogil=True, cache=True)
def cheap_pass(fix_R_base: np.ndarray, rotation_index: np.ndarray, base_p_centres: np.ndarray, chords: np.ndarray,
               base_p_taps: np.ndarray, tap_order: np.ndarray, ball_radius_m: float, sample_bound_m: float,
               position_bound_m: float, lever_cap_m: float, first: int, parent_fix_R_base: np.ndarray,
               parent_rotation_index: np.ndarray, parent_rotated_positions: np.ndarray, parent_low_m: np.ndarray,
               parent_high_m: np.ndarray, lattice_low_m: np.ndarray, lattice_spacing_m: float, lattice_shape:
               np.ndarray, lattice_values_m: np.ndarray, lattice_error_m: float, mesh_low_m: np.ndarray, mesh_high_m:
               np.ndarray, rotated_positions: np.ndarray, low_m: np.ndarray, high_m: np.ndarray, straddling: np.ndarray,
               rejected_by: np.ndarray) -> None:
    """Cheap test of cells ``first .. first + n`` of a level against every tap, in ``tap_order``.

    Cells: ``fix_R_base[rotation_index]`` (R_c^T), ``base_p_centres`` (n, 3, m), ``chords[rotation_index]``.
    Parents (cell ``k``'s parent is ``k // 8``; empty ``parent_low_m`` at the root level): frames,
    ``R^T t`` and float32 intervals (parents, taps). Writes ``rotated_positions`` (n, 3), the cells'
    intervals ``low_m``/``high_m`` (n, taps) and ``straddling`` flags for the taps tested, and
    ``rejected_by``: the tap that rejected each cell or ``NOT_REJECTED``.
    """
    has_parents = parent_low_m.shape[0] > 0
    for cell in range(len(rotation_index)):
        rotation = fix_R_base[rotation_index[cell]]
        centre = base_p_centres[cell]
        t0 = rotation[0, 0] * centre[0] + rotation[0, 1] * centre[1] + rotation[0, 2] * centre[2]
        t1 = rotation[1, 0] * centre[0] + rotation[1, 1] * centre[1] + rotation[1, 2] * centre[2]
        t2 = rotation[2, 0] * centre[0] + rotation[2, 1] * centre[1] + rotation[2, 2] * centre[2]
        rotated_positions[cell, 0], rotated_positions[cell, 1], rotated_positions[cell, 2] = t0, t1, t2
        chord = chords[rotation_index[cell]]
        parent = (first + cell) // 8
        rejected_by[cell] = NOT_REJECTED
        for tap in tap_order:
            p = base_p_taps[tap]
            x0 = rotation[0, 0] * p[0] + rotation[0, 1] * p[1] + rotation[0, 2] * p[2] - t0
            x1 = rotation[1, 0] * p[0] + rotation[1, 1] * p[1] + rotation[1, 2] * p[2] - t1
            x2 = rotation[2, 0] * p[0] + rotation[2, 1] * p[1] + rotation[2, 2] * p[2] - t2
            tolerance = _tolerance_m(x0, x1, x2, chord, sample_bound_m, position_bound_m, lever_cap_m)
            band_low, band_high = ball_radius_m - tolerance, ball_radius_m + tolerance
            low, high = -np.inf, np.inf
            if has_parents:
                parent_rotation = parent_fix_R_base[parent_rotation_index[parent]]
                shift_sq = 0.0
                for axis in range(3):
                    parent_x = (parent_rotation[axis, 0] * p[0] + parent_rotation[axis, 1] * p[1]
                                + parent_rotation[axis, 2] * p[2] - parent_rotated_positions[parent, axis])
                    delta = (x0, x1, x2)[axis] - parent_x
                    shift_sq += delta * delta
                shift = math.sqrt(shift_sq)
                low = parent_low_m[parent, tap] - shift
                high = parent_high_m[parent, tap] + shift
            undecided = _straddles(low, high, band_low, band_high)
            if undecided:
                lattice_low, lattice_high = _lattice_interval_m(x0, x1, x2, lattice_low_m, lattice_spacing_m,
                                                                lattice_shape, lattice_values_m, lattice_error_m,
                                                                mesh_low_m, mesh_high_m)
                low, high = max(low, lattice_low), min(high, lattice_high)
                undecided = _straddles(low, high, band_low, band_high)
            if high < band_low or low > band_high:
                rejected_by[cell] = tap
                break
            low_m[cell, tap] = _round_down_f32(low)
            high_m[cell, tap] = _round_up_f32(high)
            straddling[cell, tap] = undecided


@numba.njit(nogil=True, cache=True)
def query_band(fix_R_base: np.ndarray, rotation_index: np.ndarray, rotated_positions: np.ndarray, chords: np.ndarray,
               cells: np.ndarray, base_p_tap: np.ndarray, ball_radius_m: float, sample_bound_m: float,
               position_bound_m: float, lever_cap_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Query points (m, fixture frame) of one tap for the given cells, and their bands' low and high ends (m)."""
    queries = np.empty((len(cells), 3))
    band_low = np.empty(len(cells))
    band_high = np.empty(len(cells))
    for row in range(len(cells)):
        cell = cells[row]
        rotation = fix_R_base[rotation_index[cell]]
        for axis in range(3):
            queries[row, axis] = (rotation[axis, 0] * base_p_tap[0] + rotation[axis, 1] * base_p_tap[1]
                                  + rotation[axis, 2] * base_p_tap[2] - rotated_positions[cell, axis])
        tolerance = _tolerance_m(queries[row, 0], queries[row, 1], queries[row, 2], chords[rotation_index[cell]],
                                 sample_bound_m, position_bound_m, lever_cap_m)
        band_low[row] = ball_radius_m - tolerance
        band_high[row] = ball_radius_m + tolerance
    return queries, band_low, band_high
