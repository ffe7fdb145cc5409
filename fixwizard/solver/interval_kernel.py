"""The search's inner loop, compiled with Numba: per cell and tap, the band and the cheap interval test.

For cell ``c`` with centre frame ``(R_c, t_c)`` and tap ``p`` (base frame, m) the query point is
``x = R_c^T p - R_c^T t_c`` (fixture frame, m). The band its signed distance must meet is
``r_ball -/+ (b_s + b_p + min(|x| + b_p, lever_cap) * chord)`` (see ``search``). The cheap test
bounds the distance at ``x`` by the parent's interval widened by ``|x - x_parent|`` and by the
distance lattice (nearest vertex plus the offset to it, then the eight corners of the voxel);
cells whose interval misses the band are rejected. Intervals that still straddle a band edge are then settled,
tap by tap in order, for the cells no tap has rejected: by the float64 mesh hierarchy's interval
(``mesh_distance.query_point``), signed where the closest point lies inside a face with a trustworthy normal
(the face's plane decides, as ``DistanceOracle`` does) and where the cheap interval does not already prove the
point outside. The few others (closest point on an edge or a corner, or on a sliver face) are flagged for
``DistanceOracle.distance_interval_m``, whose pseudonormal, ray parity and winding number decide their sign.

Arithmetic is float64 without fast-math, so every value equals numpy's; the stored float32
interval ends are rounded outward.
"""

import math
from typing import Any

import numba
import numpy as np

from fixwizard.geometry.mesh_distance import (
    query_point,
    row_normal,
    row_point_m,
    triangle_row_high_m,
    triangle_row_reach_high_m,
)
from fixwizard.parallel import PARALLEL_KERNEL_LOCK

Arrays = tuple[Any, ...]  # several arrays passed to a compiled kernel as one argument
NOT_REJECTED = -1
SQRT_3 = math.sqrt(3.0)
ROUNDING_M = 1e-12  # far above float64's rounding of query points of fixtures within a kilometre, far below any bound
BLOCK_CELLS = 1024  # cells per parallel work item


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


@numba.njit(nogil=True, cache=True)
def _too_near_everywhere(x0: float, x1: float, x2: float, rotation: np.ndarray, chord: float, half_side_m: float,
                         shift_m: float, row: np.ndarray, near_m: float) -> bool:
    """Whether at every pose of a cell the query point lies nearer than ``near_m`` (m) to the row's triangle, so
    that its signed distance (never above the distance to any one triangle) is below ``near_m`` there.

    The cell: centre frame ``rotation = R_c^T``, rotations within angle ``gamma`` of ``R_c`` (``chord =
    2 sin(gamma / 2)``), positions in the cube of half side ``half_side_m`` (m, base frame) about ``t_c``;
    ``x = R_c^T (p - t_c)`` (m) the centre's query point, and ``shift_m`` a bound on ``|x' - x|`` over the cell.
    With ``R = R_c E`` (``E`` turning by ``theta <= gamma`` about a unit axis ``a``), ``x' - x = (E^T - I) x +
    E^T R_c^T (t_c - t)``. Along the triangle's unit normal ``n`` (Rodrigues' formula):
    ``|n . (E^T - I) x| <= sin(gamma) |x x n| + (1 - cos gamma) (|x| + |n . x|) / 2`` (the largest of
    ``(a . n)(a . x)`` over unit ``a`` is ``(|x| + n . x) / 2``; ``sin(gamma)`` taken as 1 beyond 90 deg), and
    ``|n . E^T R_c^T v| = |(R_c E n) . v| <= h (|R_c n|_1 + sqrt(3) chord)`` for ``v`` in the cube, never above
    ``sqrt(3) h``. The offset of ``x'`` along ``n`` is what moves its distance most; ``mesh_distance.
    triangle_row_reach_high_m`` turns both offsets into a bound on the distance."""
    n0, n1, n2 = row_normal(row)
    if n0 == 0.0 and n1 == 0.0 and n2 == 0.0:
        return False
    turned_l1 = (abs(rotation[0, 0] * n0 + rotation[1, 0] * n1 + rotation[2, 0] * n2)
                 + abs(rotation[0, 1] * n0 + rotation[1, 1] * n1 + rotation[2, 1] * n2)
                 + abs(rotation[0, 2] * n0 + rotation[1, 2] * n1 + rotation[2, 2] * n2))
    position_along = half_side_m * min(SQRT_3, turned_l1 + SQRT_3 * chord)
    sine = chord * math.sqrt(max(1.0 - 0.25 * chord * chord, 0.0)) if chord <= math.sqrt(2.0) else 1.0
    c0, c1, c2 = x1 * n2 - x2 * n1, x2 * n0 - x0 * n2, x0 * n1 - x1 * n0
    lever_across = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    length = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    rotation_along = sine * lever_across + 0.25 * chord * chord * (length + abs(x0 * n0 + x1 * n1 + x2 * n2))
    # ROUNDING_M covers the rounding of the query points (m-sized coordinates, float64) and of these sums
    along = (position_along + rotation_along) * (1.0 + 1e-12) + ROUNDING_M
    return triangle_row_reach_high_m(x0, x1, x2, row, along, shift_m + ROUNDING_M) < near_m - ROUNDING_M


@numba.njit(nogil=True, cache=True, inline="always")
def _straddles(low: float, high: float, band_low: float, band_high: float) -> bool:
    return high >= band_low and low <= band_high and (low < band_low or high > band_high)


@numba.njit(nogil=True, cache=True, inline="always")
def _box_gap_m(x0: float, x1: float, x2: float, lattice: Arrays) -> float:
    """Distance (m) from a point to the mesh's bounding box (zero inside it): where positive, the point lies outside
    the solid, at least that far from the surface."""
    mesh_low_m, mesh_high_m = lattice[5], lattice[6]
    g0 = max(mesh_low_m[0] - x0, x0 - mesh_high_m[0], 0.0)
    g1 = max(mesh_low_m[1] - x1, x1 - mesh_high_m[1], 0.0)
    g2 = max(mesh_low_m[2] - x2, x2 - mesh_high_m[2], 0.0)
    return math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)


@numba.njit(nogil=True, cache=True, inline="always")
def _vertex_bounds_m(x0: float, x1: float, x2: float, j0: int, j1: int, j2: int,
                     lattice: Arrays) -> tuple[float, float, int]:
    """Bounds (m) on the signed distance at a point from lattice vertex ``(j0, j1, j2)``: its value minus and plus
    the point's distance to it and the values' error (the signed distance is 1-Lipschitz); the vertex's face."""
    lattice_low_m, spacing_m, shape, values_m, value_error_m = lattice[:5]
    o0 = x0 - (lattice_low_m[0] + j0 * spacing_m)
    o1 = x1 - (lattice_low_m[1] + j1 * spacing_m)
    o2 = x2 - (lattice_low_m[2] + j2 * spacing_m)
    reach = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2) + value_error_m
    flat = (j0 * shape[1] + j1) * shape[2] + j2
    return values_m[flat] - reach, values_m[flat] + reach, lattice[7][flat]


@numba.njit(nogil=True, cache=True, inline="always")
def _nearest_index(coordinate: float, low_m: float, spacing_m: float, size: int) -> int:
    return min(max(math.floor((coordinate - low_m) / spacing_m + 0.5), 0), size - 1)


@numba.njit(nogil=True, cache=True)
def _nearest_vertex_interval_m(x0: float, x1: float, x2: float, lattice: Arrays) -> tuple[float, float, int]:
    """Interval (m) holding the signed distance at a point (m, fixture frame) from the nearest lattice vertex
    (clamped to the lattice) and the bounding box, and the face closest to that vertex."""
    lattice_low_m, spacing_m, shape = lattice[:3]
    low, high, face = _vertex_bounds_m(x0, x1, x2, _nearest_index(x0, lattice_low_m[0], spacing_m, shape[0]),
                                       _nearest_index(x1, lattice_low_m[1], spacing_m, shape[1]),
                                       _nearest_index(x2, lattice_low_m[2], spacing_m, shape[2]), lattice)
    gap = _box_gap_m(x0, x1, x2, lattice)
    return (max(low, gap) if gap > 0.0 else low), high, face


@numba.njit(nogil=True, cache=True)
def _voxel_interval_m(x0: float, x1: float, x2: float, lattice: Arrays) -> tuple[float, float]:
    """``DistanceGrid.interval_m`` for one point (m, fixture frame): the tightest of the bounds from the eight
    corners of the lattice voxel holding it (the nearest voxel outside the lattice), and the bounding box. The
    nearest vertex is one of the corners, so this interval lies within ``_nearest_vertex_interval_m``'s."""
    lattice_low_m, spacing_m, shape = lattice[:3]
    i0 = min(max(math.floor((x0 - lattice_low_m[0]) / spacing_m), 0), shape[0] - 2)
    i1 = min(max(math.floor((x1 - lattice_low_m[1]) / spacing_m), 0), shape[1] - 2)
    i2 = min(max(math.floor((x2 - lattice_low_m[2]) / spacing_m), 0), shape[2] - 2)
    low, high = -np.inf, np.inf
    for corner in range(8):
        corner_low, corner_high, _ = _vertex_bounds_m(x0, x1, x2, i0 + (corner & 1), i1 + ((corner >> 1) & 1),
                                                      i2 + (corner >> 2), lattice)
        low, high = max(low, corner_low), min(high, corner_high)
    gap = _box_gap_m(x0, x1, x2, lattice)
    return (max(low, gap) if gap > 0.0 else low), high


@numba.njit(nogil=True, cache=True)
def lattice_intervals_m(points_m: np.ndarray, lattice: Arrays) -> tuple[np.ndarray, np.ndarray]:
    """``_voxel_interval_m`` of each (N, 3) point: the intervals' low and high ends (m)."""
    low = np.empty(len(points_m))
    high = np.empty(len(points_m))
    for row in range(len(points_m)):
        low[row], high[row] = _voxel_interval_m(points_m[row, 0], points_m[row, 1], points_m[row, 2], lattice)
    return low, high


@numba.njit(nogil=True, cache=True)
def face_distances_m(points_m: np.ndarray, faces: np.ndarray, triangle_rows: np.ndarray) -> np.ndarray:
    """The face bound of each (N, 3) point: ``triangle_row_high_m`` to its face."""
    distances = np.empty(len(points_m))
    for row in range(len(points_m)):
        distances[row] = triangle_row_high_m(points_m[row, 0], points_m[row, 1], points_m[row, 2],
                                             triangle_rows[faces[row]])
    return distances


@numba.njit(nogil=True, cache=True, parallel=True)
def _parallel_filter(cells: Arrays, taps: Arrays, band: Arrays, parent_index: np.ndarray, parents: Arrays,
                     lattice: Arrays, mesh: Arrays, out: Arrays) -> None:
    count = len(cells[1])
    blocks = (count + BLOCK_CELLS - 1) // BLOCK_CELLS
    for block in numba.prange(blocks):
        _filter_range(block * BLOCK_CELLS, min(count, (block + 1) * BLOCK_CELLS), cells, taps, band, parent_index,
                      parents, lattice, mesh, out)


def filter_pass(cells: Arrays, taps: Arrays, band: Arrays, parent_index: np.ndarray, parents: Arrays,
                 lattice: Arrays, mesh: Arrays, out: Arrays) -> None:
    """``_filter_range`` over all cells, in blocks spread over the cores (a few blocks on the calling thread:
    waking the parallel workers costs milliseconds)."""
    count = len(cells[1])
    if count <= 2 * BLOCK_CELLS:
        _filter_range(0, count, cells, taps, band, parent_index, parents, lattice, mesh, out)
    else:
        with PARALLEL_KERNEL_LOCK:
            _parallel_filter(cells, taps, band, parent_index, parents, lattice, mesh, out)


@numba.njit(nogil=True, cache=True)
def _filter_range(start: int, stop: int, cells: Arrays, taps: Arrays, band: Arrays, parent_index: np.ndarray,
                  parents: Arrays, lattice: Arrays, mesh: Arrays, out: Arrays) -> None:
    """Cells ``start .. stop`` of a chunk of ``n``: the cheap test against every tap, then, for a cell no tap
    rejected, the exact stage of the taps whose intervals straddle a band edge (``cells``, ``taps``, ``band``,
    ``parents`` and ``lattice`` as for ``_cheap_cell``; ``mesh``: ``DistanceOracle.kernel_arguments``;
    ``out = (rotated_positions (n, 3), low (n, T), high, faces, straddling, rejected_by (n,), deferred (n, T))``,
    ``deferred`` all false on entry). Straddling intervals the exact stage cannot sign are left as they are and
    flagged ``deferred``; the rest are replaced by the exact interval, or reject the cell."""
    for cell in range(start, stop):
        _cheap_cell(cell, cells, taps, band, parent_index, parents, lattice, mesh[0], out)
        if out[5][cell] == NOT_REJECTED:
            _exact_cell(cell, cells, taps, band, mesh, out)


@numba.njit(nogil=True, cache=True, inline="always")
def _rejects_or_keeps(cell: int, tap: int, low: float, high: float, face: int, band_low: float, band_high: float,
                      out: Arrays) -> bool:
    """Whether interval ``[low, high]`` (m) misses the band, so that ``tap`` rejects ``cell``; else the cell keeps
    it (float32, rounded outward) with its face."""
    if high < band_low or low > band_high:
        out[5][cell] = tap
        return True
    out[1][cell, tap] = _round_down_f32(low)
    out[2][cell, tap] = _round_up_f32(high)
    out[3][cell, tap] = face
    return False


@numba.njit(nogil=True, cache=True)
def signed_interval_m(x: np.ndarray, hint: int, outside: bool, mesh: Arrays,
                      cap: float = np.inf) -> tuple[float, float, int, bool]:
    """The exact stage's interval (m) at a point ``x`` (m, mesh frame): ``DistanceOracle.distance_interval_m``'s
    (with ``hint``, signed unless ``outside``: known to lie outside) where it can tell the sign as the oracle
    does (the closest point inside a face with a trustworthy normal: the face's plane decides; within
    ``SIGN_FREE_M`` of the surface, both signs), with the closest face; and whether it could (else the interval
    is unsigned and the oracle must sign it). ``mesh``: ``DistanceOracle.kernel_arguments``. ``cap`` (m): where
    the distance is surely at least ``cap`` on either side, ``[cap, inf]`` and face -1 (``query_point``'s cap),
    the sign unknown."""
    rows, hierarchy = mesh[0], mesh[1:6]
    signed, face_normals, reliable_normal, feature_margin, sign_free_m = mesh[6:]
    low, high, face, v, w = query_point(x, rows, hierarchy, hint, cap)
    if face < 0:
        return low, high, face, True
    if not signed or outside:
        return low, high, face, True
    if low <= sign_free_m:
        return -high, high, face, True
    if min(1.0 - (v + w), min(v, w)) <= feature_margin or not reliable_normal[face]:
        return low, high, face, False
    closest = row_point_m(rows[face], v, w)
    normal = face_normals[face]
    if (x[0] - closest[0]) * normal[0] + (x[1] - closest[1]) * normal[1] + (x[2] - closest[2]) * normal[2] < 0.0:
        return -high, -low, face, True
    return low, high, face, True


@numba.njit(nogil=True, cache=True)
def _exact_cell(cell: int, cells: Arrays, taps: Arrays, band: Arrays, mesh: Arrays, out: Arrays) -> None:
    """The exact stage of one cell (see ``_filter_range``), its straddling taps in order until one rejects it."""
    fix_R_base, rotation_index, _, chords, _ = cells
    base_p_taps, tap_order = taps
    ball_radius_m, sample_bound_m, position_bound_m, lever_cap_m = band
    rotated_positions, low_m, faces_out, straddling, deferred = out[0], out[1], out[3], out[4], out[6]
    rotation = fix_R_base[rotation_index[cell]]
    chord = chords[rotation_index[cell]]
    x = np.empty(3)
    for tap in tap_order:
        if not straddling[cell, tap]:
            continue
        p = base_p_taps[tap]
        for axis in range(3):
            x[axis] = (rotation[axis, 0] * p[0] + rotation[axis, 1] * p[1] + rotation[axis, 2] * p[2]
                       - rotated_positions[cell, axis])
        tolerance = _tolerance_m(x[0], x[1], x[2], chord, sample_bound_m, position_bound_m, lever_cap_m)
        band_low, band_high = ball_radius_m - tolerance, ball_radius_m + tolerance
        # the band lies within (-band_high, band_high]: a distance beyond band_high on either side misses it
        low, high, face, signable = signed_interval_m(x, faces_out[cell, tap], low_m[cell, tap] > 0.0, mesh,
                                                      band_high * (1.0 + 1e-9))
        if face < 0:
            out[5][cell] = tap
            return
        if not signable:
            deferred[cell, tap] = True
            continue
        if _rejects_or_keeps(cell, tap, low, high, face, band_low, band_high, out):
            return
        near_m = ball_radius_m - sample_bound_m
        if low < near_m and _too_near_everywhere(x[0], x[1], x[2], rotation, chord, 0.5 * cells[4][3],
                                                 tolerance - sample_bound_m, mesh[0][face], near_m):
            out[5][cell] = tap
            return


@numba.njit(nogil=True, cache=True)
def _cheap_cell(cell: int, cells: Arrays, taps: Arrays, band: Arrays, parent_index: np.ndarray, parents: Arrays,
                lattice: Arrays, triangle_rows: np.ndarray, out: Arrays) -> None:
    """Cheap test of cell ``cell`` of a chunk of ``n`` cells against every tap, in order.

    ``cells = (fix_R_base (U, 3, 3), rotation_index (n,), position_cells (n, 3), chords (U,), octree)`` with
    ``octree = [corner (3 values, m), cell side (m)]`` of the position level: cell ``k``'s centre (base frame, m)
    is ``corner + (position_cells[k] + 0.5) * side`` (``PositionGrid.centers_m``);
    ``taps = (base_p_taps (T, 3) m, tap_order)``; ``band = (ball_radius, sample_bound, position_bound,
    lever_cap)`` in m. ``parents = (fix_R_base, rotation_index, rotated_positions, low, high, faces)``
    (cell ``k``'s parent is row ``parent_index[k]``; no rows at the root level); intervals are float32
    (parents, T).
    ``lattice``: ``DistanceGrid.kernel_arguments``; ``triangle_rows``: ``DistanceOracle.triangle_rows``.
    ``out = (rotated_positions (n, 3), low (n, T), high, faces, straddling, rejected_by (n,), ...)``: per
    tap tested, the interval, the face whose distance bounds it from above, and whether it straddles a
    band edge; the tap that rejected each cell or ``NOT_REJECTED``.
    """
    fix_R_base, rotation_index, position_cells, chords, octree = cells
    base_p_taps, tap_order = taps
    ball_radius_m, sample_bound_m, position_bound_m, lever_cap_m = band
    parent_fix_R_base, parent_rotation_index, parent_rotated_positions, parent_low, parent_high, parent_faces = parents
    rotated_positions, straddling, rejected_by = out[0], out[4], out[5]
    has_parents = parent_low.shape[0] > 0
    rotation = fix_R_base[rotation_index[cell]]
    centre = (octree[0] + (position_cells[cell, 0] + 0.5) * octree[3],
              octree[1] + (position_cells[cell, 1] + 0.5) * octree[3],
              octree[2] + (position_cells[cell, 2] + 0.5) * octree[3])
    t0 = rotation[0, 0] * centre[0] + rotation[0, 1] * centre[1] + rotation[0, 2] * centre[2]
    t1 = rotation[1, 0] * centre[0] + rotation[1, 1] * centre[1] + rotation[1, 2] * centre[2]
    t2 = rotation[2, 0] * centre[0] + rotation[2, 1] * centre[1] + rotation[2, 2] * centre[2]
    rotated_positions[cell, 0], rotated_positions[cell, 1], rotated_positions[cell, 2] = t0, t1, t2
    chord = chords[rotation_index[cell]]
    parent = parent_index[cell]
    rejected_by[cell] = NOT_REJECTED
    for tap in tap_order:
        p = base_p_taps[tap]
        x0 = rotation[0, 0] * p[0] + rotation[0, 1] * p[1] + rotation[0, 2] * p[2] - t0
        x1 = rotation[1, 0] * p[0] + rotation[1, 1] * p[1] + rotation[1, 2] * p[2] - t1
        x2 = rotation[2, 0] * p[0] + rotation[2, 1] * p[1] + rotation[2, 2] * p[2] - t2
        tolerance = _tolerance_m(x0, x1, x2, chord, sample_bound_m, position_bound_m, lever_cap_m)
        band_low, band_high = ball_radius_m - tolerance, ball_radius_m + tolerance
        low, high, face = -np.inf, np.inf, -1
        if has_parents:
            parent_rotation = parent_fix_R_base[parent_rotation_index[parent]]
            shift_sq = 0.0
            for axis in range(3):
                parent_x = (parent_rotation[axis, 0] * p[0] + parent_rotation[axis, 1] * p[1]
                            + parent_rotation[axis, 2] * p[2] - parent_rotated_positions[parent, axis])
                delta = (x0, x1, x2)[axis] - parent_x
                shift_sq += delta * delta
            shift = math.sqrt(shift_sq)
            low = parent_low[parent, tap] - shift
            high = parent_high[parent, tap] + shift
            face = parent_faces[parent, tap]
            if face >= 0 and high > band_high and _straddles(low, high, band_low, band_high):
                high = min(high, triangle_row_high_m(x0, x1, x2, triangle_rows[face]))
        undecided = _straddles(low, high, band_low, band_high)
        if undecided:
            lattice_low, lattice_high, lattice_face = _nearest_vertex_interval_m(x0, x1, x2, lattice)
            low, high = max(low, lattice_low), min(high, lattice_high)
            if face < 0:
                face = lattice_face
            if lattice_face != face and high > band_high and _straddles(low, high, band_low, band_high):
                lattice_face_distance = triangle_row_high_m(x0, x1, x2, triangle_rows[lattice_face])
                if lattice_face_distance < high:
                    high, face = lattice_face_distance, lattice_face
            undecided = _straddles(low, high, band_low, band_high)
            if undecided:
                voxel_low, voxel_high = _voxel_interval_m(x0, x1, x2, lattice)
                low, high = max(low, voxel_low), min(high, voxel_high)
                undecided = _straddles(low, high, band_low, band_high)
        if _rejects_or_keeps(cell, tap, low, high, face, band_low, band_high, out):
            break
        near_m = ball_radius_m - sample_bound_m
        if face >= 0 and low < near_m and _too_near_everywhere(x0, x1, x2, rotation, chord, 0.5 * octree[3],
                                                               tolerance - sample_bound_m, triangle_rows[face],
                                                               near_m):
            rejected_by[cell] = tap
            break
        straddling[cell, tap] = undecided


@numba.njit(nogil=True, cache=True)
def query_band(cells: Arrays, rotated_positions: np.ndarray, rows: np.ndarray, taps: np.ndarray,
               base_p_taps: np.ndarray, band: Arrays) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Query points (m, fixture frame) of cell-tap pairs ``(rows[k], taps[k])``, and their bands' low and high
    ends (m); ``cells`` and ``band`` as for ``filter_pass``."""
    fix_R_base, rotation_index, _, chords, _ = cells
    ball_radius_m, sample_bound_m, position_bound_m, lever_cap_m = band
    queries = np.empty((len(rows), 3))
    band_low = np.empty(len(rows))
    band_high = np.empty(len(rows))
    for pair in range(len(rows)):
        cell = rows[pair]
        rotation = fix_R_base[rotation_index[cell]]
        tap = base_p_taps[taps[pair]]
        for axis in range(3):
            queries[pair, axis] = (rotation[axis, 0] * tap[0] + rotation[axis, 1] * tap[1]
                                   + rotation[axis, 2] * tap[2] - rotated_positions[cell, axis])
        tolerance = _tolerance_m(queries[pair, 0], queries[pair, 1], queries[pair, 2], chords[rotation_index[cell]],
                                 sample_bound_m, position_bound_m, lever_cap_m)
        band_low[pair] = ball_radius_m - tolerance
        band_high[pair] = ball_radius_m + tolerance
    return queries, band_low, band_high
