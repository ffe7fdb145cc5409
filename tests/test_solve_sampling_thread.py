"""A mode's likelihood samples are drawn in a second thread while its bounds are refined: a solve is still the same
every time (several modes, each sampled in turn), a cancel during the bounds does not wait for the samples, and
the sampling stops before its next round."""

import threading
import time

import numpy as np
import pytest

from fixwizard.solver import estimates
from fixwizard.solver import solve as solve_module
from fixwizard.solver.estimates import Bounds
from fixwizard.solver.search import SearchCancelled, search
from fixwizard.solver.solve import solve
from test_guarantee import symmetric_case
from test_search_parts import small_problem


def same_bounds(one: Bounds, other: Bounds) -> bool:
    return np.array_equal(one.base_T_cad_center, other.base_T_cad_center) and (
        (one.position_m, one.rotation_rad, one.max_point_displacement_m)
        == (other.position_m, other.rotation_rad, other.max_point_displacement_m))


def test_a_solve_with_several_modes_is_the_same_every_time():
    fixture, _, taps = symmetric_case("brick", seed=3)
    first, second = (solve(fixture, taps, 0.003, 0.0005, max_cells=1e6, max_samples=4000) for _ in range(2))
    assert len(first.modes) > 1
    assert same_bounds(first.bounds, second.bounds) and first.effective_samples == second.effective_samples
    for one, other in zip(first.modes, second.modes, strict=True):
        assert one.probability == other.probability
        assert np.array_equal(one.base_T_cad, other.base_T_cad) and same_bounds(one.bounds, other.bounds)


def test_a_cancel_during_the_bounds_does_not_wait_for_the_samples(monkeypatch):
    fixture, problem = small_problem()
    released, sampling, finished = threading.Event(), threading.Event(), threading.Event()
    real_sample_cells = solve_module.sample_cells

    def slow_sample_cells(*args, **kwargs):
        sampling.set()
        released.wait(20)
        finished.set()
        return real_sample_cells(*args, **kwargs)

    monkeypatch.setattr(solve_module, "sample_cells", slow_sample_cells)
    cancel = threading.Event()

    def stage(step):
        if step.name == "bounds" and step.round >= 1:
            assert sampling.wait(10)
            cancel.set()

    try:
        with pytest.raises(SearchCancelled):
            solve(fixture, problem.base_p_taps, 0.003, 0.0005, max_cells=5e4, max_samples=500, stage=stage,
                  cancel=cancel)
        assert not finished.is_set()
    finally:
        released.set()


def counted_likelihood(monkeypatch, after_first=None):
    """Count the likelihood evaluations of the sampling rounds (one per round); ``after_first`` is called after the
    first."""
    calls = []
    real = estimates._log_likelihood

    def counting(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1 and after_first is not None:
            after_first()
        return real(*args, **kwargs)

    monkeypatch.setattr(estimates, "_log_likelihood", counting)
    return calls


@pytest.mark.parametrize("when", ["before", "during the first round"])
def test_a_cancel_ends_the_sampling_before_its_next_round(monkeypatch, when):
    """Coarse cells need several rounds; a cancel set before the first (or during it) stops before the next."""
    fixture, problem = small_problem()
    cells = search(problem, 2e4).final.cells
    cancel = threading.Event()
    if when == "before":
        cancel.set()
    calls = counted_likelihood(monkeypatch, cancel.set)
    with pytest.raises(SearchCancelled):
        estimates.sample_cells(cells, fixture.oracle, problem.base_p_taps, problem.ball_radius_m, 0.0005 / 3, 4000,
                               np.random.default_rng(0), problem.fixture_radius_m, cancel)
    assert len(calls) == (0 if when == "before" else 1)
    monkeypatch.undo()
    uncancelled = counted_likelihood(monkeypatch)
    estimates.sample_cells(cells, fixture.oracle, problem.base_p_taps, problem.ball_radius_m, 0.0005 / 3, 4000,
                           np.random.default_rng(0), problem.fixture_radius_m, threading.Event())
    assert len(uncancelled) > 1  # these cells do need more than one round


def test_after_a_cancelled_solve_its_sampling_thread_stops_within_a_round(monkeypatch):
    fixture, problem = small_problem()
    cancel = threading.Event()
    rounds_after_cancel = []
    real = estimates._log_likelihood

    def slow_round(*args, **kwargs):
        if cancel.is_set():
            rounds_after_cancel.append(1)
        time.sleep(0.3)
        return real(*args, **kwargs)

    monkeypatch.setattr(estimates, "_log_likelihood", slow_round)

    def stage(step):
        if step.name == "bounds" and step.round >= 1:
            cancel.set()

    with pytest.raises(SearchCancelled):
        solve(fixture, problem.base_p_taps, 0.003, 0.0005, max_cells=5e4, max_samples=4000, stage=stage,
              cancel=cancel)
    deadline = time.monotonic() + 5.0
    while any(thread.name.startswith("fixwizard-samples") for thread in threading.enumerate()):
        assert time.monotonic() < deadline, "the sampling thread went on after the cancel"
        time.sleep(0.01)
    assert len(rounds_after_cancel) <= 1  # at most the round under way when the cancel came
