"""A mode's likelihood peak and mass by Laplace's approximation: the mass matches the integral where the
likelihood is a peak and does not depend on which of the mode's poses the search starts from; a fixture's
symmetry is found from a rough guess; masses become shares."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import make_transform
from fixwizard.solver.mode_mass import fixture_symmetry, laplace_peak, mode_peak, shares_of
from fixwizard.synthetic import touching_ball_centres
from shapes import as_fixture

BALL_RADIUS_M = 0.0015
SIGMA_M = 0.001 / 3
EXTENT_M = 0.005
TOLERANCE_M = 0.001


@pytest.fixture(scope="module")
def tapped():
    """A random polytope (no symmetry: the taps fix every direction) at the base origin (base_T_fix =
    identity), and 15 exact taps spread over it."""
    fixture = as_fixture("polytope")
    fix_p_taps = touching_ball_centres(fixture.mesh, 15, BALL_RADIUS_M, np.random.default_rng(2))
    return fixture, fix_p_taps - fixture.cad_p_center


def log_likelihood(fixture, taps: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Log likelihood of the poses ``exp(omega)``, ``delta`` for steps (N, 6) = (omega * radius, delta) in m."""
    rotations = Rotation.from_rotvec(steps[:, :3] / fixture.radius_m)
    chi2 = np.zeros(len(steps))
    for tap in taps:
        fix_p_tap = rotations.inv().apply(tap - steps[:, 3:])
        chi2 += ((fixture.oracle.signed_distance_m(fix_p_tap) - BALL_RADIUS_M) / SIGMA_M) ** 2
    return -0.5 * chi2


def surface_points(fixture, count: int = 100) -> np.ndarray:
    return fixture.mesh.sample(count, seed=0) - fixture.cad_p_center


def test_the_laplace_mass_matches_the_integral_of_a_peaked_likelihood(tapped):
    fixture, taps = tapped
    peak = laplace_peak(fixture.oracle, taps, BALL_RADIUS_M, SIGMA_M, np.eye(4), fixture.radius_m, EXTENT_M)
    proposal_m = 2.0 * SIGMA_M  # wider than the peak in every direction, so importance sampling converges
    steps = np.random.default_rng(0).normal(scale=proposal_m, size=(40_000, 6))
    log_proposal = -0.5 * np.sum((steps / proposal_m) ** 2, axis=1) - 3.0 * np.log(2.0 * np.pi * proposal_m ** 2)
    log_ratio = log_likelihood(fixture, taps, steps) - log_proposal
    integral = np.log(np.mean(np.exp(log_ratio - log_ratio.max()))) + log_ratio.max()
    assert peak.log_mass + 3.0 * np.log(2.0 * np.pi) == pytest.approx(integral, abs=0.1)
    assert np.allclose(peak.base_T_fix, np.eye(4), atol=1e-5)  # exact taps: the peak is the true pose


def test_a_mode_mass_is_the_same_from_any_of_its_poses(tapped):
    fixture, taps = tapped
    rng = np.random.default_rng(1)
    starts = [make_transform(Rotation.from_rotvec(rng.normal(scale=0.01, size=3)), rng.normal(scale=0.001, size=3))
              for _ in range(3)]
    masses = [mode_peak(fixture.oracle, taps, BALL_RADIUS_M, SIGMA_M, np.array([start]), fixture.radius_m,
                        EXTENT_M).log_mass for start in starts]
    assert masses == pytest.approx([masses[0]] * 3, abs=0.01)


def test_a_symmetry_of_the_fixture_is_found_from_a_rough_guess():
    brick = as_fixture("brick")  # 100 x 60 x 30 mm, centred: half-turns about its axes map it onto itself
    guess = make_transform(Rotation.from_rotvec([0.0, 0.1, np.radians(170)]), [0.004, -0.003, 0.002])
    symmetry = fixture_symmetry(brick.oracle, surface_points(brick), guess, brick.radius_m, TOLERANCE_M)
    assert symmetry is not None
    half_turn_about_z = Rotation.from_rotvec([0.0, 0.0, np.pi])
    assert (half_turn_about_z.inv() * Rotation.from_matrix(symmetry[:3, :3])).magnitude() < 1e-3
    assert symmetry[:3, 3] == pytest.approx(np.zeros(3), abs=1e-5)


def test_an_asymmetric_fixture_has_no_symmetry(tapped):
    fixture = tapped[0]
    guess = make_transform(Rotation.from_rotvec([0.0, 0.0, np.pi]), np.zeros(3))
    assert fixture_symmetry(fixture.oracle, surface_points(fixture), guess, fixture.radius_m, TOLERANCE_M) is None


def test_shares_follow_the_masses():
    assert shares_of([-3.0, -3.0 + np.log(3.0)]) == pytest.approx([0.25, 0.75])
    assert shares_of([-1e4, -1e4]) == pytest.approx([0.5, 0.5])
