"""House habits as tests, so that `./dev test` (and CI) fails on them: ruff's lint and mypy's type check, both
configured in pyproject.toml (mypy strict on fixwizard/solver/ and fixwizard/geometry/)."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    """The tool run as a module of the test environment's Python, from the repository root."""
    return subprocess.run([sys.executable, "-m", *args], cwd=REPO, capture_output=True, text=True, timeout=600,
                          check=False)


def test_ruff_finds_nothing_to_fix():
    result = _run("ruff", "check", "--no-cache", "fixwizard", "tests", "benchmarks", "tools")
    assert result.returncode == 0, f"ruff check failed:\n{result.stdout}{result.stderr}"


def test_mypy_finds_no_type_errors():
    result = _run("mypy")
    assert result.returncode == 0, f"mypy failed:\n{result.stdout}{result.stderr}"
