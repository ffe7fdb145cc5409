"""Bounded resources: a cell budget that could not fit in memory is capped with a warning that says how much it
would need, a point cloud passed as taps and taps light years away are refused with a message."""

import numpy as np
import pytest

from fixwizard.demo import DEMO_TAPS, demo_fixture
from fixwizard.errors import InputError
from fixwizard.points import load_points
from fixwizard.solver import resources
from fixwizard.solver import solve as solve_module
from fixwizard.solver.solve import MAX_TAPS, solve


def test_a_budget_of_1e12_cells_is_capped_to_what_memory_holds_and_says_so(monkeypatch):
    monkeypatch.setattr(solve_module, "available_memory_bytes", lambda: 1e9)  # a machine with 1 GB free
    taps = load_points(DEMO_TAPS)
    solution = solve(demo_fixture(), taps, 0.003, 0.001, max_cells=1e12, max_samples=500)
    capped = resources.largest_cell_budget(len(taps), 1e9)
    assert solution.stats.max_cells == pytest.approx(capped)
    assert resources.search_peak_bytes(capped, len(taps)) <= resources.MEMORY_SHARE * 1e9 * 1.0001
    message = dict((warning.code, warning.message) for warning in solution.warnings)["cell_budget_capped"]
    assert "could need 7e+02 GB" not in message and "GB, and 1.0 GB are free" in message


def test_the_peak_estimate_grows_with_the_taps():
    assert resources.search_peak_bytes(1e7, 1000) > 30 * resources.search_peak_bytes(1e7, 20)


@pytest.mark.parametrize("taps, said", [
    (np.random.default_rng(0).random((MAX_TAPS + 1, 3)), "point cloud"),
    (np.array([[1e15, 0, 0], [0.5, 0, 0], [0.4, 0.1, 0], [0.4, 0, 0.1]]), "beyond any robot arm's reach"),
    (np.array([[0.5, 0, 0], [0.4, 0.1, 1e30], [0.4, 0, 0.1]]), r"tap 2 lies 1e\+30 m"),
    (np.array([[0.5, 0, 0], [0.4, 0.1, 0], [-1e300, 1e300, 0.1]]), r"tap 3 lies 1.41e\+300 m"),
])
@pytest.mark.filterwarnings("error")  # no numpy overflow warning on the way to the message
def test_taps_no_robot_made_are_refused_with_a_message(taps, said):
    with pytest.raises(InputError, match=said):
        solve(demo_fixture(), taps, 0.003, 0.001)
