"""The report file robot programs read: schema, atomic writing, and loading with checks."""

import numpy as np
import pytest

from fixwizard import report
from fixwizard.errors import InputError
from fixwizard.solver.solve import solve
from fixwizard.synthetic import bounded_noise, touching_ball_centres
from shapes import as_fixture


@pytest.fixture(scope="module")
def solved():
    fixture = as_fixture("l_prism")
    rng = np.random.default_rng(4)
    taps = touching_ball_centres(fixture.mesh, 20, 0.0015, rng) + bounded_noise(20, 0.0005, rng)
    solution = solve(fixture, taps, 0.003, 0.0005, max_cells=1e6, max_samples=2000)
    assert solution.status == "unique"
    return fixture, taps, solution


def test_report_round_trip_keeps_pose_and_bounds(solved, tmp_path):
    fixture, taps, solution = solved
    data = report.report_dict(solution, fixture, taps, 0.003, 0.0005, 0.0005 / 3)
    report.write(tmp_path / "r.yaml", data)
    loaded = report.load(tmp_path / "r.yaml")
    assert loaded.data["schema"] == "fixwizard.report/1"
    assert loaded.base_T_cad == pytest.approx(solution.base_T_cad, abs=1e-12)
    assert loaded.position_bound_m == pytest.approx(solution.bounds.position_m)
    assert [interval["level"] for interval in loaded.data["intervals"]] == [0.95, 0.99]
    assert loaded.data["pose"]["ur"].startswith("p[")
    assert set(loaded.data) >= {"created", "status", "modes", "warnings", "search", "inputs"}


@pytest.mark.parametrize("text, match", [("just words", "not a fixwizard report"),
                                         ("schema: fixwizard.report/1\nstatus: great\n", "status"),
                                         ("schema: fixwizard.report/1\nstatus: unique\npose: null\n", "needs 'pose'"),
                                         ("{{{", "is not valid YAML: .* at line 1")])
def test_damaged_reports_are_refused_with_a_reason(tmp_path, text, match):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match=match):
        report.load(path)


def test_writing_replaces_the_file_whole(solved, tmp_path):
    fixture, taps, solution = solved
    path = tmp_path / "r.yaml"
    path.write_text("old")
    report.write(path, report.report_dict(solution, fixture, taps, 0.003, 0.0005, 0.0005 / 3))
    assert report.load(path).status == solution.status
    assert [entry.name for entry in tmp_path.iterdir()] == ["r.yaml"]
