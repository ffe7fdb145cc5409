"""Exact minimum enclosing ball of a point set in any dimension (Welzl, move-to-front).

Written by hand because the exact library for it (Gaertner's Miniball through
``cyminiball``) does not build here and ``trimesh.nsphere`` only tests furthest-site
Voronoi vertices, which misses balls fixed by fewer than d + 1 points.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError


@dataclass(frozen=True)
class Ball:
    """A ball: ``center`` (d,) and ``radius`` in the points' units."""

    center: np.ndarray
    radius: float


def _circumball(support: list[np.ndarray]) -> Ball:
    """Smallest ball with every support point on its boundary (the circumball of their affine hull)."""
    origin = support[0]
    if len(support) == 1:
        return Ball(origin.copy(), 0.0)
    edges = np.array([point - origin for point in support[1:]])
    gram = edges @ edges.T
    coefficients = np.linalg.lstsq(2.0 * gram, np.diag(gram), rcond=None)[0]
    center = origin + coefficients @ edges
    return Ball(center, float(np.linalg.norm(center - origin)))


def _contains(ball: Ball, point: np.ndarray) -> bool:
    return float(np.sum((point - ball.center) ** 2)) <= ball.radius**2 * (1.0 + 1e-12) + 1e-30


def _move_to_front_ball(points: list[np.ndarray], end: int, support: list[np.ndarray], dim: int) -> Ball:
    ball = _circumball(support) if support else Ball(points[0].copy(), 0.0)
    if len(support) == dim + 1:
        return ball
    for index in range(end):
        if not _contains(ball, points[index]):
            ball = _move_to_front_ball(points, index, support + [points[index]], dim)
            points.insert(0, points.pop(index))
    return ball


def _extreme_points(points: np.ndarray) -> np.ndarray:
    """The convex hull vertices (the MEB depends only on them); all points if the hull is degenerate."""
    if len(points) <= points.shape[1] + 1:
        return points
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:
        return points


def minimum_enclosing_ball(points: np.ndarray, seed: int = 0) -> Ball:
    """Exact minimum enclosing ball of (N, d) points.

    The radius is recomputed as the largest distance from the centre, so the ball
    encloses every point exactly even where the centre carries rounding error.
    """
    points = np.asarray(points, float)
    if points.ndim != 2 or len(points) == 0:
        raise ValueError("minimum_enclosing_ball needs a non-empty (N, d) array")
    candidates = np.unique(_extreme_points(points), axis=0)
    order = np.random.default_rng(seed).permutation(len(candidates))
    ball = _move_to_front_ball([candidates[i] for i in order], len(candidates), [], points.shape[1])
    radius = float(np.sqrt(np.max(np.sum((points - ball.center) ** 2, axis=1))))
    return Ball(ball.center, radius)
