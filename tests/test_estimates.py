"""Likelihood samples of a surviving set: weights are a distribution, every pose lies in its cell, and when a
few coarse cells carry the weight a second, importance-weighted round spreads it over more samples."""

import numpy as np
import pytest

from fixwizard.demo import DEMO_TAPS, demo_fixture
from fixwizard.geometry.se3 import make_transform
from fixwizard.points import load_points
from fixwizard.solver import estimates
from fixwizard.solver.solve import solve

BALL_RADIUS_M = 0.0015
SIGMA_M = 0.001 / 3


@pytest.fixture(scope="module")
def coarse():
    fixture = demo_fixture()
    taps = load_points(DEMO_TAPS)
    return fixture, taps, solve(fixture, taps, 2 * BALL_RADIUS_M, 0.001, max_cells=2.4e6, max_samples=500).cells


def draw(coarse, max_samples: int = 2000):
    fixture, taps, cells = coarse
    return estimates.sample_cells(cells, fixture.oracle, taps, BALL_RADIUS_M, SIGMA_M, max_samples,
                                  np.random.default_rng(1))


def test_weights_are_a_distribution_and_every_pose_lies_in_its_cell(coarse):
    samples = draw(coarse)
    cells = coarse[2]
    assert samples.weights.sum() == pytest.approx(1.0)
    assert np.all(samples.weights >= 0)
    for index in np.argsort(-samples.weights)[:50]:
        pose = make_transform(samples.rotations[index], samples.positions_m[index])
        assert cells.subset(np.arange(len(cells)) == samples.cell_index[index]).contains(pose)


def test_a_second_round_spreads_weight_held_by_few_cells(coarse, monkeypatch):
    monkeypatch.setattr(estimates, "MIN_EFFECTIVE_SAMPLES", 0)
    first_round = draw(coarse)
    monkeypatch.setattr(estimates, "MIN_EFFECTIVE_SAMPLES", 10**9)
    second_round = draw(coarse)
    assert len(np.unique(second_round.cell_index)) < len(second_round.cell_index)  # heavy cells drawn again
    assert (estimates.effective_sample_size(second_round.weights)
            > estimates.effective_sample_size(first_round.weights))
