"""Loading a finely tessellated CAD export, as the wizard and every command do before anything else: wall time of
`load_fixture` (read, merge the STL's corners, mesh hygiene) and of building its distance oracle, each in a fresh
process, on the rounded part of `large_mesh.py` (1,310,720 triangles as a binary STL).

Usage (from the repository root):
    .venv/bin/python benchmarks/mesh_load.py [--subdivisions 8] [--repeat 3] [--compare ../other-checkout]

``--compare DIR`` loads with another checkout (its own .venv, or this one's where it has none) alternately with this
one, since these machines drift; each process imports the fixwizard of the checkout it runs in.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from large_mesh import make_inputs

REPO = Path(__file__).resolve().parents[1]
LOAD = """\
import sys, time
started = time.perf_counter()
from fixwizard.fixture import load_fixture
imported = time.perf_counter()
fixture = load_fixture(sys.argv[1], "m")
loaded = time.perf_counter()
fixture.oracle
print(loaded - imported, time.perf_counter() - loaded)
"""


def load_process(checkout: Path, mesh: Path) -> tuple[float, float]:
    """Seconds to load the fixture and to build its oracle, in a fresh process of ``checkout``'s fixwizard."""
    python = checkout / ".venv" / "bin" / "python"
    if not python.exists():
        python = REPO / ".venv" / "bin" / "python"
    result = subprocess.run([str(python), "-c", LOAD, str(mesh)], cwd=checkout, capture_output=True, text=True,
                            env={**os.environ, "PYTHONPATH": str(checkout)})
    if result.returncode != 0:
        sys.exit(f"{checkout}: the load failed:\n{result.stderr[-2000:]}")
    load_s, oracle_s = (float(value) for value in result.stdout.split())
    return load_s, oracle_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--subdivisions", type=int, default=8)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--compare", type=Path, help="another checkout, loaded alternately with this one")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="fixwizard-mesh-load-"))
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as maker:  # its gigabytes end with it
        mesh, _ = maker.submit(make_inputs, folder, args.subdivisions).result()
    checkouts = {"this": REPO} | ({"compare": args.compare.resolve()} if args.compare else {})
    for checkout in checkouts.values():
        load_process(checkout, mesh)  # compiles (or loads) its kernels once, untimed
    totals: dict[str, list[float]] = {name: [] for name in checkouts}
    for _ in range(args.repeat):
        for name, checkout in checkouts.items():
            load_s, oracle_s = load_process(checkout, mesh)
            totals[name].append(load_s + oracle_s)
            print(f"{name}: load {load_s:.1f} s, oracle {oracle_s:.1f} s, together {load_s + oracle_s:.1f} s",
                  flush=True)
    for name, seconds in totals.items():
        print(f"{name}: median {statistics.median(seconds):.1f} s over {len(seconds)}")


if __name__ == "__main__":
    main()
