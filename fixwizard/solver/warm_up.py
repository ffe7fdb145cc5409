"""Compile (or load from Numba's cache) every kernel a solve runs, on a small box: a process's first solve then pays
none of it. The first time after installing or updating fixwizard this compiles them (about half a minute on two
cores; Numba caches the result beside the sources), later it loads them (a few tenths of a second).

``python -m fixwizard.solver.warm_up`` does it once for an install (``./dev run`` calls it after each install or
update); the wizard's solver process does it as it starts, while the operator takes the first taps.
"""

from pathlib import Path

import numpy as np
import trimesh

from fixwizard.fixture import fixture_from_mesh
from fixwizard.solver.interval_kernel import query_band
from fixwizard.solver.solve import solve
from fixwizard.synthetic import touching_ball_centres

SAMPLE_BOUND_M = 0.001


def warm_up_solver() -> None:
    """A whole solve (search, hull refinement, samples, mode masses, intervals) of point-probe taps on a 5 x 4 x 3 cm
    box, three of them on its edges; a batch of signed distances near its edges (the parallel queries and rays of
    large batches); and ``query_band`` with the search's types (its pairs do not occur on this box)."""
    box = fixture_from_mesh(trimesh.creation.box((0.05, 0.04, 0.03)), Path("warm-up box"), "m", "generated")
    corner = box.mesh.bounds[1]
    on_edges = np.array([[corner[0], 0.0, corner[2]], [0.0, corner[1], corner[2]], [corner[0], corner[1], 0.0]])
    rng = np.random.default_rng(0)
    taps = np.vstack([touching_ball_centres(box.mesh, 12, 0.0, rng), on_edges])  # a point probe: signs matter
    solve(box, taps, 0.0, SAMPLE_BOUND_M, max_cells=1e5, max_samples=1000, diagnose_inconsistent=False)
    near_edges = np.repeat(on_edges, 4000, axis=0) + rng.normal(0.0, 0.002, (12000, 3))
    box.oracle.signed_distance_m(near_edges - box.cad_p_center)
    cells = (np.eye(3)[None], np.zeros(1, np.int64), np.zeros((1, 3), np.int32), np.zeros(1), np.zeros(4))
    query_band(cells, np.zeros((1, 3)), np.zeros(1, np.int64), np.zeros(1, np.int64), taps, (0.0, 0.0, 0.0, 0.0))


if __name__ == "__main__":
    warm_up_solver()
