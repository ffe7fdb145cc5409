"""Estimates from a surviving cell set: guaranteed bounds, likelihood samples, expected pose, intervals.

Frames: cells hold ``base_T_fix`` (internal frame); everything returned is of the CAD frame
``base_T_cad = base_T_fix @ fix_T_cad``. ``fix_p_origin`` is the CAD origin in the internal frame.
"""

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp
from scipy.spatial.transform import Rotation

from fixwizard.fixture import DistanceOracle
from fixwizard.geometry.meb import minimum_enclosing_ball
from fixwizard.geometry.se3 import make_transform
from fixwizard.geometry.so3_grid import chord, rotation_angles
from fixwizard.solver.cells import CellSet
from fixwizard.solver.distance_grid import distance_grid_for

CENTER_ITERATIONS = 200
# Below this many effective samples, sample_cells draws a second, importance-weighted round.
MIN_EFFECTIVE_SAMPLES = 1000


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
    """Approximate minimax centre of a small set of rotations (signs aligned to their principal quaternion)."""
    quaternions = rotations.as_quat().reshape(-1, 4)
    principal = np.linalg.eigh(quaternions.T @ quaternions)[1][:, -1]
    aligned = quaternions * np.where(quaternions @ principal < 0, -1.0, 1.0)[:, None]
    center = principal.copy()
    for step in range(1, CENTER_ITERATIONS + 1):
        farthest = aligned[np.argmax(np.sum((aligned - center) ** 2, axis=1))]
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


def cell_bound_figures(cells: CellSet, centre: BoundCentre, fix_p_origin: np.ndarray,
                       fixture_radius_m: float) -> np.ndarray:
    """(3, N): for each cell, the largest CAD-origin distance (m), rotation angle (rad) and fixture-point
    displacement (m) between the centre and any pose in the cell."""
    base_R_fix, gammas = cells.distinct_rotation_matrices()
    rotation_index = cells.rotation_index
    positions = cells.positions_m()
    position_bound = cells.position_bound_m
    cad_origins = (base_R_fix @ fix_p_origin)[rotation_index] + positions
    origin_lever = float(np.linalg.norm(fix_p_origin))
    position = (np.linalg.norm(cad_origins - centre.cad_origin_m, axis=1) + position_bound
                + origin_lever * chord(gammas[rotation_index]))
    angles = np.minimum(rotation_angles(centre.rotation.as_matrix(), base_R_fix) + gammas, np.pi)
    center_fix = centre.cad_origin_m - centre.rotation.apply(fix_p_origin)
    displacement = (np.linalg.norm(positions - center_fix, axis=1) + position_bound
                    + fixture_radius_m * chord(angles[rotation_index]))
    return np.vstack([position, angles[rotation_index], displacement])


def bounds_from_figures(centre: BoundCentre, largest: np.ndarray) -> Bounds:
    """Bounds from the largest (CAD-origin distance, rotation angle, point displacement) over a set."""
    return Bounds(make_transform(centre.rotation, centre.cad_origin_m), float(largest[0]), float(largest[1]),
                  float(largest[2]))


def sample_cells(cells: CellSet, oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float,
                 sigma_m: float, max_samples: int, rng: np.random.Generator) -> Samples:
    """Poses inside the cells, weighted so that weighted sums estimate the likelihood-weighted posterior.

    Likelihood: independent Gaussians on the signed point-to-surface residual ``d(x_i) - r_ball``; all cells
    have equal volume, so the prior over cells is uniform. First one uniform pose in each of (at most
    ``max_samples`` randomly chosen) cells. When a few cells carry almost all the weight (effective sample
    size under ``MIN_EFFECTIVE_SAMPLES``, usual for coarse cells), a second round draws ``max_samples``
    poses from cells picked in proportion to a half-and-half mix of the first weights and uniform, weighted
    by likelihood over the picking probability (importance sampling), and replaces the first.
    """
    count = len(cells)
    chosen = np.arange(count) if count <= max_samples else np.sort(rng.choice(count, max_samples, replace=False))
    samples = _weighted_draws(cells, oracle, base_p_taps, ball_radius_m, sigma_m, chosen, np.zeros(len(chosen)),
                              rng)
    if effective_sample_size(samples.weights) >= MIN_EFFECTIVE_SAMPLES:
        return samples
    pick_probability = 0.5 * samples.weights + 0.5 / len(chosen)
    picks = rng.choice(len(chosen), max_samples, p=pick_probability / pick_probability.sum())
    return _weighted_draws(cells, oracle, base_p_taps, ball_radius_m, sigma_m, chosen[picks],
                           -np.log(pick_probability[picks]), rng)


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


def _weighted_draws(cells: CellSet, oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float,
                    sigma_m: float, cell_index: np.ndarray, log_weight_offset: np.ndarray,
                    rng: np.random.Generator) -> Samples:
    """One uniform pose in each listed cell (repeats allowed), weight = likelihood x exp(offset), normalised."""
    rotations = cells.rotation_grid.sample(cells.rotation_level, cells.rotation_cells[cell_index], rng)
    side = cells.position_grid.cell_side_m(cells.position_level)
    positions = cells.positions_m(cell_index) + (rng.random((len(cell_index), 3)) - 0.5) * side
    fix_R_base = rotations.inv()
    fix_p_taps = np.concatenate([fix_R_base.apply(tap - positions) for tap in base_p_taps])
    outside = distance_grid_for(oracle).interval_m(fix_p_taps)[0] > 0.0  # no inside test needed there
    residual = oracle.distance_and_face(fix_p_taps, ~outside)[0] - ball_radius_m
    log_weight = log_weight_offset - 0.5 * np.sum((residual.reshape(len(base_p_taps), -1) / sigma_m) ** 2, axis=0)
    weights = np.exp(log_weight - logsumexp(log_weight))
    return Samples(rotations, positions, cell_index, weights / weights.sum())


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
    angles = (Rotation.from_matrix(base_T_cad[:3, :3]).inv() * samples.rotations).magnitude()
    return [Interval(level, _weighted_quantile(distances, samples.weights, level),
                     _weighted_quantile(angles, samples.weights, level)) for level in levels]
