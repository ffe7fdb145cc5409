"""Estimates from a surviving cell set: guaranteed bounds, likelihood samples, expected pose, intervals.

Frames: cells hold ``base_T_fix`` (internal frame); everything returned is of the CAD frame
``base_T_cad = base_T_fix @ fix_T_cad``. ``fix_p_origin`` is the CAD origin in the internal frame.
"""

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np
from scipy.spatial.transform import Rotation
from scipy.special import gammaln, logsumexp

from fixwizard.fixture import DistanceOracle
from fixwizard.geometry.hull_cover import HullCover
from fixwizard.geometry.meb import minimum_enclosing_ball
from fixwizard.geometry.se3 import make_transform, points_in_frames, rotation_angle_rad
from fixwizard.geometry.so3_grid import chord
from fixwizard.parallel import PARALLEL_KERNEL_LOCK
from fixwizard.solver.cells import CellSet
from fixwizard.solver.distance_grid import distance_grid_for
from fixwizard.solver.search import SearchCancelled

CENTER_ITERATIONS = 200
# Below this many effective samples, sample_cells draws a second, importance-weighted round, then a third.
MIN_EFFECTIVE_SAMPLES = 1000
# The first two rounds only find where the likelihood lies (on the four real runs their effective sample sizes are
# 16-528 of 40 000 draws, and the fitted round that follows reaches 10 000-14 000): they draw max_samples / SCOUTING
# poses; a first round whose effective size would reach MIN_EFFECTIVE_SAMPLES at full size is drawn at full size.
SCOUTING = 4
# Then rounds of a share of draws from a Student-t fitted to the previous round's weighted samples (wider by
# PROPOSAL_INFLATION in scale, and never narrower per coordinate than a cell's own spread scaled by the previous
# effective sample size), the rest uniform over the cells so that no part of the set goes unsampled; up to
# FITTED_ROUNDS of them while they gain.
NIL_SIGMAS = 10.0
QUERY_POINTS = 2_000_000  # tap points per distance query: bounded memory for any number of taps
PROPOSAL_SHARE = 0.8
PROPOSAL_DOF = 5.0
PROPOSAL_INFLATION = 1.5
FITTED_ROUNDS = 4


@dataclass(frozen=True)
class Bounds:
    """Guaranteed bounds around a centre pose: every pose of the set lies within them.

    ``position_m``: distance of the CAD origin; ``rotation_rad``: rotation angle;
    ``max_point_displacement_m``: displacement of any fixture point between the centre pose and any pose.
    """

    base_T_cad_center: np.ndarray
    position_m: float
    rotation_rad: float
    max_point_displacement_m: float


@dataclass(frozen=True)
class Interval:
    """Radii around the expected pose holding ``level`` of the probability mass."""

    level: float
    position_m: float
    rotation_rad: float


@dataclass(frozen=True)
class Samples:
    """Stratified pose samples (one per sampled cell) with normalised weights (float64, sum 1)."""

    rotations: Rotation
    positions_m: np.ndarray
    cell_index: np.ndarray
    weights: np.ndarray


def rotation_center(rotations: Rotation) -> Rotation:
    """Approximate minimax centre of a small set of rotations (signs aligned to their principal quaternion): steps
    towards the farthest unit quaternion, the one least aligned with the centre."""
    quaternions = rotations.as_quat().reshape(-1, 4)
    principal = np.linalg.eigh(quaternions.T @ quaternions)[1][:, -1]
    aligned = quaternions * np.where(quaternions @ principal < 0, -1.0, 1.0)[:, None]
    center = principal.copy()
    for step in range(1, CENTER_ITERATIONS + 1):
        farthest = aligned[np.argmin(aligned @ center)]
        center += (farthest - center) / (step + 1)
    return Rotation.from_quat(center / np.linalg.norm(center))


@dataclass(frozen=True)
class BoundCentre:
    """The pose bounds are measured from: ``rotation`` and the CAD origin ``cad_origin_m`` (base frame, m)."""

    rotation: Rotation
    cad_origin_m: np.ndarray


def bound_centre(cells: CellSet, fix_p_origin: np.ndarray, rotation_centre: Rotation) -> BoundCentre:
    """Centre from a rotation and the minimum enclosing ball of the cells' CAD origins."""
    rotations, _, rotation_index = cells.distinct_rotations()
    cad_origins = rotations.apply(fix_p_origin).reshape(-1, 3)[rotation_index] + cells.positions_m()
    return BoundCentre(rotation_centre, minimum_enclosing_ball(cad_origins).center)


# Cells whose ball bound lies below this fraction of the largest displacement found keep the ball bound: they do
# not set the maximum, and refinement (which splits cells near the maximum as it shrinks round after round) never
# comes down to them. At 0.75 refinement chose worse cells on the real runs; at 0.5 the bounds are those of
# computing every cell.
HULL_SCREEN_FRACTION = 0.5


HULL_BLOCK_CELLS = 2048  # cells per round of the parallel hull bounds, between updates of the largest one


@numba.njit(nogil=True, cache=True, inline="always")
def _hull_displacement_m(cell: int, base_R_fix: np.ndarray, rotation_index: np.ndarray, positions_m: np.ndarray,
                         centre_R: np.ndarray, centre_p_m: np.ndarray, cover: tuple[np.ndarray, np.ndarray],
                         norms: np.ndarray, chords: np.ndarray, turn_chords: np.ndarray) -> float:
    """``max_u |(R_c - C) u + t_c - t_C| + |u| chord + e_u turn_chord`` over the cover's balls ``(u, e_u)`` for one
    cell (m): ``chord`` of the cell's gamma, ``turn_chord`` of the largest angle between the centre's rotation and
    the cell's."""
    fix_p_cover, radii = cover
    rotation = base_R_fix[rotation_index[cell]]
    lever = rotation - centre_R
    offset = positions_m[cell] - centre_p_m
    chord_cell = chords[rotation_index[cell]]
    turn_chord = turn_chords[rotation_index[cell]]
    best = 0.0
    for vertex in range(len(fix_p_cover)):
        total = 0.0
        for axis in range(3):
            value = offset[axis]
            for k in range(3):
                value += lever[axis, k] * fix_p_cover[vertex, k]
            total += value * value
        best = max(best, math.sqrt(total) + norms[vertex] * chord_cell + radii[vertex] * turn_chord)
    return best


@numba.njit(nogil=True, cache=True, parallel=True)
def _hull_displacements_m(base_R_fix: np.ndarray, rotation_index: np.ndarray, positions_m: np.ndarray,
                          centre_R: np.ndarray, centre_p_m: np.ndarray, cover: tuple[np.ndarray, np.ndarray],
                          chords: np.ndarray, turn_chords: np.ndarray, ball_m: np.ndarray,
                          order: np.ndarray) -> np.ndarray:
    """For each cell (centre rotation ``base_R_fix[rotation_index]``, position), an upper bound (m) on the largest
    displacement of a fixture point between the centre pose and any pose of the cell: the smaller of its ball
    bound ``ball_m`` and ``_hull_displacement_m`` over the hull cover (the displacement is convex in the point,
    so the hull's vertices hold its maximum over the fixture, and each lies in a ball of the cover). That bound
    is computed in ``order`` (largest ball bound first), in rounds of ``HULL_BLOCK_CELLS`` spread over the cores,
    for the cells whose ball bound reaches ``HULL_SCREEN_FRACTION`` of the largest bound of the rounds before,
    and no more once a round starts below it (those cells keep their ball bound)."""
    out = ball_m.copy()
    norms = np.sqrt(np.sum(cover[0]**2, axis=1))
    largest = 0.0
    start = 0
    while start < len(order) and ball_m[order[start]] >= HULL_SCREEN_FRACTION * largest:
        stop = min(start + HULL_BLOCK_CELLS, len(order))
        screen = HULL_SCREEN_FRACTION * largest
        for position in numba.prange(start, stop):
            cell = order[position]
            if ball_m[cell] >= screen:
                best = _hull_displacement_m(cell, base_R_fix, rotation_index, positions_m, centre_R, centre_p_m,
                                            cover, norms, chords, turn_chords)
                out[cell] = min(ball_m[cell], best * (1.0 + 1e-12))
        for position in range(start, stop):
            largest = max(largest, out[order[position]])
        start = stop
    return out


def cell_bound_figures(cells: CellSet, centre: BoundCentre, fix_p_origin: np.ndarray,
                       cover: HullCover) -> np.ndarray:
    """(3, N): for each cell, the largest CAD-origin distance (m), rotation angle (rad) and fixture-point
    displacement (m) between the centre and any pose in the cell. ``cover``: balls covering the fixture's convex
    hull vertices (m, internal frame); the displacement is the smaller of the hull bound and the fixture ball's
    (``|t_c - t_C| + r chord(angle)``), both upper bounds."""
    base_R_fix, gammas = cells.distinct_rotation_matrices()
    rotation_index = cells.rotation_index
    positions = cells.positions_m()
    position_bound = cells.position_bound_m
    cad_origins = (base_R_fix @ fix_p_origin)[rotation_index] + positions
    origin_lever = float(np.linalg.norm(fix_p_origin))
    position = (np.linalg.norm(cad_origins - centre.cad_origin_m, axis=1) + position_bound
                + origin_lever * chord(gammas[rotation_index]))
    angles = np.minimum(rotation_angle_rad(centre.rotation.as_matrix().T @ base_R_fix) + gammas, np.pi)
    center_fix = centre.cad_origin_m - centre.rotation.apply(fix_p_origin)
    ball = (np.linalg.norm(positions - center_fix, axis=1) + cover.radius_m * chord(angles[rotation_index]))
    with PARALLEL_KERNEL_LOCK:
        displacement = _hull_displacements_m(np.ascontiguousarray(base_R_fix), rotation_index,
                                             np.ascontiguousarray(positions), centre.rotation.as_matrix(), center_fix,
                                             (np.ascontiguousarray(cover.points_m, float),
                                              np.ascontiguousarray(cover.radii_m, float)),
                                             chord(gammas), chord(angles), ball, np.argsort(-ball))
    return np.vstack([position, angles[rotation_index], displacement + position_bound])


def bounds_from_figures(centre: BoundCentre, largest: np.ndarray) -> Bounds:
    """Bounds from the largest (CAD-origin distance, rotation angle, point displacement) over a set."""
    return Bounds(make_transform(centre.rotation, centre.cad_origin_m), float(largest[0]), float(largest[1]),
                  float(largest[2]))


def sample_cells(cells: CellSet, oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float,
                 sigma_m: float, max_samples: int, rng: np.random.Generator, radius_m: float = 0.1,
                 cancel: threading.Event | None = None) -> Samples:
    """Poses inside the cells, weighted so that weighted sums estimate the likelihood-weighted posterior.

    Likelihood: independent Gaussians on the signed point-to-surface residual ``d(x_i) - r_ball``; all cells
    have equal volume, so the prior over cells is uniform. First one uniform pose in each of (at most
    ``max_samples`` randomly chosen) cells. When a few cells carry almost all the weight (effective sample
    size under ``MIN_EFFECTIVE_SAMPLES``, usual for coarse cells), a second round draws poses from cells picked
    in proportion to a half-and-half mix of the first weights and uniform, weighted by likelihood over the
    picking probability (importance sampling), and replaces the first. Both rounds draw a ``SCOUTING`` share of
    ``max_samples`` unless that share already shows a full round would do (``_scouted``). When the
    likelihood is still narrower than the cells, rounds of ``max_samples`` drawn from a Student-t fitted to the
    round before
    (``_fitted_round``, each fitted to the one before; ``radius_m`` the fixture radius that scales rotations to
    lengths): the round with the largest effective sample size is kept. Raises ``SearchCancelled`` before a
    round once ``cancel`` is set.
    """
    def go_on() -> None:
        if cancel is not None and cancel.is_set():
            raise SearchCancelled

    def uniform_round(draws: int) -> tuple[Samples, np.ndarray]:
        go_on()
        chosen = np.arange(len(cells)) if len(cells) <= draws else np.sort(rng.choice(len(cells), draws, replace=False))
        return _weighted_draws(cells, oracle, base_p_taps, ball_radius_m, sigma_m, chosen, np.zeros(len(chosen)),
                               rng), chosen

    samples, chosen = _scouted(uniform_round, max_samples)
    if effective_sample_size(samples.weights) >= MIN_EFFECTIVE_SAMPLES:
        return samples
    pick_probability = 0.5 * samples.weights + 0.5 / len(chosen)

    def importance_round(draws: int) -> tuple[Samples, np.ndarray]:
        go_on()
        picks = rng.choice(len(chosen), draws, p=pick_probability / pick_probability.sum())
        return _weighted_draws(cells, oracle, base_p_taps, ball_radius_m, sigma_m, chosen[picks],
                               -np.log(pick_probability[picks]), rng), picks

    samples, _ = _scouted(importance_round, max_samples)
    fitted = samples
    for _ in range(FITTED_ROUNDS):
        if effective_sample_size(samples.weights) >= MIN_EFFECTIVE_SAMPLES:
            break
        go_on()
        fitted = _fitted_round(cells, oracle, base_p_taps, ball_radius_m, sigma_m, fitted, max_samples, rng, radius_m)
        if effective_sample_size(fitted.weights) > effective_sample_size(samples.weights):
            samples = fitted
    return samples


def _scouted(draw: Callable[[int], tuple[Samples, np.ndarray]], max_samples: int) -> tuple[Samples, np.ndarray]:
    """A round of ``max_samples / SCOUTING`` draws, drawn again with ``max_samples`` when the effective sample size
    that many would give (it grows with the draws) reaches ``MIN_EFFECTIVE_SAMPLES``; ``draw(n)`` returns the
    samples of ``n`` draws (fewer when fewer cells exist) and what was drawn from."""
    scouts = max(1, max_samples // SCOUTING)
    samples, drawn = draw(scouts)
    if len(drawn) < scouts or effective_sample_size(samples.weights) * SCOUTING < MIN_EFFECTIVE_SAMPLES:
        return samples, drawn
    return draw(max_samples)


def _uniform_poses(cells: CellSet, cell_index: np.ndarray, rng: np.random.Generator) -> tuple[Rotation, np.ndarray]:
    """One uniform pose (Haar measure times volume) in each listed cell."""
    rotations = cells.rotation_grid.sample(cells.rotation_level, cells.rotation_cells[cell_index], rng)
    side = cells.position_grid.cell_side_m(cells.position_level)
    return rotations, cells.positions_m(cell_index) + (rng.random((len(cell_index), 3)) - 0.5) * side


def _log_likelihood(oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float, sigma_m: float,
                    rotations: Rotation, positions_m: np.ndarray) -> np.ndarray:
    """Log-likelihood (up to a constant) of each pose ``base_T_fix``: Gaussian residuals of every tap; poses in
    batches of at most ``QUERY_POINTS`` tap points."""
    matrices = rotations.as_matrix().reshape(-1, 3, 3)
    batch = max(1, QUERY_POINTS // len(base_p_taps))
    log_likelihood = np.empty(len(matrices))
    for first in range(0, len(matrices), batch):
        rows = slice(first, first + batch)
        fix_p_taps = points_in_frames(matrices[rows], positions_m[rows], base_p_taps).reshape(-1, 3)
        outside = distance_grid_for(oracle).interval_m(fix_p_taps)[0] > 0.0  # no inside test needed there
        # a tap this many sigmas off zeroes the weight (exp(-50)): farther distances need not be known
        residual = oracle.signed_distance_m(fix_p_taps, ~outside, ball_radius_m + NIL_SIGMAS * sigma_m) - ball_radius_m
        log_likelihood[rows] = -0.5 * np.sum((residual.reshape(-1, len(base_p_taps)) / sigma_m) ** 2, axis=1)
    return log_likelihood


def _normalised(log_weight: np.ndarray) -> np.ndarray:
    weights = np.exp(log_weight - logsumexp(log_weight))
    return weights / weights.sum()


def _weighted_draws(cells: CellSet, oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float,
                    sigma_m: float, cell_index: np.ndarray, log_weight_offset: np.ndarray,
                    rng: np.random.Generator) -> Samples:
    """One uniform pose in each listed cell (repeats allowed), weight = likelihood x exp(offset), normalised."""
    rotations, positions = _uniform_poses(cells, cell_index, rng)
    log_weight = log_weight_offset + _log_likelihood(oracle, base_p_taps, ball_radius_m, sigma_m, rotations,
                                                     positions)
    return Samples(rotations, positions, cell_index, _normalised(log_weight))


def _haar_jacobian(rotvec_rad: np.ndarray) -> np.ndarray:
    """Density of the Haar measure (total 8 pi^2) in rotation-vector coordinates: 2 (1 - cos a) / a^2."""
    angle = np.linalg.norm(rotvec_rad, axis=1)
    small = angle < 1e-4
    safe = np.where(small, 1.0, angle)
    return np.where(small, 1.0 - angle**2 / 12.0, 2.0 * (1.0 - np.cos(safe)) / safe**2)


def _fitted_round(cells: CellSet, oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float,
                  sigma_m: float, previous: Samples, count: int, rng: np.random.Generator,
                  radius_m: float) -> Samples:
    """``count`` poses by defensive importance sampling: ``PROPOSAL_SHARE`` from a multivariate Student-t in
    the coordinates ``y = (omega * radius_m, p - p0)`` (m) about the weighted mean pose ``(R0, p0)`` of the
    previous samples, ``R = R0 exp(omega)``, fitted to their weighted covariance; the rest uniform over the cells.
    Weights are the likelihood over the mixture's density (both with respect to the Haar measure times volume),
    zero outside the cells."""
    mean_quaternion = np.linalg.eigh((previous.rotations.as_quat() * previous.weights[:, None]).T
                                     @ previous.rotations.as_quat())[1][:, -1]
    centre = Rotation.from_quat(mean_quaternion)
    centre_p = previous.weights @ previous.positions_m

    def coordinates(rotations: Rotation, positions: np.ndarray) -> np.ndarray:
        return np.hstack([(centre.inv() * rotations).as_rotvec() * radius_m, positions - centre_p])

    known = coordinates(previous.rotations, previous.positions_m)
    mean = previous.weights @ known
    offsets = known - mean
    # a cell's own spread (uniform over its side; its rotation radius gamma as a length), shrunk as the previous
    # round's samples grow many enough to tell the shape of the likelihood
    gamma = float(np.max(cells.rotation_grid.gamma(cells.rotation_level, cells.rotation_ids)))
    side = cells.position_grid.cell_side_m(cells.position_level)
    cell_variance = np.array([(gamma * radius_m) ** 2 / 3.0] * 3 + [side**2 / 12.0] * 3)
    covariance = (PROPOSAL_INFLATION**2 * (offsets * previous.weights[:, None]).T @ offsets
                  + np.diag(cell_variance) / effective_sample_size(previous.weights))
    factor = np.linalg.cholesky(covariance)
    fitted_count = int(round(PROPOSAL_SHARE * count))
    scale = np.sqrt(rng.chisquare(PROPOSAL_DOF, fitted_count) / PROPOSAL_DOF)
    drawn = mean + (rng.standard_normal((fitted_count, 6)) @ factor.T) / scale[:, None]
    drawn_rotations = centre * Rotation.from_rotvec(drawn[:, :3] / radius_m)
    uniform_index = rng.integers(0, len(cells), count - fitted_count)
    uniform_rotations, uniform_positions = _uniform_poses(cells, uniform_index, rng)
    rotations = Rotation.concatenate([drawn_rotations, uniform_rotations])
    positions = np.vstack([centre_p + drawn[:, 3:], uniform_positions])
    y = coordinates(rotations, positions)
    cell_index = cells.locate(rotations, positions)
    cell_index[:fitted_count][np.linalg.norm(drawn[:, :3], axis=1) / radius_m >= np.pi] = -1  # outside the chart
    inside = np.flatnonzero(cell_index >= 0)
    # densities with respect to the Haar measure (rad^3, total 8 pi^2) times volume (m^3)
    solved = np.linalg.solve(factor, (y[inside] - mean).T)
    log_t = (-0.5 * (PROPOSAL_DOF + 6.0) * np.log1p(np.sum(solved**2, axis=0) / PROPOSAL_DOF)
             - np.sum(np.log(np.diag(factor))) + _t_log_normaliser(PROPOSAL_DOF, 6))
    log_t += 3.0 * np.log(radius_m) - np.log(_haar_jacobian(y[inside, :3] / radius_m))
    cell_volume = (8.0 * np.pi**2 / cells.rotation_grid.n_cells(cells.rotation_level)
                   * cells.position_grid.cell_side_m(cells.position_level) ** 3)
    log_uniform = np.full(len(inside), -np.log(len(cells) * cell_volume))
    log_proposal = np.logaddexp(np.log(PROPOSAL_SHARE) + log_t, np.log1p(-PROPOSAL_SHARE) + log_uniform)
    log_weight = np.full(len(positions), -np.inf)
    log_weight[inside] = _log_likelihood(oracle, base_p_taps, ball_radius_m, sigma_m, rotations[inside],
                                         positions[inside]) - log_proposal
    kept = np.flatnonzero(np.isfinite(log_weight))
    return Samples(rotations[kept], positions[kept], cell_index[kept], _normalised(log_weight[kept]))


def _t_log_normaliser(dof: float, dimension: int) -> float:
    """Log of the multivariate Student-t density's constant for an identity scale."""
    return float(gammaln(0.5 * (dof + dimension)) - gammaln(0.5 * dof) - 0.5 * dimension * np.log(dof * np.pi))


def mixture(parts: list[tuple[Samples, np.ndarray]], shares: np.ndarray) -> Samples:
    """One sample set from several (each with the indices of its cells in the whole set), part ``k``
    holding ``shares[k]`` of the weight."""
    return Samples(Rotation.concatenate([samples.rotations for samples, _ in parts]),
                   np.vstack([samples.positions_m for samples, _ in parts]),
                   np.concatenate([cells[samples.cell_index] for samples, cells in parts]),
                   np.concatenate([share * samples.weights for (samples, _), share in zip(parts, shares, strict=True)]))


def effective_sample_size(weights: np.ndarray) -> float:
    """Kish's effective number of samples of normalised weights: 1 / sum(w^2)."""
    return float(1.0 / np.sum(weights ** 2))


def expected_pose(samples: Samples, mask: np.ndarray, fix_T_cad: np.ndarray) -> np.ndarray:
    """Probability-weighted mean ``base_T_cad`` of the masked samples (quaternion mean by eigenvector)."""
    weights = samples.weights[mask] / samples.weights[mask].sum()
    position = weights @ samples.positions_m[mask]
    quaternions = samples.rotations[np.flatnonzero(mask)].as_quat()
    mean_quaternion = np.linalg.eigh((quaternions * weights[:, None]).T @ quaternions)[1][:, -1]
    return make_transform(Rotation.from_quat(mean_quaternion), position) @ fix_T_cad


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, level: float) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][min(np.searchsorted(cumulative, level * cumulative[-1]), len(values) - 1)])


def intervals(samples: Samples, base_T_cad: np.ndarray, fix_p_origin: np.ndarray,
              levels: tuple[float, ...] = (0.95, 0.99)) -> list[Interval]:
    """Radii about ``base_T_cad`` (CAD origin distance, rotation angle) holding each level of the mass."""
    cad_origins = samples.rotations.apply(fix_p_origin) + samples.positions_m
    distances = np.linalg.norm(cad_origins - base_T_cad[:3, 3], axis=1)
    angles = rotation_angle_rad(base_T_cad[:3, :3].T @ samples.rotations.as_matrix())
    return [Interval(level, _weighted_quantile(distances, samples.weights, level),
                     _weighted_quantile(angles, samples.weights, level)) for level in levels]
