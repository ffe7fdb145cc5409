"""Which fixture is this? The same taps against several meshes: a mesh for which no pose explains the taps
is ruled out (the search keeps every pose that could explain them, so an empty set is a proof at any cell
budget); a mesh with surviving poses fits as far as that budget can tell.

``fixwizard identify POINTS MESH [MESH ...]`` prints one line per mesh and warns when more than one fits;
the sampling screen's "Which fixture?" runs the same against every mesh the wizard offers.
"""

import argparse
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from fixwizard.errors import FixwizardError
from fixwizard.fixture import load_fixture
from fixwizard.points import load_points
from fixwizard.solver.search import SearchProblem, search
from fixwizard.solver.solve import validate_inputs
from fixwizard.units import parse_length_m

DEFAULT_MAX_CELLS = 1e6
Verdict = Literal["fits", "ruled out", "unreadable"]


@dataclass(frozen=True)
class MeshVerdict:
    """One mesh's verdict; ``surviving_cells`` counts the poses' cells left at the budget (0 when ruled out)."""

    mesh: Path
    verdict: Verdict
    surviving_cells: int
    message: str


def identify(base_p_taps: np.ndarray, meshes: list[tuple[Path, str]], ball_diameter_m: float,
             sample_bound_m: float, max_cells: float = DEFAULT_MAX_CELLS,
             cancel: threading.Event | None = None) -> list[MeshVerdict]:
    """The verdict of every mesh (path and its units, "m" or "mm") for the taps (N, 3, base frame, m); lengths
    in m. A mesh that cannot be loaded gets the verdict "unreadable" with the loader's message instead of
    stopping the others. Raises ``SearchCancelled`` when ``cancel`` is set meanwhile."""
    base_p_taps = np.asarray(base_p_taps, float)
    validate_inputs(base_p_taps, ball_diameter_m, sample_bound_m, sample_bound_m / 3.0, max_cells)
    return [_verdict(base_p_taps, Path(mesh), units, ball_diameter_m, sample_bound_m, max_cells, cancel)
            for mesh, units in meshes]


def _verdict(base_p_taps: np.ndarray, mesh: Path, mesh_units: str, ball_diameter_m: float, sample_bound_m: float,
             max_cells: float, cancel: threading.Event | None) -> MeshVerdict:
    try:
        fixture = load_fixture(mesh, mesh_units)
    except FixwizardError as error:
        return MeshVerdict(mesh, "unreadable", 0, str(error))
    problem = SearchProblem(fixture.oracle, fixture.radius_m, base_p_taps, ball_diameter_m / 2.0, sample_bound_m)
    tree = search(problem, max_cells, cancel=cancel)
    survivors = None if tree is None else tree.final
    if survivors is None or len(survivors) == 0:
        return MeshVerdict(mesh, "ruled out", 0, "no pose of this mesh explains the taps")
    count = len(survivors)
    return MeshVerdict(mesh, "fits", count, f"{count:,} cells of poses explain the taps at this budget")


def summary_lines(verdicts: list[MeshVerdict]) -> list[str]:
    """One line per mesh, then what the verdicts mean together."""
    lines = [f"{verdict.verdict:10} {verdict.mesh}: {verdict.message}" for verdict in verdicts]
    fitting = [verdict.mesh.name for verdict in verdicts if verdict.verdict == "fits"]
    if not fitting:
        lines.append("no mesh fits: check the units (--mesh-units), the tip calibration and the sample bound, or "
                     "tap again")
    elif len(fitting) > 1:
        lines.append(f"warning: {len(fitting)} meshes fit these taps ({', '.join(fitting)}); tap features that "
                     "differ between them, or solve each at a larger --max-cells")
    return lines


def identify_command(args: argparse.Namespace) -> int:
    """Run ``fixwizard identify``: exit 0 when some mesh fits, 2 when none does."""
    verdicts = identify(load_points(args.points), [(Path(mesh), args.mesh_units) for mesh in args.meshes],
                        parse_length_m(args.ball_diameter), parse_length_m(args.sample_bound), args.max_cells)
    print("\n".join(summary_lines(verdicts)))
    return 0 if any(verdict.verdict == "fits" for verdict in verdicts) else 2


def register_identify_parser(commands, parse_cell_budget) -> None:
    """Add the ``identify`` sub-command to the CLI's sub-parsers."""
    parser = commands.add_parser("identify", help="which of several meshes can the taps belong to?")
    parser.add_argument("points", metavar="POINTS", help="taps: YAML {frame: base, points_m: [...]} or CSV x,y,z")
    parser.add_argument("meshes", metavar="MESH", nargs="+", help="candidate fixture meshes (STL, PLY or OBJ)")
    parser.add_argument("--sample-bound", required=True, help="bound on each tap's error, e.g. 1mm")
    parser.add_argument("--ball-diameter", required=True, help="diameter of the tip ball, e.g. 3mm")
    parser.add_argument("--mesh-units", choices=("m", "mm"), default="m", help="units of the mesh files")
    parser.add_argument("--max-cells", type=parse_cell_budget, default=DEFAULT_MAX_CELLS,
                        help=f"cell budget per mesh (default {DEFAULT_MAX_CELLS:g})")
    parser.set_defaults(func=identify_command)
