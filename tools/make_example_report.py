"""Regenerate examples/report.yaml: the report of the bundled demo bracket's simulated taps, as `fixwizard solve`
writes it (1e7 cells), with the mesh named by its path in the repository. Run from the repository root:

    .venv/bin/python tools/make_example_report.py

tests/test_schemas.py checks that the example loads, matches the report's JSON Schema and has the layout the code
writes today.
"""

import datetime as dt
from pathlib import Path

import numpy as np

from fixwizard import report
from fixwizard.demo import DEMO_MESH, DEMO_TAPS, demo_fixture
from fixwizard.points import load_points
from fixwizard.solver.solve import solve

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "report.yaml"
BALL_DIAMETER_M, SAMPLE_BOUND_M = 0.003, 0.001
CREATED = dt.datetime(2026, 1, 5, 9, 30, tzinfo=dt.UTC)


def main() -> None:
    fixture = demo_fixture()
    base_p_taps = load_points(DEMO_TAPS)
    solution = solve(fixture, base_p_taps, BALL_DIAMETER_M, SAMPLE_BOUND_M)
    data = report.report_dict(solution, fixture, np.asarray(base_p_taps), BALL_DIAMETER_M, SAMPLE_BOUND_M,
                              SAMPLE_BOUND_M / 3.0, created=CREATED, simulated=True, name="bracket")
    data["fixture"]["mesh"] = str(DEMO_MESH.relative_to(REPO))
    report.write(EXAMPLE, data)
    print(f"{EXAMPLE.relative_to(REPO)}: {solution.status}, {solution.stats.elapsed_s:.1f} s")


if __name__ == "__main__":
    main()
