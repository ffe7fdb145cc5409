"""The farthest poses that satisfy every tap: certified lower bounds on how far the consistent set really reaches.

The guaranteed bounds are upper bounds on the set's extent (every pose within them); the *reach* is a lower
bound: the largest CAD-origin distance, rotation angle and fixture-point displacement from the bound centre of
poses that provably explain every tap (each tap's distance interval within ``r_ball +- b_s``: ``certified``).
The true extent lies between the two, so ``bound / reach`` measures how tight the bounds are, and no bound can
honestly be smaller than the reach.

Candidates come from pushing outward from feasible starts with a constrained optimiser (SLSQP), along each axis
and a few random directions, for each of the three figures; a candidate that ends a little outside the feasible
set is pulled back towards its start until it certifies.

Frames: poses are ``base_T_fix``; the figures are measured as ``estimates.cell_bound_figures`` measures them.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from fixwizard.geometry.hull_cover import HullCover
from fixwizard.geometry.se3 import make_transform, points_in_frames, rotation_angle_rad
from fixwizard.geometry.so3_grid import chord
from fixwizard.solver.estimates import BoundCentre
from fixwizard.solver.mode_mass import laplace_peak
from fixwizard.solver.search import SearchProblem

RANDOM_DIRECTIONS = 4
BACKOFF_STEPS = 12  # bisections towards the start for a candidate that does not certify
OPTIMISER_ITERATIONS = 60
DIFFERENCE_STEP_M = 1e-6
FEASIBLE_SHARE = 0.9  # a start is looked for with every tap within this share of the bound, so that it certifies


@dataclass(frozen=True)
class Reach:
    """Largest (CAD-origin distance m, rotation angle rad, point displacement m) from the bound centre over the
    certified poses found, and those poses ``base_T_fix``."""

    figures: np.ndarray
    poses: list[np.ndarray]


def certified(problem: SearchProblem, base_T_fix: np.ndarray) -> bool:
    """Whether a pose explains every tap for sure: each tap's distance interval within the ball radius plus or
    minus the sample bound."""
    fix_p_taps = points_in_frames(base_T_fix[:3, :3], base_T_fix[:3, 3], problem.base_p_taps)[0]
    low, high, _ = problem.oracle.distance_interval_m(fix_p_taps)
    return bool(np.all(low >= problem.ball_radius_m - problem.sample_bound_m)
                and np.all(high <= problem.ball_radius_m + problem.sample_bound_m))


def pose_figures(base_T_fix: np.ndarray, centre: BoundCentre, fix_p_origin: np.ndarray,
                 cover: HullCover) -> np.ndarray:
    """(CAD-origin distance m, rotation angle rad, largest displacement m of a fixture point) of a pose from the
    centre pose; the displacement is at least that of the cover's ball centres less their radii times the turn's
    chord (exact for a cover of the hull vertices themselves): a lower bound, as a reach must be."""
    base_R_fix = base_T_fix[:3, :3]
    origin = base_R_fix @ fix_p_origin + base_T_fix[:3, 3]
    centre_R = centre.rotation.as_matrix()
    centre_p_fix = centre.cad_origin_m - centre_R @ fix_p_origin
    angle = rotation_angle_rad(centre_R.T @ base_R_fix)
    displacement = (np.linalg.norm(cover.points_m @ (base_R_fix - centre_R).T + (base_T_fix[:3, 3] - centre_p_fix),
                                   axis=1) - cover.radii_m * chord(angle))
    return np.array([np.linalg.norm(origin - centre.cad_origin_m), angle, displacement.max()])


def _pose(start: np.ndarray, step: np.ndarray, radius_m: float) -> np.ndarray:
    rotation = Rotation.from_matrix(start[:3, :3]) * Rotation.from_rotvec(step[:3] / radius_m)
    return make_transform(rotation, start[:3, 3] + step[3:])


def _residuals_m(problem: SearchProblem, start: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Each tap's signed distance less the ball radius (m) at the start pose moved by each step (K, 6): (K, N)."""
    rotations = Rotation.from_matrix(start[:3, :3]) * Rotation.from_rotvec(steps[:, :3] / problem.fixture_radius_m)
    fix_p_taps = points_in_frames(rotations.as_matrix(), start[:3, 3] + steps[:, 3:], problem.base_p_taps)
    distances = problem.oracle.signed_distance_m(fix_p_taps.reshape(-1, 3))
    return distances.reshape(len(steps), -1) - problem.ball_radius_m


def _push(problem: SearchProblem, start: np.ndarray, objective: Callable[[np.ndarray], float], extent_m: float,
          bound_m: float | None = None) -> np.ndarray:
    """The pose that maximises ``objective(pose)`` subject to every tap within ``bound_m`` (default the sample
    bound), from ``start``."""
    radius = problem.fixture_radius_m
    bound = problem.sample_bound_m if bound_m is None else bound_m
    offsets = DIFFERENCE_STEP_M * np.vstack([np.zeros(6), np.eye(6)])

    def constraints(step: np.ndarray) -> np.ndarray:
        return bound**2 - _residuals_m(problem, start, step[None])[0] ** 2

    def constraint_jacobian(step: np.ndarray) -> np.ndarray:
        values = bound**2 - _residuals_m(problem, start, step + offsets) ** 2
        return ((values[1:] - values[0]) / DIFFERENCE_STEP_M).T

    def negative(step: np.ndarray) -> float:
        return -objective(_pose(start, step, radius))

    def negative_gradient(step: np.ndarray) -> np.ndarray:
        values = np.array([negative(step + offset) for offset in offsets])
        return (values[1:] - values[0]) / DIFFERENCE_STEP_M

    result = minimize(negative, np.zeros(6), jac=negative_gradient, method="SLSQP",
                      bounds=[(-extent_m, extent_m)] * 6,
                      constraints=[{"type": "ineq", "fun": constraints, "jac": constraint_jacobian}],
                      options={"maxiter": OPTIMISER_ITERATIONS, "ftol": 1e-12})
    return _pose(start, result.x, radius)


def _pulled_back(problem: SearchProblem, start: np.ndarray, end: np.ndarray) -> np.ndarray | None:
    """``end`` if it certifies, else the farthest certified pose found between a certified ``start`` and ``end``."""
    if certified(problem, end):
        return end
    radius = problem.fixture_radius_m
    step = np.concatenate([Rotation.from_matrix(start[:3, :3].T @ end[:3, :3]).as_rotvec() * radius,
                           end[:3, 3] - start[:3, 3]])
    low, high = 0.0, 1.0
    for _ in range(BACKOFF_STEPS):
        middle = 0.5 * (low + high)
        if certified(problem, _pose(start, middle * step, radius)):
            low = middle
        else:
            high = middle
    return _pose(start, low * step, radius) if low > 0.0 else None


def _objectives(centre: BoundCentre, fix_p_origin: np.ndarray, cover: HullCover,
                rng: np.random.Generator) -> list[Callable[..., float]]:
    """Functions of a pose to push outward: the CAD origin along directions, the rotation about axes, the
    farthest hull points along directions."""
    axes = np.vstack([np.eye(3), -np.eye(3)])
    random = rng.normal(size=(RANDOM_DIRECTIONS, 3))
    directions = np.vstack([axes, random / np.linalg.norm(random, axis=1, keepdims=True)])
    centre_R = centre.rotation.as_matrix()
    centre_p_fix = centre.cad_origin_m - centre_R @ fix_p_origin
    points = cover.points_m
    far = points[np.argsort(-np.linalg.norm(points - points.mean(axis=0), axis=1))[:2]]
    objectives: list[Callable[..., float]] = []
    for direction in directions:
        objectives.append(lambda pose, u=direction: float(u @ (pose[:3, :3] @ fix_p_origin + pose[:3, 3]
                                                                - centre.cad_origin_m)))
        objectives.append(lambda pose, u=direction: float(u @ Rotation.from_matrix(centre_R.T @ pose[:3, :3])
                                                          .as_rotvec()))
        for point in far:
            objectives.append(lambda pose, u=direction, p=point: float(
                u @ (pose[:3, :3] @ p + pose[:3, 3] - centre_R @ p - centre_p_fix)))
    return objectives


def _chebyshev_fit(problem: SearchProblem, start: np.ndarray, extent_m: float) -> np.ndarray:
    """The pose near ``start`` (within ``extent_m``) whose largest tap error ``|s(x_i) - r_ball|`` is least (a local
    optimum), by SLSQP on the step and that error: it reaches poses that explain every tap however little room the
    taps leave them (taps off by nearly the whole bound on both sides of a face leave poses with every error near
    it, and none within ``FEASIBLE_SHARE`` of it)."""
    offsets = DIFFERENCE_STEP_M * np.vstack([np.zeros(6), np.eye(6)])
    free = np.ones((len(problem.base_p_taps), 1))
    known: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def errors(step_and_error: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each tap's error over the sample bound at the step, and its Jacobian in the step (N, 6); the last step's
        kept, as SLSQP asks for both constraints' values and Jacobians there in turn."""
        key = step_and_error[:6].tobytes()
        if key not in known:
            values = _residuals_m(problem, start, step_and_error[:6] + offsets) / problem.sample_bound_m
            known.clear()
            known[key] = values[0], ((values[1:] - values[0]) / DIFFERENCE_STEP_M).T
        return known[key]

    constraints = [{"type": "ineq", "fun": lambda y: y[6] - errors(y)[0],
                    "jac": lambda y: np.hstack([-errors(y)[1], free])},
                   {"type": "ineq", "fun": lambda y: y[6] + errors(y)[0],
                    "jac": lambda y: np.hstack([errors(y)[1], free])}]
    worst = float(np.max(np.abs(errors(np.zeros(7))[0])))
    result = minimize(lambda y: y[6], np.append(np.zeros(6), worst), jac=lambda _: np.append(np.zeros(6), 1.0),
                      method="SLSQP", bounds=[(-extent_m, extent_m)] * 6 + [(0.0, None)], constraints=constraints,
                      options={"maxiter": OPTIMISER_ITERATIONS, "ftol": 1e-12})
    return _pose(start, result.x[:6], problem.fixture_radius_m)


def certified_start(problem: SearchProblem, starts: list[np.ndarray], extent_m: float) -> np.ndarray | None:
    """The first certified pose of ``starts`` (poses ``base_T_fix``), else of their nearest least-squares fits and
    the feasible poses pushed from them (within ``extent_m``, a bound on how far any pose of the set lies), else of
    the Chebyshev fits from those least-squares fits (``_chebyshev_fit``, slower: for taps that leave no pose with
    every error within ``FEASIBLE_SHARE`` of the bound); None when none certifies."""
    start = next((pose for pose in starts if certified(problem, pose)), None)
    if start is not None:
        return start
    fits = []
    for pose in starts:
        fitted = laplace_peak(problem.oracle, problem.base_p_taps, problem.ball_radius_m, problem.sample_bound_m / 3.0,
                              pose, problem.fixture_radius_m, extent_m).base_T_fix
        # a least-squares fit can leave one tap just outside the bound: look for any pose with every tap inside
        feasible = _push(problem, fitted, lambda _: 0.0, extent_m, FEASIBLE_SHARE * problem.sample_bound_m)
        for candidate in (fitted, feasible):
            if certified(problem, candidate):
                return candidate
        fits.append(fitted)
    return next((pose for pose in (_chebyshev_fit(problem, fitted, extent_m) for fitted in fits)
                 if certified(problem, pose)), None)


def reach(problem: SearchProblem, starts: list[np.ndarray], centre: BoundCentre, fix_p_origin: np.ndarray,
          cover: HullCover, extent_m: float, seed: int = 0) -> Reach | None:
    """The certified reach from ``certified_start`` of ``starts`` (poses ``base_T_fix``), pushed outward within
    ``extent_m`` (a bound on how far any pose of the set lies); None when no start certifies."""
    start = certified_start(problem, starts, extent_m)
    if start is None:
        return None
    poses = [start]
    for objective in _objectives(centre, fix_p_origin, cover, np.random.default_rng(seed)):
        found = _pulled_back(problem, start, _push(problem, start, objective, extent_m))
        if found is not None:
            poses.append(found)
    figures = np.max([pose_figures(pose, centre, fix_p_origin, cover) for pose in poses], axis=0)
    return Reach(figures, poses)
