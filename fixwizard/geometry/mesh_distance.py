"""Distance from points to a triangle mesh in float64, as a guaranteed interval, for any triangle shape; and rays
cast against the same hierarchy (first hits, crossings for inside tests).

Open3D answers closest-point queries in float32 with an error that grows with the triangle's shape (up to
0.6 mm on 1 m long, 1 mm wide triangles), so the search's exact stage runs here instead: a bounding-volume
hierarchy over the triangles and, per triangle, an interval ``[low, high]`` that holds the true Euclidean
distance whatever the triangle's shape.

Per triangle (``triangle_interval_m``), all arithmetic relative to its first vertex ``a``, with ``u = 2^-53``
float64's unit roundoff, ``L`` the longest edge and ``S = |x - a| + L``:

- ``high``: the smaller of the distances to the closest point by Voronoi regions (Ericson 5.1.5, with clamped
  barycentrics, so every branch returns a point of the triangle whatever the rounding) and to each edge's
  nearest point; plus ``ROUNDING_ULPS * u * S``.
- ``low``, the larger of two bounds, each robust where the other is not:
  - plane and edge lines: ``sqrt(h^2 + max(0, s_max)^2)`` with ``h`` the distance to the triangle's plane and
    ``s_max`` the largest in-plane distance outside one of the three edge lines. The unit normal is the cross
    product of the two edges that meet at the largest angle; its direction errs by at most
    ``phi = NORMAL_ULPS * u * |e1| |e2| / |e1 x e2|`` (at most ``NORMAL_ULPS * u * L / w_min``, with ``w_min``
    the smallest height), which moves ``h`` and each ``s_k`` by at most ``phi (|x - a| + L)`` and can flip the
    side of an edge line only for a triangle thinner than ``phi L`` there: both are covered by ``2 phi S``.
  - edges: every point of the triangle lies within ``w_k`` (the opposite vertex's distance from segment ``k``)
    of edge ``k``, so the distance is at least ``d(x, e_k) - w_k``; segment distances are well conditioned for
    any shape.

  The first is tight for well-shaped triangles and loses ``2 phi S`` on slivers; the second is tight for slivers
  (small ``w_k``). Their worst case over all shapes is about ``sqrt(u) S``: 1e-8 m for a 1 m triangle.
  Then ``ROUNDING_ULPS * u * S`` is taken off.

Every other rounding step is covered by ``ROUNDING_ULPS * u * S``: each computed length is a short chain of
sums of products of magnitudes at most ``S``, each step rounding by at most ``u`` relative; 64 ulps is several
times the longest chain. ``tests/test_mesh_distance.py`` checks ``low <= exact <= high`` against exact rational
arithmetic on random triangles of aspect up to 1e9 and points from 1e-7 m to 1 m away.

The hierarchy (``MeshDistance``) prunes a node when a lower bound on its box's distance exceeds the smallest
``high`` so far: no triangle in it can be nearer. The mesh's distance then lies in ``[min low, min high]`` over
the triangles visited, and the triangle of the smallest ``high`` is returned with its closest point.
"""

import math
from typing import Any

import numba
import numpy as np

from fixwizard.parallel import PARALLEL_KERNEL_LOCK

UNIT_ROUNDOFF = 2.0**-53
# A closest point within this barycentric margin of an edge or vertex takes that feature's pseudonormal for its sign
# (that is safe for points whose true closest feature is the face itself); beyond it, the face's plane signs it.
FEATURE_MARGIN = 1e-3
Vector3 = tuple[float, float, float]  # a point or an offset (m) as three floats, as the compiled kernels pass them
Arrays = tuple[Any, ...]  # several arrays passed to a compiled kernel as one argument
ROUNDING_ULPS = 64.0
NORMAL_ULPS = 16.0
LEAF_TRIANGLES = 4
# The traversals keep one stacked node per level of the hierarchy (and the root's): a hierarchy deeper than this
# would overrun them. The surface-area heuristic can peel off one triangle per level (triangles shrinking
# geometrically, as on a mesh graded towards a point), so below SAH_DEPTH every node is split at its median instead,
# which adds at most log2(F / LEAF_TRIANGLES) < 30 levels for any mesh that fits in memory.
STACK_DEPTH = 128
SAH_DEPTH = 64
BLOCK_POINTS = 1024  # points per parallel work item
SERIAL_POINTS = 2 * BLOCK_POINTS  # fewer points are queried on the calling thread


@numba.njit(nogil=True, cache=True, inline="always")
def _dot(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    return a0 * b0 + a1 * b1 + a2 * b2


@numba.njit(nogil=True, cache=True, inline="always")
def _fraction(numerator: float, denominator: float) -> float:
    """``numerator / denominator`` clamped to [0, 1]; 0 where the denominator is not positive."""
    return min(max(numerator / denominator, 0.0), 1.0) if denominator > 0.0 else 0.0


@numba.njit(nogil=True, cache=True, inline="always")
def _segment_distance_m(o0: float, o1: float, o2: float, e0: float, e1: float, e2: float) -> float:
    """Distance (m) from offset ``o`` (point minus the segment's start) to the segment along ``e``."""
    t = _fraction(_dot(o0, o1, o2, e0, e1, e2), _dot(e0, e1, e2, e0, e1, e2))
    r0, r1, r2 = o0 - t * e0, o1 - t * e1, o2 - t * e2
    return math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)


@numba.njit(nogil=True, cache=True)
def closest_weights(p0: float, p1: float, p2: float, ab: Vector3, ac: Vector3) -> tuple[float, float]:
    """Barycentric weights ``(v, w)`` of the point ``a + v ab + w ac`` of a triangle closest to ``a + p`` by
    Voronoi regions (Ericson 5.1.5). Clamped, so the point lies on the triangle whatever the rounding."""
    ab0, ab1, ab2 = ab
    ac0, ac1, ac2 = ac
    d1 = _dot(ab0, ab1, ab2, p0, p1, p2)
    d2 = _dot(ac0, ac1, ac2, p0, p1, p2)
    if d1 <= 0.0 and d2 <= 0.0:  # vertex a
        return 0.0, 0.0
    d3 = _dot(ab0, ab1, ab2, p0 - ab0, p1 - ab1, p2 - ab2)
    d4 = _dot(ac0, ac1, ac2, p0 - ab0, p1 - ab1, p2 - ab2)
    if d3 >= 0.0 and d4 <= d3:  # vertex b
        return 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:  # edge ab
        return _fraction(d1, d1 - d3), 0.0
    d5 = _dot(ab0, ab1, ab2, p0 - ac0, p1 - ac1, p2 - ac2)
    d6 = _dot(ac0, ac1, ac2, p0 - ac0, p1 - ac1, p2 - ac2)
    if d6 >= 0.0 and d5 <= d6:  # vertex c
        return 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:  # edge ac
        return 0.0, _fraction(d2, d2 - d6)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:  # edge bc
        w = _fraction(d4 - d3, (d4 - d3) + (d5 - d6))
        return 1.0 - w, w
    total = va + vb + vc
    v, w = _fraction(vb, total), _fraction(vc, total)
    if v + w > 1.0:
        return 0.0, 0.0
    return v, w



# Per-triangle data (float64 rows): first vertex a, edges ab and ac (m); unit normal; the normal's slack factor
# 2 phi (0 where the triangle is too thin for a normal); outward in-plane unit normals of edges ab, bc, ca;
# widths w_ab, w_bc, w_ca (m); the longest edge (m).
_A, _AB, _AC, _NORMAL, _SLACK, _SIDES, _WIDTHS, _LONGEST = 0, 3, 6, 9, 12, 13, 22, 25
ROW = 26


@numba.njit(nogil=True, cache=True)
def triangle_row(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The data ``triangle_row_interval_m`` needs of triangle ``abc`` (see the row layout above)."""
    row = np.zeros(ROW)
    ab = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
    ac = (c[0] - a[0], c[1] - a[1], c[2] - a[2])
    bc = (ac[0] - ab[0], ac[1] - ab[1], ac[2] - ab[2])
    for axis in range(3):
        row[_A + axis], row[_AB + axis], row[_AC + axis] = a[axis], ab[axis], ac[axis]
    length_ab = math.sqrt(_dot(ab[0], ab[1], ab[2], ab[0], ab[1], ab[2]))
    length_ac = math.sqrt(_dot(ac[0], ac[1], ac[2], ac[0], ac[1], ac[2]))
    length_bc = math.sqrt(_dot(bc[0], bc[1], bc[2], bc[0], bc[1], bc[2]))
    row[_LONGEST] = max(length_ab, length_ac, length_bc)
    row[_WIDTHS] = _segment_distance_m(ac[0], ac[1], ac[2], ab[0], ab[1], ab[2])
    row[_WIDTHS + 1] = _segment_distance_m(-ab[0], -ab[1], -ab[2], bc[0], bc[1], bc[2])
    row[_WIDTHS + 2] = _segment_distance_m(ab[0] - ac[0], ab[1] - ac[1], ab[2] - ac[2], -ac[0], -ac[1], -ac[2])
    # the normal from the two edges meeting at the largest angle: at the vertex opposite the longest edge
    if length_bc >= length_ab and length_bc >= length_ac:
        e, f, first, second = ab, ac, length_ab, length_ac
    elif length_ac >= length_ab:
        e, f, first, second = bc, (-ab[0], -ab[1], -ab[2]), length_bc, length_ab
    else:
        e, f, first, second = (-ac[0], -ac[1], -ac[2]), (-bc[0], -bc[1], -bc[2]), length_ac, length_bc
    n0, n1, n2 = e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0]
    n_length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if n_length == 0.0:
        return row
    phi = NORMAL_ULPS * UNIT_ROUNDOFF * first * second / n_length
    if phi >= 0.25:
        return row
    n0, n1, n2 = n0 / n_length, n1 / n_length, n2 / n_length
    row[_NORMAL], row[_NORMAL + 1], row[_NORMAL + 2] = n0, n1, n2
    row[_SLACK] = 2.0 * phi
    edges = (ab, bc, (-ac[0], -ac[1], -ac[2]))
    thirds = (ac, (-ab[0], -ab[1], -ab[2]), (ab[0] - ac[0], ab[1] - ac[1], ab[2] - ac[2]))  # third vertex - start
    for k in range(3):
        g, t = edges[k], thirds[k]
        m0, m1, m2 = g[1] * n2 - g[2] * n1, g[2] * n0 - g[0] * n2, g[0] * n1 - g[1] * n0
        m_length = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        if m_length == 0.0:
            continue
        away = -1.0 if _dot(t[0], t[1], t[2], m0, m1, m2) > 0.0 else 1.0  # the side away from the third vertex
        base = _SIDES + 3 * k
        row[base], row[base + 1], row[base + 2] = away * m0 / m_length, away * m1 / m_length, away * m2 / m_length
    return row


@numba.njit(nogil=True, cache=True, inline="always")
def row_point_m(row: np.ndarray, v: float, w: float) -> Vector3:
    """The point (m) of a row's triangle with barycentric weights ``v``, ``w`` of its second and third vertex,
    computed as ``a + v (b - a) + w (c - a)``."""
    return (row[_A] + v * row[_AB] + w * row[_AC], row[_A + 1] + v * row[_AB + 1] + w * row[_AC + 1],
            row[_A + 2] + v * row[_AB + 2] + w * row[_AC + 2])


@numba.njit(nogil=True, cache=True, inline="always")
def row_normal(row: np.ndarray) -> Vector3:
    """The row's unit normal (zero where the triangle is too thin for one)."""
    return row[_NORMAL], row[_NORMAL + 1], row[_NORMAL + 2]


@numba.njit(nogil=True, cache=True, inline="always")
def _plane_low_m(x0: float, x1: float, x2: float, row: np.ndarray) -> float:
    """A cheap lower bound (m) on the distance from point ``x`` to the row's triangle: the distance to its plane
    less the normal's slack and the rounding (negative where the triangle has no normal)."""
    p0, p1, p2 = x0 - row[_A], x1 - row[_A + 1], x2 - row[_A + 2]
    scale = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2) + row[_LONGEST]
    height = abs(_dot(p0, p1, p2, row[_NORMAL], row[_NORMAL + 1], row[_NORMAL + 2]))
    return height - (row[_SLACK] + ROUNDING_ULPS * UNIT_ROUNDOFF) * scale if row[_SLACK] > 0.0 else -1.0


@numba.njit(nogil=True, cache=True, inline="always")
def _closest_point_offset(x0: float, x1: float, x2: float, row: np.ndarray) -> tuple[Vector3, float, float, float]:
    """``x - a`` for point ``x``, the weights ``(v, w)`` of the triangle's point closest to ``x`` (Voronoi
    regions, clamped), and that point's distance (m), without rounding allowance."""
    p = (x0 - row[_A], x1 - row[_A + 1], x2 - row[_A + 2])
    ab = (row[_AB], row[_AB + 1], row[_AB + 2])
    ac = (row[_AC], row[_AC + 1], row[_AC + 2])
    v, w = closest_weights(p[0], p[1], p[2], ab, ac)
    r0, r1, r2 = p[0] - v * ab[0] - w * ac[0], p[1] - v * ab[1] - w * ac[1], p[2] - v * ab[2] - w * ac[2]
    return p, v, w, math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)


@numba.njit(nogil=True, cache=True, inline="always")
def _rounding_m(p: Vector3, row: np.ndarray) -> float:
    return ROUNDING_ULPS * UNIT_ROUNDOFF * (math.sqrt(_dot(p[0], p[1], p[2], p[0], p[1], p[2])) + row[_LONGEST])


@numba.njit(nogil=True, cache=True)
def triangle_row_high_m(x0: float, x1: float, x2: float, row: np.ndarray) -> float:
    """An upper bound (m) on the distance from point ``x`` to the row's triangle: the distance to a point of it
    plus the rounding allowance (see the module doc)."""
    p, _, _, distance = _closest_point_offset(x0, x1, x2, row)
    return distance + _rounding_m(p, row)


@numba.njit(nogil=True, cache=True)
def triangle_row_interval_m(x0: float, x1: float, x2: float, row: np.ndarray) -> tuple[float, float, float, float]:
    """``(low, high, v, w)``: an interval (m) holding the distance from point ``x`` to the row's triangle (any
    shape, degenerate included; see the module doc), and the barycentric weights of the point giving ``high``
    (of the triangle's second and third vertex)."""
    p, v, w, point_distance = _closest_point_offset(x0, x1, x2, row)
    ab = (row[_AB], row[_AB + 1], row[_AB + 2])
    ac = (row[_AC], row[_AC + 1], row[_AC + 2])
    pb = (p[0] - ab[0], p[1] - ab[1], p[2] - ab[2])
    pc = (p[0] - ac[0], p[1] - ac[1], p[2] - ac[2])
    edge_ab = _segment_distance_m(p[0], p[1], p[2], ab[0], ab[1], ab[2])
    edge_bc = _segment_distance_m(pb[0], pb[1], pb[2], ac[0] - ab[0], ac[1] - ab[1], ac[2] - ab[2])
    edge_ca = _segment_distance_m(pc[0], pc[1], pc[2], -ac[0], -ac[1], -ac[2])
    rounding = _rounding_m(p, row)
    nearest_edge = min(edge_ab, edge_bc, edge_ca)
    high = min(point_distance, nearest_edge) + rounding
    # every point of the triangle lies within w_k of edge k
    low = max(edge_ab - row[_WIDTHS], edge_bc - row[_WIDTHS + 1], edge_ca - row[_WIDTHS + 2])
    if row[_SLACK] > 0.0:
        slack = row[_SLACK] * (rounding / (ROUNDING_ULPS * UNIT_ROUNDOFF))
        height = max(abs(_dot(p[0], p[1], p[2], row[_NORMAL], row[_NORMAL + 1], row[_NORMAL + 2])) - slack, 0.0)
        outside = max(_dot(p[0], p[1], p[2], row[_SIDES], row[_SIDES + 1], row[_SIDES + 2]),
                      _dot(pb[0], pb[1], pb[2], row[_SIDES + 3], row[_SIDES + 4], row[_SIDES + 5]),
                      _dot(pc[0], pc[1], pc[2], row[_SIDES + 6], row[_SIDES + 7], row[_SIDES + 8])) - slack
        # projecting outside an edge line for sure, the nearest point of the triangle is on an edge; projecting
        # inside every edge line for sure, the foot on the plane is (nearly) a point of the triangle
        low = max(low, nearest_edge if outside > 0.0 else height)
        if outside + 2.0 * slack < 0.0:
            high = min(high, height + 2.0 * slack + rounding)
    return max(low - rounding, 0.0), high, v, w


@numba.njit(nogil=True, cache=True)
def triangle_row_reach_high_m(x0: float, x1: float, x2: float, row: np.ndarray, along_m: float,
                              across_m: float) -> float:
    """An upper bound (m) on the distance to the row's triangle from every point ``x'`` with ``|x' - x| <= across_m``
    and ``|n . (x' - x)| <= along_m`` (``n`` the row's unit normal), for a point ``x`` whose foot on the triangle's
    plane lies inside the triangle; inf where that foot is not surely inside (or the triangle has no normal).

    With the true unit normal ``n*``, ``x``'s true foot ``f`` and ``m`` its true in-plane distance from the three
    edge lines, the disc of radius ``m`` about ``f`` lies in the triangle, so the distance from ``x'`` is at most
    ``sqrt((|n* . (x - f)| + |n* . (x' - x)|)^2 + max(0, |x' - x| - m)^2)``. The row's normal errs by at most
    ``phi`` (its slack is ``2 phi``), which moves the height ``|n . (x - a)|`` and each in-plane edge distance by at
    most ``2 phi S`` (see the module doc) and ``n* . (x' - x)`` by at most ``2 phi |x' - x|``.
    """
    if row[_SLACK] <= 0.0:
        return np.inf
    p = (x0 - row[_A], x1 - row[_A + 1], x2 - row[_A + 2])
    pb = (p[0] - row[_AB], p[1] - row[_AB + 1], p[2] - row[_AB + 2])
    pc = (p[0] - row[_AC], p[1] - row[_AC + 1], p[2] - row[_AC + 2])
    rounding = _rounding_m(p, row)
    slack = row[_SLACK] * (rounding / (ROUNDING_ULPS * UNIT_ROUNDOFF)) + rounding
    outside = max(_dot(p[0], p[1], p[2], row[_SIDES], row[_SIDES + 1], row[_SIDES + 2]),
                  _dot(pb[0], pb[1], pb[2], row[_SIDES + 3], row[_SIDES + 4], row[_SIDES + 5]),
                  _dot(pc[0], pc[1], pc[2], row[_SIDES + 6], row[_SIDES + 7], row[_SIDES + 8]))
    margin = -outside - slack
    if margin <= 0.0:
        return np.inf
    height = abs(_dot(p[0], p[1], p[2], row[_NORMAL], row[_NORMAL + 1], row[_NORMAL + 2])) + slack
    along = height + along_m + row[_SLACK] * across_m
    beside = max(across_m - margin, 0.0)
    return math.sqrt(along * along + beside * beside) * (1.0 + 8.0 * UNIT_ROUNDOFF) + rounding


@numba.njit(nogil=True, cache=True)
def triangle_interval_m(x: np.ndarray, a: np.ndarray, b: np.ndarray,
                        c: np.ndarray) -> tuple[float, float, float, float]:
    """``triangle_row_interval_m`` of triangle ``abc``."""
    return triangle_row_interval_m(x[0], x[1], x[2], triangle_row(a, b, c))


@numba.njit(nogil=True, cache=True)
def _triangle_rows(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    rows = np.empty((len(triangles), ROW))
    for face in range(len(triangles)):
        rows[face] = triangle_row(vertices[triangles[face, 0]], vertices[triangles[face, 1]],
                                  vertices[triangles[face, 2]])
    return rows


@numba.njit(nogil=True, cache=True)
def _best_split(boxes: np.ndarray, start: int, stop: int, prefix: np.ndarray) -> int:
    """Where to split rows ``start:stop`` of ``boxes`` (low xyz, high xyz per row, sorted along an axis) so that the
    children's box surfaces times their triangle counts are smallest (the surface-area heuristic); ``prefix`` is
    scratch space of at least ``stop - start``."""
    count = stop - start
    low0 = low1 = low2 = np.inf
    high0 = high1 = high2 = -np.inf
    for index in range(count):
        row = start + index
        low0, low1, low2 = min(low0, boxes[row, 0]), min(low1, boxes[row, 1]), min(low2, boxes[row, 2])
        high0, high1, high2 = max(high0, boxes[row, 3]), max(high1, boxes[row, 4]), max(high2, boxes[row, 5])
        e0, e1, e2 = high0 - low0, high1 - low1, high2 - low2
        prefix[index] = (e0 * e1 + e1 * e2 + e2 * e0) * (index + 1)
    low0 = low1 = low2 = np.inf
    high0 = high1 = high2 = -np.inf
    best, best_cost = count // 2, np.inf
    for index in range(count - 1, 0, -1):
        row = start + index
        low0, low1, low2 = min(low0, boxes[row, 0]), min(low1, boxes[row, 1]), min(low2, boxes[row, 2])
        high0, high1, high2 = max(high0, boxes[row, 3]), max(high1, boxes[row, 4]), max(high2, boxes[row, 5])
        e0, e1, e2 = high0 - low0, high1 - low1, high2 - low2
        cost = prefix[index - 1] + (e0 * e1 + e1 * e2 + e2 * e0) * (count - index)
        if cost < best_cost:
            best, best_cost = index, cost
    return best


@numba.njit(nogil=True, cache=True)
def _sort_rows(boxes: np.ndarray, order: np.ndarray, start: int, stop: int, axis: int, keys: np.ndarray,
               spare: np.ndarray, spare_order: np.ndarray) -> None:
    """Sort rows ``start:stop`` of ``boxes`` and ``order`` by their box centre along ``axis`` (stable: ties keep
    their order); ``keys``, ``spare`` and ``spare_order`` are scratch space."""
    count = stop - start
    for index in range(count):
        keys[index] = 0.5 * (boxes[start + index, axis] + boxes[start + index, axis + 3])
    permutation = np.argsort(keys[:count], kind="mergesort")
    for index in range(count):
        source = start + permutation[index]
        spare_order[index] = order[source]
        for column in range(6):
            spare[index, column] = boxes[source, column]
    for index in range(count):
        order[start + index] = spare_order[index]
        for column in range(6):
            boxes[start + index, column] = spare[index, column]


@numba.njit(nogil=True, cache=True)
def _build_hierarchy(lows: np.ndarray, highs: np.ndarray) -> Arrays:
    """Bounding-volume hierarchy over boxes ``(F, 3)`` (m): each node split along the widest axis of its centres
    where the surface-area heuristic says (at its median from level ``SAH_DEPTH`` on, so that no traversal's
    ``STACK_DEPTH`` is overrun), at most ``LEAF_TRIANGLES`` per leaf. Returns the nodes' boxes (low,
    high), each inner node's two children (-1 for a leaf), each node's range in ``order``, and ``order`` (the
    triangles, leaf by leaf). The triangles' boxes are kept in ``order``'s order as it is built, so that every
    pass over a node's members reads them in sequence (they lie scattered over the mesh's memory otherwise)."""
    count = len(lows)
    order = np.arange(count)
    boxes = np.empty((count, 6))
    boxes[:, :3] = lows
    boxes[:, 3:] = highs
    keys, prefix = np.empty(count), np.empty(count)
    spare, spare_order = np.empty((count, 6)), np.empty(count, np.int64)
    centre_low, centre_high = np.empty(3), np.empty(3)
    capacity = 2 * count + 1
    node_low = np.empty((capacity, 3))
    node_high = np.empty((capacity, 3))
    children = np.full((capacity, 2), -1, np.int64)
    ranges = np.zeros((capacity, 2), np.int64)
    stack = np.empty((capacity, 4), np.int64)  # node, start, stop, its level (the root's: 0)
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = 0, 0, count, 0
    nodes, depth = 1, 1
    while depth > 0:
        depth -= 1
        node, start, stop, level = stack[depth, 0], stack[depth, 1], stack[depth, 2], stack[depth, 3]
        node_low[node], node_high[node] = np.inf, -np.inf
        centre_low[:], centre_high[:] = np.inf, -np.inf
        for row in range(start, stop):
            for axis in range(3):
                node_low[node, axis] = min(node_low[node, axis], boxes[row, axis])
                node_high[node, axis] = max(node_high[node, axis], boxes[row, axis + 3])
                centre = 0.5 * (boxes[row, axis] + boxes[row, axis + 3])
                centre_low[axis] = min(centre_low[axis], centre)
                centre_high[axis] = max(centre_high[axis], centre)
        ranges[node, 0], ranges[node, 1] = start, stop
        if stop - start <= LEAF_TRIANGLES:
            continue
        _sort_rows(boxes, order, start, stop, int(np.argmax(centre_high - centre_low)), keys, spare, spare_order)
        middle = start + (_best_split(boxes, start, stop, prefix) if level < SAH_DEPTH else (stop - start) // 2)
        children[node, 0], children[node, 1] = nodes, nodes + 1
        stack[depth, 0], stack[depth, 1], stack[depth, 2], stack[depth, 3] = nodes, start, middle, level + 1
        stack[depth + 1, 0], stack[depth + 1, 1], stack[depth + 1, 2] = nodes + 1, middle, stop
        stack[depth + 1, 3] = level + 1
        nodes += 2
        depth += 2
    return node_low[:nodes], node_high[:nodes], children[:nodes], ranges[:nodes], order


@numba.njit(nogil=True, cache=True, inline="always")
def _box_low_m(x: np.ndarray, low: np.ndarray, high: np.ndarray) -> float:
    """A lower bound (m) on the distance from ``x`` to a box (float64 rounding taken off)."""
    total = 0.0
    for axis in range(3):
        gap = max(low[axis] - x[axis], x[axis] - high[axis], 0.0)
        total += gap * gap
    return math.sqrt(total) * (1.0 - 8.0 * UNIT_ROUNDOFF)


@numba.njit(nogil=True, cache=True)
def _nearest_within(x: np.ndarray, rows: np.ndarray, hierarchy: Arrays, hint: int,
                    cap: float) -> tuple[float, float, int, float, float]:
    """The hierarchy's traversal for ``query_point``: boxes and planes farther than ``min(best high, cap)`` (m)
    are pruned. The result is the exact interval where its ``high`` is at most ``cap``; where it is more, every
    pruned triangle lies beyond ``cap`` and the interval's ``low`` is only the least among those visited."""
    node_low, node_high, children, ranges, order = hierarchy
    stack = np.empty(STACK_DEPTH, np.int64)
    reach = np.empty(STACK_DEPTH)  # each stacked node's box distance bound
    stack[0], reach[0] = 0, 0.0
    depth = 1
    best_low, best_high, best_face, best_v, best_w = np.inf, np.inf, -1, 0.0, 0.0
    if hint >= 0:
        best_low, best_high, best_v, best_w = triangle_row_interval_m(x[0], x[1], x[2], rows[hint])
        best_face = hint
    while depth > 0:
        depth -= 1
        node = stack[depth]
        if reach[depth] > min(best_high, cap):
            continue
        if children[node, 0] < 0:
            for slot in range(ranges[node, 0], ranges[node, 1]):
                face = order[slot]
                if _plane_low_m(x[0], x[1], x[2], rows[face]) > min(best_high, cap):
                    continue
                low, high, v, w = triangle_row_interval_m(x[0], x[1], x[2], rows[face])
                best_low = min(best_low, low)
                if high < best_high:
                    best_high, best_face, best_v, best_w = high, face, v, w
            continue
        first, second = children[node, 0], children[node, 1]
        first_reach = _box_low_m(x, node_low[first], node_high[first])
        second_reach = _box_low_m(x, node_low[second], node_high[second])
        if first_reach > second_reach:
            first, second, first_reach, second_reach = second, first, second_reach, first_reach
        stack[depth], reach[depth] = second, second_reach
        stack[depth + 1], reach[depth + 1] = first, first_reach
        depth += 2
    return best_low, best_high, best_face, best_v, best_w


@numba.njit(nogil=True, cache=True)
def query_point(x: np.ndarray, rows: np.ndarray, hierarchy: Arrays, hint: int,
                cap: float) -> tuple[float, float, int, float, float]:
    """The mesh's distance interval at ``x`` (m), the triangle of the smallest ``high`` and its weights. ``hint``:
    a triangle likely to be near (-1: none); its interval starts the search, so that far nodes are pruned at once
    (the result is the same: every triangle nearer than its ``high`` is still visited). ``cap`` (m): where the
    distance is surely at least ``cap`` the interval is ``[cap, inf]`` and the triangle -1, found without
    searching beyond ``cap``; everywhere else the interval is the exact one (as with ``cap`` infinite)."""
    low, high, face, v, w = _nearest_within(x, rows, hierarchy, hint, cap)
    if high <= cap:
        return low, high, face, v, w
    if low >= cap:
        return cap, np.inf, -1, 0.0, 0.0
    return _nearest_within(x, rows, hierarchy, hint, np.inf)  # the nearest lies within cap or just beyond it


@numba.njit(nogil=True, cache=True)
def _query_range(start: int, stop: int, points: np.ndarray, rows: np.ndarray, hierarchy: Arrays, hints: np.ndarray,
                 cap: float, out: Arrays) -> None:
    low_out, high_out, face_out, weights_out = out
    for point in range(start, stop):
        low, high, face, v, w = query_point(points[point], rows, hierarchy, hints[point], cap)
        low_out[point], high_out[point], face_out[point] = low, high, face
        weights_out[point, 0], weights_out[point, 1] = v, w


@numba.njit(nogil=True, cache=True, parallel=True)
def _query(points: np.ndarray, rows: np.ndarray, hierarchy: Arrays, hints: np.ndarray, cap: float,
           out: Arrays) -> None:
    count = len(points)
    blocks = (count + BLOCK_POINTS - 1) // BLOCK_POINTS
    for block in numba.prange(blocks):
        _query_range(block * BLOCK_POINTS, min(count, (block + 1) * BLOCK_POINTS), points, rows, hierarchy, hints,
                     cap, out)


@numba.njit(nogil=True, cache=True, inline="always")
def _ray_box_entry(origin: np.ndarray, inverse: np.ndarray, low: np.ndarray, high: np.ndarray) -> float:
    """Where a ray (origin, inverse direction) enters a box, as its parameter t >= 0; inf when it misses."""
    near, far = 0.0, np.inf
    for axis in range(3):
        first = (low[axis] - origin[axis]) * inverse[axis]
        second = (high[axis] - origin[axis]) * inverse[axis]
        if first != first or second != second:  # 0 * inf: the ray runs in the slab's plane
            if origin[axis] < low[axis] or origin[axis] > high[axis]:
                return np.inf
            continue
        near = max(near, min(first, second))
        far = min(far, max(first, second))
    return near if near <= far * (1.0 + 8.0 * UNIT_ROUNDOFF) else np.inf


@numba.njit(nogil=True, cache=True, inline="always")
def _ray_triangle_t(origin: np.ndarray, direction: np.ndarray, row: np.ndarray) -> float:
    """Parameter t > 0 where the ray crosses the row's triangle (Moeller-Trumbore), inf when it does not."""
    ab0, ab1, ab2 = row[_AB], row[_AB + 1], row[_AB + 2]
    ac0, ac1, ac2 = row[_AC], row[_AC + 1], row[_AC + 2]
    p0 = direction[1] * ac2 - direction[2] * ac1
    p1 = direction[2] * ac0 - direction[0] * ac2
    p2 = direction[0] * ac1 - direction[1] * ac0
    determinant = _dot(ab0, ab1, ab2, p0, p1, p2)
    if determinant == 0.0:
        return np.inf
    inverse = 1.0 / determinant
    t0, t1, t2 = origin[0] - row[_A], origin[1] - row[_A + 1], origin[2] - row[_A + 2]
    u = _dot(t0, t1, t2, p0, p1, p2) * inverse
    if u < 0.0 or u > 1.0:
        return np.inf
    q0, q1, q2 = t1 * ab2 - t2 * ab1, t2 * ab0 - t0 * ab2, t0 * ab1 - t1 * ab0
    v = _dot(direction[0], direction[1], direction[2], q0, q1, q2) * inverse
    if v < 0.0 or u + v > 1.0:
        return np.inf
    t = _dot(ac0, ac1, ac2, q0, q1, q2) * inverse
    return t if t > 0.0 else np.inf


@numba.njit(nogil=True, cache=True)
def _ray_range(start: int, stop: int, origins: np.ndarray, directions: np.ndarray, rows: np.ndarray,
               hierarchy: Arrays, first_out: np.ndarray, crossings_out: np.ndarray) -> None:
    """Per ray of ``start .. stop``: the parameter of its first hit (inf: none) and how many triangles it crosses."""
    node_low, node_high, children, ranges, order = hierarchy
    for ray in range(start, stop):
        origin, direction = origins[ray], directions[ray]
        inverse = np.empty(3)
        for axis in range(3):
            inverse[axis] = 1.0 / direction[axis] if direction[axis] != 0.0 else np.inf
        stack = np.empty(STACK_DEPTH, np.int64)
        stack[0] = 0
        depth = 1
        first, crossings = np.inf, 0
        while depth > 0:
            depth -= 1
            node = stack[depth]
            if _ray_box_entry(origin, inverse, node_low[node], node_high[node]) == np.inf:
                continue
            if children[node, 0] < 0:
                for slot in range(ranges[node, 0], ranges[node, 1]):
                    t = _ray_triangle_t(origin, direction, rows[order[slot]])
                    if t < np.inf:
                        crossings += 1
                        first = min(first, t)
                continue
            stack[depth], stack[depth + 1] = children[node, 0], children[node, 1]
            depth += 2
        first_out[ray], crossings_out[ray] = first, crossings


@numba.njit(nogil=True, cache=True, parallel=True)
def _rays(origins: np.ndarray, directions: np.ndarray, rows: np.ndarray, hierarchy: Arrays, first_out: np.ndarray,
          crossings_out: np.ndarray) -> None:
    count = len(origins)
    blocks = (count + BLOCK_POINTS - 1) // BLOCK_POINTS
    for block in numba.prange(blocks):
        _ray_range(block * BLOCK_POINTS, min(count, (block + 1) * BLOCK_POINTS), origins, directions, rows,
                   hierarchy, first_out, crossings_out)


class MeshDistance:
    """Unsigned distance intervals (m) from points to a triangle mesh (vertices ``(V, 3)`` m, triangles
    ``(F, 3)``), float64 throughout; see the module doc. ``rows``: each triangle's data for
    ``triangle_row_interval_m`` and ``triangle_row_high_m``; ``hierarchy``: the bounding-volume hierarchy, as
    ``query_point`` takes it."""

    def __init__(self, vertices_m: np.ndarray, triangles: np.ndarray) -> None:
        vertices = np.ascontiguousarray(vertices_m, np.float64)
        triangles = np.ascontiguousarray(triangles, np.int64)
        corners = vertices[triangles]
        self.rows = _triangle_rows(vertices, triangles)
        self.hierarchy = _build_hierarchy(corners.min(axis=1), corners.max(axis=1))

    def query(self, points_m: np.ndarray, hint_faces: np.ndarray | None = None,
              cap_m: float = np.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For each (N, 3) point: the interval's low and high ends (m), the triangle of the nearest point found,
        and that point's barycentric weights ``(N, 2)`` (of the triangle's second and third vertex).
        ``hint_faces`` (N,): a triangle likely near each point (-1 for none), which only makes the search faster.
        ``cap_m``: points farther from every triangle get ``[cap_m, inf]`` and triangle -1 (a far point costs a
        search of the whole hierarchy otherwise)."""
        points = np.ascontiguousarray(points_m, np.float64).reshape(-1, 3)
        count = len(points)
        hints = np.full(count, -1, np.int64) if hint_faces is None else np.ascontiguousarray(hint_faces, np.int64)
        if len(hints) != count or (count and (hints.min() < -1 or hints.max() >= len(self.rows))):
            raise ValueError("one hint face (or -1) per point, within the mesh")
        out = (np.empty(count), np.empty(count), np.empty(count, np.int64), np.empty((count, 2)))
        if count < SERIAL_POINTS:  # waking the parallel workers costs milliseconds: more than a few queries
            _query_range(0, count, points, self.rows, self.hierarchy, hints, float(cap_m), out)
        else:
            with PARALLEL_KERNEL_LOCK:
                _query(points, self.rows, self.hierarchy, hints, float(cap_m), out)
        return out

    def rays(self, origins_m: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each ray (origins (N, 3) m, directions (N, 3), any length): the parameter of its first hit along
        the direction (m for unit directions; inf when it hits nothing) and how many triangles it crosses (a ray
        grazing an edge may count a crossing twice or not at all)."""
        origins = np.ascontiguousarray(origins_m, np.float64).reshape(-1, 3)
        directions = np.ascontiguousarray(np.broadcast_to(directions, origins.shape), np.float64)
        first, crossings = np.empty(len(origins)), np.empty(len(origins), np.int64)
        if len(origins) < SERIAL_POINTS:
            _ray_range(0, len(origins), origins, directions, self.rows, self.hierarchy, first, crossings)
        else:
            with PARALLEL_KERNEL_LOCK:
                _rays(origins, directions, self.rows, self.hierarchy, first, crossings)
        return first, crossings
