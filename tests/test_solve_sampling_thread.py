"""A mode's likelihood samples are drawn in a second thread while its bounds are refined: a solve is still the same
every time (several modes, each sampled in turn), and a cancel during the bounds does not wait for the samples."""

import threading

import numpy as np
import pytest

from fixwizard.solver import solve as solve_module
from fixwizard.solver.estimates import Bounds
from fixwizard.solver.search import SearchCancelled
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
