"""A few balls that cover the vertices of a point cloud's convex hull: where a rigid motion moves a fixture point
farthest, for the displacement bounds.

The displacement ``|(R - C) p + t - c|`` of a point between two poses is convex in ``p``, so over a fixture it is
largest at a vertex of the fixture's convex hull; a hull vertex ``v`` within ``e`` of a ball's centre ``u`` moves
at most ``e |R - C| = e chord(angle(C^T R))`` more than ``u`` does. A hull of at most ``MAX_POINTS`` vertices is
its own cover (radii zero, exact). A larger one (a finely tessellated rounded part: every vertex of a 1.3 million
triangle ellipsoid lies on its hull, and a bound over all of them took minutes) is covered by one ball per
occupied cube of a grid coarse enough to leave at most ``MAX_POINTS``: centred on the mean of the vertices in it,
with the largest distance to them as radius. A cloud of more than ``QHULL_POINTS`` points first drops those
strictly inside the hull of its extreme points in a few hundred directions (none of them is a hull vertex), then
takes the hull of the rest if they are few enough for qhull (which takes seconds on hundreds of thousands), else
covers them all.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

MAX_POINTS = 2048
QHULL_POINTS = 50_000
INNER_DIRECTIONS = 512
CHUNK_VALUES = 10_000_000  # products per chunk of a point-by-direction pass (80 MB)
ROUNDING_RELATIVE = 1e-12  # added to each radius, of the cloud's size: above the rounding of means and distances


@dataclass(frozen=True)
class HullCover:
    """Ball centres ``points_m`` (K, 3) and radii ``radii_m`` (K,), m: every hull vertex lies in one ball."""

    points_m: np.ndarray
    radii_m: np.ndarray

    @property
    def radius_m(self) -> float:
        """Largest distance (m) of a covered point from the origin."""
        return float(np.max(np.linalg.norm(self.points_m, axis=1) + self.radii_m))


def _hull_vertices(points: np.ndarray) -> np.ndarray | None:
    """The vertices of the points' convex hull; None where it is flat or qhull fails."""
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:
        return None


def _fibonacci_directions(count: int) -> np.ndarray:
    """``count`` unit vectors spread evenly over the sphere."""
    index = np.arange(count) + 0.5
    z = 1.0 - 2.0 * index / count
    azimuth = np.pi * (1.0 + 5.0**0.5) * index
    ring = np.sqrt(1.0 - z * z)
    return np.column_stack([ring * np.cos(azimuth), ring * np.sin(azimuth), z])


def _beyond_inner_hull(points: np.ndarray) -> np.ndarray:
    """The points that can be vertices of the cloud's hull: all but those strictly inside the hull of its extreme
    points in ``INNER_DIRECTIONS`` directions (a point of that inner hull is a convex combination of cloud points,
    so no vertex). A box's lattice keeps its corners and faces; a ball's surface keeps nearly all."""
    offsets = points - points.mean(axis=0)
    directions = _fibonacci_directions(INNER_DIRECTIONS)
    farthest, extreme = np.full(len(directions), -np.inf), np.zeros(len(directions), np.int64)
    step = max(1, CHUNK_VALUES // len(directions))
    for start in range(0, len(points), step):
        along = directions @ offsets[start:start + step].T  # (directions, chunk): rows contiguous
        best = np.argmax(along, axis=1)
        better = along[np.arange(len(directions)), best] > farthest
        farthest[better] = along[np.arange(len(directions)), best][better]
        extreme[better] = start + best[better]
    extreme = np.unique(extreme)
    try:
        facets = ConvexHull(offsets[extreme]).equations  # n . x + e <= 0 inside
    except QhullError:
        return points
    margin = ROUNDING_RELATIVE * float(np.max(np.abs(offsets)))
    beyond = np.zeros(len(points), bool)
    beyond[extreme] = True
    step = max(1, CHUNK_VALUES // len(facets))
    for start in range(0, len(points), step):
        chunk = offsets[start:start + step]
        beyond[start:start + step] |= np.max(chunk @ facets[:, :3].T + facets[:, 3], axis=1) > -margin
    return points[beyond]


def _cube_keys(points: np.ndarray, low: np.ndarray, side: float) -> np.ndarray:
    """One integer per point naming the grid cube of side ``side`` (m) that holds it (at most 2^20 per axis)."""
    cubes = np.floor((points - low) / side).astype(np.int64)
    return (cubes[:, 0] << 42) | (cubes[:, 1] << 21) | cubes[:, 2]


def _grid_cover(points: np.ndarray) -> HullCover:
    """One ball per occupied cube of the coarsest grid (sides growing by a quarter from 1/1024 of the cloud's
    extent) that leaves at most ``MAX_POINTS`` of them; the side is first bracketed by doubling, on a sample."""
    low = points.min(axis=0)
    extent = float(np.max(points.max(axis=0) - low)) or 1.0
    side = extent / 1024.0
    sample = points[:: max(1, len(points) // 100_000)]
    while len(np.unique(_cube_keys(sample, low, 2.0 * side))) > MAX_POINTS:
        side *= 2.0
    while True:
        occupied, member_of = np.unique(_cube_keys(points, low, side), return_inverse=True)
        if len(occupied) <= MAX_POINTS:
            break
        side *= 1.25
    counts = np.bincount(member_of, minlength=len(occupied)).astype(float)
    sums = np.column_stack([np.bincount(member_of, points[:, axis], len(occupied)) for axis in range(3)])
    centres = sums / counts[:, None]
    distances = np.linalg.norm(points - centres[member_of], axis=1)
    radii = np.zeros(len(occupied))
    np.maximum.at(radii, member_of, distances)
    scale = extent + float(np.max(np.abs(points)))
    return HullCover(centres, radii + ROUNDING_RELATIVE * scale)


def hull_cover(points: np.ndarray) -> HullCover:
    """Balls covering every vertex of the (N, 3) points' convex hull (see the module doc)."""
    points = np.asarray(points, float)
    candidates = _beyond_inner_hull(points) if len(points) > QHULL_POINTS else points
    vertices = _hull_vertices(candidates) if 4 < len(candidates) <= QHULL_POINTS else None
    if vertices is not None:
        candidates = vertices
    if len(candidates) <= MAX_POINTS:
        return HullCover(candidates, np.zeros(len(candidates)))
    return _grid_cover(candidates)
