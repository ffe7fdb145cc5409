"""The warm-up: after it, a process's solves (a full one, the live check's first look and quick check) compile no
kernel of their own, so neither the operator's first solve after installing nor the wizard's first live check
waits half a minute for Numba."""

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

CHECK = """
import importlib, pkgutil, sys
import numba
import fixwizard
sys.path.insert(0, {tests!r})
from conftest import real_taps
modules = [importlib.import_module(info.name) for info in pkgutil.walk_packages(fixwizard.__path__, "fixwizard.")
           if ".tui" not in info.name and not info.name.endswith("__main__")]

def compiled():
    return {{f"{{module.__name__}}.{{name}}": set(map(str, value.signatures)) for module in modules
            for name, value in vars(module).items()
            if isinstance(value, numba.core.dispatcher.Dispatcher) and value.__module__ == module.__name__}}

from fixwizard.solver.warm_up import warm_up_solver
warm_up_solver()
before = compiled()
from pathlib import Path
from fixwizard.fixture import load_fixture
from fixwizard.solver.solve import solve
from fixwizard.workflow.live import first_look, quick_check
data = Path({data!r})
fixture = load_fixture(data / "meshes" / "matlab_logo.ply")
taps = real_taps(data, "expert")
solve(fixture, taps, 0.003, 0.001, max_cells=3e5)
quick_check(fixture, taps[:11], 0.003, 0.001, previous=first_look(fixture, taps[:10], 0.003, 0.001))
print(sorted(name for name, signatures in compiled().items() if signatures - before.get(name, set())))
"""


@pytest.mark.slow
def test_after_the_warm_up_a_solve_of_real_taps_compiles_nothing(real_data):
    """In a fresh process (another test's compiled kernels would hide a gap)."""
    script = CHECK.format(tests=str(REPO / "tests"), data=str(real_data))
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=REPO, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip().splitlines()[-1] == "[]"
