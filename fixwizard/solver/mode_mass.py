"""Each mode's share of the likelihood mass, by Laplace's approximation about the mode's likelihood peak.

Why not from the cell samples: the likelihood (sigma = a third of the sample bound) is narrower than a cell,
so a mode's sampled mass is set by the one sample that landed nearest its peak. Symmetric modes then come out
as 100 / 0 / 0 / 0 instead of equal shares. Laplace's approximation integrates the peak itself: equal
likelihoods give equal masses. Finding the peak is a local search; on a symmetric fixture the best mode's peak,
carried over by the fixture's own symmetry (``fixture_symmetry``), is a start in each other mode.

Frames and units: poses are ``base_T_fix`` (rotation ``base_R_fix``, position ``base_p_fix`` in m). The pose
is perturbed as ``base_R_fix * exp(omega)``, ``base_p_fix + delta`` with the 6-vector ``(omega * radius,
delta)`` in m, so that both halves move fixture points by about their own length.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.optimize import OptimizeResult, least_squares
from scipy.spatial.transform import Rotation

from fixwizard.fixture import DistanceOracle, Fixture
from fixwizard.geometry.se3 import invert, make_transform, points_in_frames
from fixwizard.solver.cells import CellSet
from fixwizard.solver.estimates import Samples

# Finite-difference step of the Jacobian (m): far above float32 rounding of the distance queries (~1e-8 m),
# far below the sample bound.
DIFFERENCE_STEP_M = 1e-5
# Residuals (in sigmas, or tolerances) beyond which the first, robust fit stops pulling quadratically.
ROBUST_SCALE = 3.0
MASS_STARTS = 24
MIN_STARTS_PER_MODE = 2
MAX_STARTS_PER_MODE = 8
# Residual evaluations per fit of a rough share: most fits end within it; a coarse mode's robust fit can take 600
ROUGH_FIT_EVALUATIONS = 60
SYMMETRY_POINTS = 100  # surface points a symmetry of the fixture must carry onto the surface
CARRY_WITHIN = 0.1  # a mode whose own peak is this close to the best one's (in log mass) keeps it


def _residuals(oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float, sigma_m: float,
               base_R_fix: Rotation, base_p_fix: np.ndarray, radius_m: float, steps: np.ndarray,
               signed: bool = True) -> np.ndarray:
    """Tap residuals ``(d(x_i) - r_ball) / sigma`` (K, N) at the pose perturbed by each of ``steps`` (K, 6), in
    one distance query (``signed``: negative inside a closed mesh)."""
    rotations = base_R_fix * Rotation.from_rotvec(steps[:, :3] / radius_m)
    fix_p_taps = points_in_frames(rotations.as_matrix(), base_p_fix + steps[:, 3:], base_p_taps).reshape(-1, 3)
    distances = oracle.signed_distance_m(fix_p_taps, np.full(len(fix_p_taps), signed))
    return (distances.reshape(len(steps), len(base_p_taps)) - ball_radius_m) / sigma_m


@dataclass(frozen=True)
class Peak:
    """A likelihood peak: the log of the likelihood integrated about it (up to a constant shared by all
    modes) and its pose ``base_T_fix``."""

    log_mass: float
    base_T_fix: np.ndarray


def _fit(residuals: Callable[[np.ndarray], np.ndarray], batch: Callable[[np.ndarray], np.ndarray],
         extent_m: float, robust: bool, max_evaluations: int | None = None) -> OptimizeResult:
    """Least squares over a 6-vector step within ``extent_m``; ``batch`` gives the residuals at several steps
    (K, 6) in one query, for the central-difference Jacobian (least_squares' own steps are relative to x,
    which is small here). ``robust``: a soft-L1 fit first, so that a point held on the wrong face does not pin
    the fit. ``max_evaluations``: of the residuals per fit (None: least_squares' own limit)."""
    offsets = DIFFERENCE_STEP_M * np.vstack([np.eye(6), -np.eye(6)])

    def jacobian(step: np.ndarray) -> np.ndarray:
        shifted = batch(step + offsets)
        return (shifted[:6] - shifted[6:]).T / (2.0 * DIFFERENCE_STEP_M)

    options = {"jac": jacobian, "bounds": (-extent_m, extent_m), "x_scale": extent_m, "max_nfev": max_evaluations}
    start = np.zeros(6)
    if robust:
        start = least_squares(residuals, start, loss="soft_l1", f_scale=ROBUST_SCALE, **options).x
    return least_squares(residuals, start, **options)


def _perturbed(base_T_fix: np.ndarray, step: np.ndarray, radius_m: float) -> np.ndarray:
    rotation = Rotation.from_matrix(base_T_fix[:3, :3]) * Rotation.from_rotvec(step[:3] / radius_m)
    return make_transform(rotation, base_T_fix[:3, 3] + step[3:])


def laplace_peak(oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float, sigma_m: float,
                 base_T_fix: np.ndarray, radius_m: float, extent_m: float, max_evaluations: int | None = None) -> Peak:
    """The likelihood peak nearest a pose, within ``extent_m`` (the mode's largest point displacement) of it.

    Its mass is ``exp(-chi2 / 2) / sqrt(det H)`` with the Gauss-Newton Hessian ``H = J^T J``. ``H`` gains
    ``1 / extent_m^2`` on its diagonal: directions the taps leave free are limited by the mode's extent instead
    of making the integral infinite. ``max_evaluations``: as for ``_fit`` (a peak not reached is a lesser mass).
    """
    base_R_fix = Rotation.from_matrix(base_T_fix[:3, :3])

    def batch(steps: np.ndarray) -> np.ndarray:
        return _residuals(oracle, base_p_taps, ball_radius_m, sigma_m, base_R_fix, base_T_fix[:3, 3], radius_m,
                          steps)

    extent_m = max(extent_m, DIFFERENCE_STEP_M * 10.0)
    fit = _fit(lambda step: batch(step[None])[0], batch, extent_m, robust=True, max_evaluations=max_evaluations)
    hessian = fit.jac.T @ fit.jac + np.eye(6) / extent_m ** 2
    return Peak(float(-0.5 * np.sum(fit.fun ** 2) - 0.5 * np.linalg.slogdet(hessian)[1]),
                _perturbed(base_T_fix, fit.x, radius_m))


def mode_peak(oracle: DistanceOracle, base_p_taps: np.ndarray, ball_radius_m: float, sigma_m: float,
              base_T_fix_starts: np.ndarray, radius_m: float, extent_m: float) -> Peak:
    """A mode's peak: the one of largest mass among the peaks nearest its poses ``base_T_fix_starts``
    (K, 4, 4).

    A mode's likelihood can have several peaks (a tap near an edge can sit on either face); which one a
    single start finds is luck, and symmetric modes would then get unequal masses.
    """
    return max((laplace_peak(oracle, base_p_taps, ball_radius_m, sigma_m, start, radius_m, extent_m)
                for start in base_T_fix_starts), key=lambda peak: peak.log_mass)


def fixture_symmetry(oracle: DistanceOracle, fix_p_surface: np.ndarray, fix_T_fix_guess: np.ndarray,
                     radius_m: float, tolerance_m: float) -> np.ndarray | None:
    """The rigid motion ``fix_T_fix`` nearest the guess that maps the fixture surface onto itself (every
    point of ``fix_p_surface`` (N, 3, m) ends within ``tolerance_m`` of the surface), or None."""
    guess_R = Rotation.from_matrix(fix_T_fix_guess[:3, :3])

    def batch(steps: np.ndarray) -> np.ndarray:
        """Distances (in tolerances) of the surface points moved back by the motion."""
        return _residuals(oracle, fix_p_surface, 0.0, tolerance_m, guess_R, fix_T_fix_guess[:3, 3], radius_m,
                          steps, signed=False)

    fit = _fit(lambda step: batch(step[None])[0], batch, radius_m, robust=True)
    if np.max(np.abs(fit.fun)) > 1.0:
        return None
    return _perturbed(fix_T_fix_guess, fit.x, radius_m)


@dataclass(frozen=True)
class ModeLikelihood:
    """One mode: its cells, its likelihood samples and its largest point displacement ``extent_m`` (m)."""

    cells: CellSet
    samples: Samples
    extent_m: float


def mode_shares(fixture: Fixture, base_p_taps: np.ndarray, ball_radius_m: float, sigma_m: float,
                sample_bound_m: float, modes: list[ModeLikelihood], rng: np.random.Generator,
                rough: bool = False) -> np.ndarray:
    """Each mode's probability (sum 1): its peak's share of the likelihood mass.

    A mode's peak is looked for from ``MASS_STARTS`` of its samples over all modes (at least 2 and at most 8
    per mode): half its most likely ones, half drawn at random, because in a coarse mode the most likely
    samples can all lie in the basin of a lesser peak. Then the best peak is carried to every mode with a
    lesser one by the fixture's symmetry, if it has one (surface matched within the sample bound) and the
    carried pose lies in that mode. ``rough`` (a set the taps do not pin down, whose modes span centimetres and
    whose shares no one acts on): from each mode's most likely sample only, ``ROUGH_FIT_EVALUATIONS`` at most,
    nothing carried.
    """
    if len(modes) == 1:
        return np.ones(1)
    oracle, radius_m = fixture.oracle, fixture.radius_m
    if rough:
        return shares_of([laplace_peak(oracle, base_p_taps, ball_radius_m, sigma_m, _starts(mode.samples, 1, rng)[0],
                                       radius_m, mode.extent_m, ROUGH_FIT_EVALUATIONS).log_mass for mode in modes])
    starts = min(MAX_STARTS_PER_MODE, max(MIN_STARTS_PER_MODE, MASS_STARTS // len(modes)))
    peaks = [mode_peak(oracle, base_p_taps, ball_radius_m, sigma_m, _starts(mode.samples, starts, rng), radius_m,
                       mode.extent_m) for mode in modes]
    best = max(peaks, key=lambda peak: peak.log_mass)
    fix_p_surface = trimesh.sample.sample_surface(fixture.mesh, SYMMETRY_POINTS, seed=0)[0] - fixture.cad_p_center
    for index, (mode, peak) in enumerate(zip(modes, peaks, strict=True)):
        if peak.log_mass >= best.log_mass - CARRY_WITHIN:
            continue
        symmetry = fixture_symmetry(oracle, fix_p_surface, invert(best.base_T_fix) @ peak.base_T_fix, radius_m,
                                    sample_bound_m)
        carried = None if symmetry is None else best.base_T_fix @ symmetry
        if carried is not None and mode.cells.contains(carried):
            peaks[index] = max(peak, laplace_peak(oracle, base_p_taps, ball_radius_m, sigma_m, carried, radius_m,
                                                  mode.extent_m), key=lambda found: found.log_mass)
    return shares_of([peak.log_mass for peak in peaks])


def _starts(samples: Samples, count: int, rng: np.random.Generator) -> np.ndarray:
    """Poses ``base_T_fix`` (count, 4, 4) to look for a mode's peak from: its most likely samples, then
    random ones."""
    likely = np.argsort(-samples.weights)[:(count + 1) // 2]
    others = np.setdiff1d(np.arange(len(samples.weights)), likely)
    chosen = np.concatenate([likely, rng.choice(others, min(count // 2, len(others)), replace=False)])
    return np.array([make_transform(samples.rotations[index], samples.positions_m[index]) for index in chosen])


def shares_of(log_masses: list[float]) -> np.ndarray:
    """Probabilities (sum 1) from each mode's log mass."""
    values = np.asarray(log_masses, dtype=float)
    shares = np.exp(values - values.max())
    return shares / shares.sum()
