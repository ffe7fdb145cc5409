"""A finely tessellated CAD export, as a user solves it: whole-process wall time of `fixwizard solve` on a rounded
part of about 1.3 million triangles (every vertex of it on its convex hull), with 15 simulated taps.

Usage (from the repository root):
    .venv/bin/python benchmarks/large_mesh.py [--subdivisions 8] [--repeat 1]

The part is an icosphere (subdivisions 8: 1,310,720 triangles) stretched to 160 x 100 x 50 mm and rippled by
2 mm, so that it is no symmetric shape; the taps are ball centres touching it (3 mm ball) with errors up to
0.5 mm at a fixed pose. The first solve builds the mesh's distance lattice and caches it (as the first solve of
any new mesh does); the printed times are of the solves after it, each a fresh process, with the phases the CLI
reports (its elapsed seconds) and the peak memory.
"""

import argparse
import statistics
import tempfile
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from cli_process import timed_command

REPO = Path(__file__).resolve().parents[1]


def make_inputs(folder: Path, subdivisions: int) -> tuple[Path, Path]:
    """The rippled ellipsoid as STL and its taps as a POINTS file."""
    import numpy as np
    import trimesh
    from scipy.spatial.transform import Rotation

    from fixwizard.geometry.se3 import make_transform, transform_points
    from fixwizard.points import write_points
    from fixwizard.synthetic import bounded_noise, touching_ball_centres

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.05)
    vertices = sphere.vertices * [1.6, 1.0, 0.5]
    vertices = vertices + 0.002 * np.sin(40.0 * vertices[:, [1, 2, 0]])
    part = trimesh.Trimesh(vertices, sphere.faces)
    mesh = folder / "rounded_part.stl"
    part.export(mesh)
    rng = np.random.default_rng(1)
    cad_p_centres = touching_ball_centres(part, 15, 0.0015, rng)
    base_T_cad = make_transform(Rotation.from_rotvec([0.1, 0.05, 0.4]), [0.3, -0.1, 0.05])
    points = folder / "taps.yaml"
    write_points(points, transform_points(base_T_cad, cad_p_centres) + bounded_noise(15, 0.0005, rng))
    return mesh, points


def solve_process(mesh: Path, points: Path, report: Path) -> tuple[float, float, list[str]]:
    """Wall time (s) and peak memory (MB) of one whole `fixwizard solve` process, and the lines it wrote to
    stderr."""
    return timed_command(REPO, ["solve", str(mesh), str(points), "--sample-bound", "1mm", "--ball-diameter", "3mm",
                                "-o", str(report)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--subdivisions", type=int, default=8)
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="fixwizard-large-mesh-"))
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as maker:  # its gigabytes end with it
        mesh, points = maker.submit(make_inputs, folder, args.subdivisions).result()
    first, first_peak, _ = solve_process(mesh, points, folder / "report.yaml")
    print(f"first solve (builds and caches the lattice): {first:.1f} s, {first_peak:.0f} MB")
    walls, peaks = [], []
    for _ in range(args.repeat):
        seconds, peak, lines = solve_process(mesh, points, folder / "report.yaml")
        walls.append(seconds)
        peaks.append(peak)
        for line in lines:
            if "level rotation 0 / position 0" in line or not line.startswith("  level"):
                print(f"    {line.strip()}")
        print(f"solve: {seconds:.1f} s")
    print(f"median {statistics.median(walls):.1f} s over {len(walls)}; peak memory of a solve {max(peaks):.0f} MB")


if __name__ == "__main__":
    main()
