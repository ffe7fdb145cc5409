"""Which faces of a triangle mesh another face meets inside them: where a face's plane cannot be trusted to tell
inside from outside.

The distance's sign at a point whose closest point lies inside a face (each barycentric weight above
``FEATURE_MARGIN``) comes from that face's plane (``fixture.DistanceOracle`` and the search's compiled exact stage).
Nothing crosses the segment from the point to its closest point (a crossing would lie nearer the point; the closest
point's rounding is covered below), so that sign is right for every such point of a face when

1. no other face meets the face's inner triangle (each weight at least ``INNER_MARGIN``, half ``FEATURE_MARGIN``:
   room for the rounding of computed weights): the winding number just off the face is then the same all over it,
   on each side, since it changes only across the surface; and
2. just off one point of the face it is 0 on the outer side and 1 on the inner: ``mesh_hygiene`` looks at the
   centroid, ``step_m`` off both ways, once this module has found that
3. no other face meets that segment through the centroid, so both points lie just off this face.

``faces_met`` finds the faces where 1 or 3 fails. Meeting is decided by separating axes: two convex sets are apart
when their projections on some axis are. For two triangles the two normals, the cross products of their edges and
each triangle's edges turned in its own and in the other's plane suffice, whatever their shapes (coplanar, slivers
of zero area); for a segment and a triangle the normal, the segment's cross products with the edges, and the edges
and the segment turned in the plane. A projection is rounded by a few ulps of the coordinates; a gap counts only
beyond ``contact_tolerance_m`` (``CONTACT_SHARE`` of the mesh's size, far above that rounding and the closest
point's, far below any gap a part has), so what rounding hides counts as meeting: a face found unmet is unmet.

The faces near a face are those of the bounding-volume hierarchy whose boxes overlap its inner triangle's and the
segment's, and are not apart from them on its quick axes (its normal, its edges turned in its plane). A disc cut
in a fan of thousands of thin faces meeting at its centre gives each of them thousands (every box holds the centre),
quadratic time; a face with more than ``CANDIDATE_LIMIT`` is left ``CROWDED``, and its plane must not sign.
"""

import math

import numba
import numpy as np

from fixwizard.geometry.mesh_distance import FEATURE_MARGIN, STACK_DEPTH, UNIT_ROUNDOFF, MeshDistance
from fixwizard.parallel import PARALLEL_KERNEL_LOCK

INNER_MARGIN = 0.5 * FEATURE_MARGIN
# A gap between faces counts when wider than this share of the mesh's bounding-box diagonal (0.3 picometres on a 300 mm
# fixture) plus CONTACT_ULPS of its largest coordinate: the projections round by a few ulps of the coordinates, a
# closest point by about 1e-14 of the distance from its triangle's corner.
CONTACT_SHARE = 1e-12
CONTACT_ULPS = 256.0
BLOCK_FACES = 256  # faces per parallel work item
# A face with more faces near it than this (boxes overlapping its own, not apart on its quick axes) is not checked:
# thousands of long thin faces meeting at one vertex (a disc cut in a fan of thousands) would take quadratic time.
CANDIDATE_LIMIT = 512
UNMET, MET, CROWDED = 0, 1, 2


@numba.njit(nogil=True, cache=True, inline="always")
def _cross(u0: float, u1: float, u2: float, v0: float, v1: float, v2: float) -> tuple[float, float, float]:
    return u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0


@numba.njit(nogil=True, cache=True, inline="always")
def _edge(corners: np.ndarray, k: int) -> tuple[float, float, float]:
    """Edge ``k`` of a triangle (3 x 3 corners; from corner k to corner k + 1), or the segment (2 x 3 ends) itself."""
    following = (k + 1) % len(corners)
    return (corners[following, 0] - corners[k, 0], corners[following, 1] - corners[k, 1],
            corners[following, 2] - corners[k, 2])


@numba.njit(nogil=True, cache=True, inline="always")
def _range_along(points: np.ndarray, d0: float, d1: float, d2: float) -> tuple[float, float]:
    low = high = points[0, 0] * d0 + points[0, 1] * d1 + points[0, 2] * d2
    for k in range(1, len(points)):
        value = points[k, 0] * d0 + points[k, 1] * d1 + points[k, 2] * d2
        low, high = min(low, value), max(high, value)
    return low, high


@numba.njit(nogil=True, cache=True)
def _apart_along(first: np.ndarray, second: np.ndarray, axis: tuple[float, float, float], tolerance_m: float) -> bool:
    """Whether the points ``first`` and ``second`` (rows) project onto ``axis`` (any length) with a gap wider than
    ``tolerance_m``; never for a zero axis."""
    d0, d1, d2 = axis
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if length == 0.0:
        return False
    low_1, high_1 = _range_along(first, d0, d1, d2)
    low_2, high_2 = _range_along(second, d0, d1, d2)
    return max(low_2 - high_1, low_1 - high_2) > tolerance_m * length


@numba.njit(nogil=True, cache=True)
def _normal(corners: np.ndarray) -> tuple[float, float, float]:
    u0, u1, u2 = _edge(corners, 0)
    v0, v1, v2 = _edge(corners, 1)
    return _cross(u0, u1, u2, v0, v1, v2)


@numba.njit(nogil=True, cache=True)
def triangles_apart(first: np.ndarray, second: np.ndarray, tolerance_m: float) -> bool:
    """Whether two triangles (3 x 3 corners, m) lie more than ``tolerance_m`` apart along some separating axis: the
    normals, each normal crossed with every edge (each triangle's edges turned in either plane), every edge of one
    crossed with every edge of the other."""
    normal_1, normal_2 = _normal(first), _normal(second)
    if _apart_along(first, second, normal_1, tolerance_m) or _apart_along(first, second, normal_2, tolerance_m):
        return True
    for normal in (normal_1, normal_2):
        for corners in (first, second):
            for k in range(3):
                e0, e1, e2 = _edge(corners, k)
                if _apart_along(first, second, _cross(normal[0], normal[1], normal[2], e0, e1, e2), tolerance_m):
                    return True
    for i in range(3):
        u0, u1, u2 = _edge(first, i)
        for j in range(3):
            v0, v1, v2 = _edge(second, j)
            if _apart_along(first, second, _cross(u0, u1, u2, v0, v1, v2), tolerance_m):
                return True
    return False


@numba.njit(nogil=True, cache=True)
def segment_apart(ends: np.ndarray, corners: np.ndarray, tolerance_m: float) -> bool:
    """Whether a segment (2 x 3 ends, m) and a triangle (3 x 3 corners) lie more than ``tolerance_m`` apart along
    some separating axis: the normal, the segment crossed with each edge, the edges and the segment turned in the
    plane, and for a triangle of zero area (a segment) the normals within a plane holding both."""
    n0, n1, n2 = _normal(corners)
    s0, s1, s2 = _edge(ends, 0)
    if _apart_along(ends, corners, (n0, n1, n2), tolerance_m):
        return True
    if _apart_along(ends, corners, _cross(n0, n1, n2, s0, s1, s2), tolerance_m):
        return True
    for k in range(3):
        e0, e1, e2 = _edge(corners, k)
        a0, a1, a2 = _cross(s0, s1, s2, e0, e1, e2)
        if (_apart_along(ends, corners, (a0, a1, a2), tolerance_m)
                or _apart_along(ends, corners, _cross(n0, n1, n2, e0, e1, e2), tolerance_m)
                or _apart_along(ends, corners, _cross(a0, a1, a2, s0, s1, s2), tolerance_m)
                or _apart_along(ends, corners, _cross(a0, a1, a2, e0, e1, e2), tolerance_m)):
            return True
    return False


@numba.njit(nogil=True, cache=True, inline="always")
def _beyond(low: float, high: float, probe: np.ndarray, axis: np.ndarray, tolerance_m: float) -> bool:
    """Whether ``[low, high]`` lies more than ``tolerance_m`` beyond ``probe`` (low, high) along ``axis``."""
    width = tolerance_m * math.sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2])
    return low - probe[1] > width or probe[0] - high > width


@numba.njit(nogil=True, cache=True)
def _points_apart(points: np.ndarray, axes: np.ndarray, probe_ranges: np.ndarray, tolerance_m: float) -> bool:
    """Whether the points (rows) lie beyond the probe's range on one of ``axes``."""
    for k in range(len(axes)):
        low, high = _range_along(points, axes[k, 0], axes[k, 1], axes[k, 2])
        if _beyond(low, high, probe_ranges[k], axes[k], tolerance_m):
            return True
    return False


@numba.njit(nogil=True, cache=True)
def _box_apart(box_low: np.ndarray, box_high: np.ndarray, origin: np.ndarray, axes: np.ndarray,
               probe_ranges: np.ndarray, tolerance_m: float) -> bool:
    """Whether a box (absolute coordinates, m) lies beyond the probe's range (relative to ``origin``) on one of
    ``axes``: a subtree of the hierarchy no face of which can meet the probe."""
    for k in range(len(axes)):
        middle = spread = 0.0
        for axis in range(3):
            middle += (0.5 * (box_low[axis] + box_high[axis]) - origin[axis]) * axes[k, axis]
            spread += 0.5 * (box_high[axis] - box_low[axis]) * abs(axes[k, axis])
        if _beyond(middle - spread, middle + spread, probe_ranges[k], axes[k], tolerance_m):
            return True
    return False


@numba.njit(nogil=True, cache=True)
def _face_met(face: int, vertices: np.ndarray, faces: np.ndarray, hierarchy: tuple[np.ndarray, ...], step_m: float,
              tolerance_m: float, candidate_limit: int) -> tuple[int, int]:
    """Whether another face meets ``face``'s inner triangle or the segment ``step_m`` either side of its centroid
    along its normal (coordinates relative to its first corner): ``MET``, ``UNMET``, or ``CROWDED`` when more than
    ``candidate_limit`` faces lie near it; and how many faces were looked at. The inner triangle and the segment
    both project within the inner triangle's range onto its edges turned in its plane, and within the segment's
    onto its normal: a face (or a box of the hierarchy) apart on one of those four axes is apart from both, which
    settles most faces near it."""
    node_low, node_high, children, ranges, order = hierarchy
    origin = vertices[faces[face, 0]]
    inner = np.empty((3, 3))
    ends = np.empty((2, 3))
    other = np.empty((3, 3))
    for axis in range(3):
        ab = vertices[faces[face, 1], axis] - origin[axis]
        ac = vertices[faces[face, 2], axis] - origin[axis]
        inner[0, axis] = INNER_MARGIN * ab + INNER_MARGIN * ac
        inner[1, axis] = (1.0 - 2.0 * INNER_MARGIN) * ab + INNER_MARGIN * ac
        inner[2, axis] = INNER_MARGIN * ab + (1.0 - 2.0 * INNER_MARGIN) * ac
        ends[0, axis] = ends[1, axis] = (ab + ac) / 3.0
    n0, n1, n2 = _normal(inner)
    length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    for axis, component in enumerate((n0, n1, n2)):
        ends[0, axis] -= step_m * component / length
        ends[1, axis] += step_m * component / length
    # the quick axes: the normal (the segment's range, widened by twice the tolerance), the inner edges turned in
    # the plane (the inner triangle's ranges: the segment lies within them)
    quick_axes = np.empty((4, 3))
    quick_ranges = np.empty((4, 2))
    quick_axes[0, 0], quick_axes[0, 1], quick_axes[0, 2] = n0, n1, n2
    quick_ranges[0, 1] = (step_m + 2.0 * tolerance_m) * length
    quick_ranges[0, 0] = -quick_ranges[0, 1]
    for k in range(3):
        e0, e1, e2 = _edge(inner, k)
        quick_axes[k + 1] = _cross(n0, n1, n2, e0, e1, e2)
        quick_ranges[k + 1] = _range_along(inner, quick_axes[k + 1, 0], quick_axes[k + 1, 1], quick_axes[k + 1, 2])
    low, high = np.empty(3), np.empty(3)
    for axis in range(3):
        low[axis] = origin[axis] + min(inner[:, axis].min(), ends[:, axis].min()) - tolerance_m
        high[axis] = origin[axis] + max(inner[:, axis].max(), ends[:, axis].max()) + tolerance_m
    stack = np.empty(STACK_DEPTH, np.int64)
    stack[0] = 0
    depth = 1
    candidates = 0
    while depth > 0:
        depth -= 1
        node = stack[depth]
        outside = False
        for axis in range(3):
            outside |= node_low[node, axis] > high[axis] or node_high[node, axis] < low[axis]
        if outside or _box_apart(node_low[node], node_high[node], origin, quick_axes, quick_ranges, tolerance_m):
            continue
        if children[node, 0] >= 0:
            stack[depth], stack[depth + 1] = children[node, 0], children[node, 1]
            depth += 2
            continue
        for slot in range(ranges[node, 0], ranges[node, 1]):
            candidate = order[slot]
            if candidate == face:
                continue
            candidates += 1
            if candidates > candidate_limit:
                return CROWDED, candidates
            for corner in range(3):
                for axis in range(3):
                    other[corner, axis] = vertices[faces[candidate, corner], axis] - origin[axis]
            if _points_apart(other, quick_axes, quick_ranges, tolerance_m):
                continue
            if not triangles_apart(inner, other, tolerance_m) or not segment_apart(ends, other, tolerance_m):
                return MET, candidates
    return UNMET, candidates


@numba.njit(nogil=True, cache=True, parallel=True)
def _faces_met(vertices: np.ndarray, faces: np.ndarray, hierarchy: tuple[np.ndarray, ...], checked: np.ndarray,
               step_m: float, tolerance_m: float, candidate_limit: int, status_out: np.ndarray) -> None:
    blocks = (len(checked) + BLOCK_FACES - 1) // BLOCK_FACES
    for block in numba.prange(blocks):
        for slot in range(block * BLOCK_FACES, min(len(checked), (block + 1) * BLOCK_FACES)):
            status_out[slot] = _face_met(checked[slot], vertices, faces, hierarchy, step_m, tolerance_m,
                                         candidate_limit)[0]


def contact_tolerance_m(vertices_m: np.ndarray) -> float:
    """The gap (m) below which two faces of this mesh count as meeting (``CONTACT_SHARE``, ``CONTACT_ULPS``)."""
    size_m = float(np.linalg.norm(np.ptp(vertices_m, axis=0)))
    return CONTACT_SHARE * size_m + CONTACT_ULPS * UNIT_ROUNDOFF * float(np.abs(vertices_m).max())


def faces_met(surface: MeshDistance, vertices_m: np.ndarray, faces: np.ndarray, checked: np.ndarray,
              step_m: float, candidate_limit: int = CANDIDATE_LIMIT) -> np.ndarray:
    """For each face of ``checked`` (indices; each with a normal: not a sliver), whether another face of the mesh
    (``vertices_m`` (V, 3) m, ``faces`` (F, 3), ``surface`` its hierarchy) meets its inner triangle or the segment
    ``step_m`` (m) either side of its centroid along its normal (see the module doc): ``MET``, ``UNMET``, or
    ``CROWDED`` (not checked: more than ``candidate_limit`` faces near it)."""
    status = np.zeros(len(checked), np.int8)
    if len(checked):
        vertices = np.ascontiguousarray(vertices_m, np.float64)
        with PARALLEL_KERNEL_LOCK:
            _faces_met(vertices, np.ascontiguousarray(faces, np.int64), surface.hierarchy,
                       np.ascontiguousarray(checked, np.int64), float(step_m), contact_tolerance_m(vertices),
                       int(candidate_limit), status)
    return status
