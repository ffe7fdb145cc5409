"""Poses that explain every tap, found independently of the solver: its own float64 distances and an optimiser.

A pose ``base_T_cad`` explains tap ``p_i`` when ``|s(cad_T_base p_i) - r_ball| <= b_s``, ``s`` the signed distance to
the true solid's surface (negative inside; unsigned for an open surface). Nothing here uses fixwizard's distance
code or search: the distance is a brute force over every triangle (the plane where the foot falls inside the
triangle, else the nearest of its three edges), the sign the solid's winding number (van Oosterom and Strackee's
solid angles), and the poses come from scipy.optimize: a least-squares fit of the taps' errors from random starts,
then a Chebyshev fit (the least largest error: SLSQP on an epigraph variable), then pushes from each feasible pose as
far as the taps allow along random directions (a fixture point along a direction, a turn about an axis), the poses
most likely to lie outside a bound. A pose counts as feasible only when every error is within the bound less
``SLACK_M``, so that rounding here cannot call a pose feasible that is not.
"""

from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.optimize import least_squares, minimize
from scipy.spatial.transform import Rotation

SLACK_M = 1e-9
# The optimisers aim this far inside the bound (a fraction of it), so that their end points pass the check above.
AIM_FRACTION = 1e-3


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.sum(u * v, axis=-1)


def _closest_on_segments(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Closest points (M, 3) to points (M, 3) on segments from ``start`` to ``end`` (M, 3)."""
    edge = end - start
    length2 = _dot(edge, edge)
    with np.errstate(divide="ignore", invalid="ignore"):
        along = np.clip(np.where(length2 > 0, _dot(points - start, edge) / length2, 0.0), 0.0, 1.0)
    return start + along[..., None] * edge


@dataclass(frozen=True)
class Surface:
    """Triangles (F, 3, 3, m) with what every query needs: their normals (not unit), bounding balls and edges."""

    triangles: np.ndarray
    normals: np.ndarray
    centres: np.ndarray
    radii: np.ndarray

    @staticmethod
    def of(triangles: np.ndarray) -> "Surface":
        triangles = np.asarray(triangles, float)
        centres = triangles.mean(axis=1)
        return Surface(triangles, np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]),
                       centres, np.max(np.linalg.norm(triangles - centres[:, None], axis=-1), axis=1))


def closest_points(surface: Surface, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For points (N, 3): the distance (N,) to the nearest triangle of the surface, float64 brute force, the
    closest point (N, 3) and the index of its triangle (N,). A point's foot on a triangle's plane is the closest point
    when it falls inside the triangle; otherwise the closest point lies on one of its edges. Triangles whose bounding
    ball lies farther than some triangle's farthest point are left out."""
    to_centres = np.linalg.norm(points[:, None] - surface.centres[None], axis=-1)
    farthest = np.min(to_centres + surface.radii, axis=1)
    rows, faces = np.nonzero(to_centres - surface.radii <= farthest[:, None] * (1 + 1e-9) + 1e-12)
    p = points[rows]
    a, b, c = (surface.triangles[faces, k] for k in range(3))
    normal = surface.normals[faces]
    norm2 = _dot(normal, normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        foot = p - (_dot(p - a, normal) / norm2)[..., None] * normal
    inside = ((_dot(np.cross(b - a, foot - a), normal) >= 0) & (_dot(np.cross(c - b, foot - b), normal) >= 0)
              & (_dot(np.cross(a - c, foot - c), normal) >= 0) & (norm2 > 0))
    candidates = np.stack([np.where(inside[..., None], foot, np.inf), _closest_on_segments(p, a, b),
                           _closest_on_segments(p, b, c), _closest_on_segments(p, c, a)])  # (4, M, 3)
    distances = np.linalg.norm(p[None] - candidates, axis=-1)  # (4, M)
    which = np.argmin(distances, axis=0)
    pair_distances = distances[which, np.arange(len(rows))]
    order = np.lexsort((pair_distances, rows))  # by point, nearest first
    first = order[np.searchsorted(rows[order], np.arange(len(points)))]
    return pair_distances[first], candidates[which[first], first], faces[first]


def unsigned_distances_m(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (N,) from points (N, 3) to the nearest of the triangles (F, 3, 3) (``closest_points``)."""
    return closest_points(Surface.of(triangles), points)[0]


def winding_numbers(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Generalised winding number (N,) of a closed outward-wound surface about each point: 1 inside, 0 outside."""
    a, b, c = (triangles[None, :, k] - points[:, None, :] for k in range(3))
    la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
    numerator = _dot(a, np.cross(b, c))
    denominator = la * lb * lc + _dot(a, b) * lc + _dot(a, c) * lb + _dot(b, c) * la
    return np.sum(2.0 * np.arctan2(numerator, denominator), axis=1) / (4.0 * np.pi)


@dataclass(frozen=True)
class Taps:
    """Taps (N, 3, m, base frame) on a true solid: its triangles (CAD frame, m), whether it is closed (signed
    distances), the ball radius and the sample bound (m)."""

    surface: Surface
    signed: bool
    base_p_taps: np.ndarray
    ball_radius_m: float
    sample_bound_m: float
    vertices: np.ndarray = field(repr=False)

    @staticmethod
    def on(solid: trimesh.Trimesh, base_p_taps: np.ndarray, ball_radius_m: float, sample_bound_m: float) -> "Taps":
        signed = bool(solid.is_watertight and solid.is_winding_consistent and solid.volume > 0)
        return Taps(Surface.of(solid.triangles), signed, np.asarray(base_p_taps, float), ball_radius_m,
                    sample_bound_m, np.asarray(solid.vertices, float))

    def errors_and_gradients(self, base_T_cad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each tap's error ``s - r_ball`` (N,, m) at a pose, and the gradient (N, 3, CAD frame) of ``s`` at the tap:
        away from the closest point, outward; on the surface, the closest face's normal."""
        cad_p_taps = (self.base_p_taps - base_T_cad[:3, 3]) @ base_T_cad[:3, :3]
        distances, closest, faces = closest_points(self.surface, cad_p_taps)
        sign = (np.where(winding_numbers(self.surface.triangles, cad_p_taps) > 0.5, -1.0, 1.0) if self.signed
                else np.ones(len(distances)))
        on = distances < 1e-12
        away = np.where(on[:, None], self.surface.normals[faces], (cad_p_taps - closest) * sign[:, None])
        gradients = away / np.linalg.norm(away, axis=1, keepdims=True)
        return sign * distances - self.ball_radius_m, gradients

    def errors_m(self, base_T_cad: np.ndarray) -> np.ndarray:
        """Each tap's error ``s - r_ball`` (N,, m) at a pose."""
        return self.errors_and_gradients(base_T_cad)[0]

    def feasible(self, base_T_cad: np.ndarray) -> bool:
        """Whether the pose explains every tap within the sample bound less ``SLACK_M``."""
        return bool(np.max(np.abs(self.errors_m(base_T_cad))) <= self.sample_bound_m - SLACK_M)


def pose(reference: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``reference`` turned by the rotation vector ``x[:3]`` (base frame, about its origin) and moved by ``x[3:]``."""
    result = np.eye(4)
    result[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix() @ reference[:3, :3]
    result[:3, 3] = reference[:3, 3] + x[3:]
    return result


def _left_jacobian(rotvec: np.ndarray) -> np.ndarray:
    """SO(3)'s left Jacobian: ``exp(v + dv) = exp(J dv) exp(v)`` to first order."""
    angle = float(np.linalg.norm(rotvec))
    skew = np.array([[0.0, -rotvec[2], rotvec[1]], [rotvec[2], 0.0, -rotvec[0]], [-rotvec[1], rotvec[0], 0.0]])
    if angle < 1e-8:
        return np.eye(3) + skew / 2
    return (np.eye(3) + (1 - np.cos(angle)) / angle**2 * skew
            + (angle - np.sin(angle)) / angle**3 * skew @ skew)


def errors_and_jacobian(taps: Taps, reference: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The taps' errors (N,, m) at ``pose(reference, x)`` and their derivatives (N, 6) by ``x``."""
    moved = pose(reference, x)
    errors, cad_gradients = taps.errors_and_gradients(moved)
    gradients = cad_gradients @ moved[:3, :3].T  # base frame
    # s(R^T (p - t)): a turn dw of the pose about the base origin moves the tap by -dw x (p - t) in the fixture
    by_turn = -np.cross(taps.base_p_taps - moved[:3, 3], gradients)
    return errors, np.hstack([by_turn @ _left_jacobian(x[:3]), -gradients])


class _Evaluations:
    """``errors_and_jacobian`` about one start pose, remembering the last one (an optimiser asks for the values and
    their derivatives at the same point in two calls)."""

    def __init__(self, taps: Taps, start: np.ndarray) -> None:
        self.taps, self.start = taps, start
        self.x: np.ndarray | None = None
        self.last: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros((0, 6)))

    def __call__(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.x is None or not np.array_equal(x, self.x):
            self.x, self.last = np.array(x, float), errors_and_jacobian(self.taps, self.start, x)
        return self.last

    def two_sided(self, x: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
        """``width - e >= 0`` and ``width + e >= 0`` for every tap error ``e`` at ``x``, and their derivatives."""
        errors, jacobian = self(x)
        return np.concatenate([width - errors, width + errors]), np.vstack([-jacobian, jacobian])


def least_squares_fit(taps: Taps, start: np.ndarray) -> np.ndarray:
    evaluations = _Evaluations(taps, start)
    fit = least_squares(lambda x: evaluations(x)[0], np.zeros(6), jac=lambda x: evaluations(x)[1], max_nfev=60,
                        x_scale=np.r_[1.0, 1.0, 1.0, np.full(3, 0.05)])
    return pose(start, fit.x)


def chebyshev_fit(taps: Taps, start: np.ndarray) -> np.ndarray:
    """The pose near ``start`` whose largest tap error is least (SLSQP on ``min w s.t. |e_i| <= w``)."""
    evaluations = _Evaluations(taps, start)

    def jacobian(z: np.ndarray) -> np.ndarray:
        derivatives = evaluations.two_sided(z[:6], z[6])[1]
        return np.hstack([derivatives, np.ones((len(derivatives), 1))])

    worst = float(np.max(np.abs(taps.errors_m(start))))
    fit = minimize(lambda z: z[6], np.r_[np.zeros(6), worst], jac=lambda z: np.r_[np.zeros(6), 1.0],
                   method="SLSQP", constraints=[{"type": "ineq", "fun": lambda z: evaluations.two_sided(z[:6], z[6])[0],
                                                 "jac": jacobian}],
                   options={"maxiter": 60, "ftol": 1e-14})
    candidate = pose(start, fit.x[:6])
    return candidate if np.max(np.abs(taps.errors_m(candidate))) < worst else start


def fitted(taps: Taps, start: np.ndarray) -> np.ndarray:
    """A least-squares fit from ``start``, then a Chebyshev fit from there."""
    return chebyshev_fit(taps, least_squares_fit(taps, start))


def pushed(taps: Taps, start: np.ndarray, objective: "Objective") -> np.ndarray | None:
    """The feasible pose farthest from ``start`` (feasible) along ``objective`` that SLSQP finds, if it checks out."""
    aim = taps.sample_bound_m * (1.0 - AIM_FRACTION)
    evaluations = _Evaluations(taps, start)
    fit = minimize(lambda x: -objective(start, x), np.zeros(6), jac=lambda x: -objective.gradient(start, x),
                   method="SLSQP", constraints=[{"type": "ineq", "fun": lambda x: evaluations.two_sided(x, aim)[0],
                                                 "jac": lambda x: evaluations.two_sided(x, aim)[1]}],
                   options={"maxiter": 60, "ftol": 1e-14})
    candidate = pose(start, fit.x)
    return candidate if taps.feasible(candidate) else None


class Objective:
    """How far a pose reached along a random direction: a fixture point moved along a unit vector (m), or the turn
    about a unit axis (rad, scaled by the fixture's size so both are lengths)."""

    def __init__(self, rng: np.random.Generator, vertices: np.ndarray, size_m: float) -> None:
        self.direction = rng.normal(size=3)
        self.direction /= np.linalg.norm(self.direction)
        self.turn = bool(rng.random() < 0.4)
        self.point = vertices[rng.integers(len(vertices))] if rng.random() < 0.7 else vertices.mean(axis=0)
        self.size_m = size_m

    def __call__(self, start: np.ndarray, x: np.ndarray) -> float:
        if self.turn:
            return float(self.size_m * x[:3] @ self.direction)
        moved = pose(start, x)
        return float((moved[:3, :3] @ self.point + moved[:3, 3]) @ self.direction)

    def gradient(self, start: np.ndarray, x: np.ndarray) -> np.ndarray:
        if self.turn:
            return np.r_[self.size_m * self.direction, np.zeros(3)]
        arm = pose(start, x)[:3, :3] @ self.point  # the point about the base origin turns by dw x arm
        return np.r_[np.cross(arm, self.direction) @ _left_jacobian(x[:3]), self.direction]


def random_starts(taps: Taps, rng: np.random.Generator, count: int) -> list[np.ndarray]:
    """Random poses: uniform rotations, the CAD-frame centre of the vertices placed near the taps' centroid."""
    centre_cad = taps.vertices.mean(axis=0)
    spread = np.linalg.norm(np.ptp(taps.vertices, axis=0)) / 4
    starts = []
    for rotation in Rotation.random(count, random_state=rng.integers(2**31)).as_matrix():
        start = np.eye(4)
        start[:3, :3] = rotation
        start[:3, 3] = taps.base_p_taps.mean(axis=0) + rng.normal(scale=spread, size=3) - rotation @ centre_cad
        starts.append(start)
    return starts


def feasible_poses(taps: Taps, rng: np.random.Generator, known: list[np.ndarray], starts: int = 12,
                   pushes: int = 12) -> list[np.ndarray]:
    """Feasible poses: ``known`` ones that check out, fits from the others and from ``starts`` random poses that check
    out, and ``pushes`` pushes along random directions, each from one of those picked at random."""
    found = []
    for start in [*known, *random_starts(taps, rng, starts)]:
        if taps.feasible(start):
            found.append(start)
            continue
        candidate = fitted(taps, start)
        if taps.feasible(candidate):
            found.append(candidate)
    size_m = float(np.linalg.norm(np.ptp(taps.vertices, axis=0)))
    bases = list(found)
    for _ in range(pushes if bases else 0):
        candidate = pushed(taps, bases[rng.integers(len(bases))], Objective(rng, taps.vertices, size_m))
        if candidate is not None:
            found.append(candidate)
    return found


def rotation_angle_rad(first: np.ndarray, second: np.ndarray) -> float:
    return float(Rotation.from_matrix(first[:3, :3].T @ second[:3, :3]).magnitude())


def displacement_m(vertices: np.ndarray, first: np.ndarray, second: np.ndarray) -> float:
    """The largest distance (m) a CAD-frame vertex moves between two poses (the largest over the solid: the
    displacement is convex in the point, so largest at a vertex of the hull)."""
    return float(np.max(np.linalg.norm(vertices @ (first[:3, :3] - second[:3, :3]).T + first[:3, 3]
                                       - second[:3, 3], axis=1)))
