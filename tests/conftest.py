"""Shared test helpers: where the paper's real data lives, and how to skip without it; the loopback UR controllers'
process."""

import atexit
import errno
import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

from fixwizard.geometry.se3 import read_pose_dir, read_pose_file
from fixwizard.workflow.import_poses import ball_centres_m
from fixwizard.workflow.solver_process import SolverProcess
from ur_loopback import LoopbackProcess

# Distance lattices are cached on disk; tests (and the programs they start) keep theirs in a fresh folder.
os.environ["FIXWIZARD_CACHE"] = tempfile.mkdtemp(prefix="fixwizard-cache-")
atexit.register(shutil.rmtree, os.environ["FIXWIZARD_CACHE"], ignore_errors=True)

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "matlab-logo"
RUNS = ("student_1", "student_2", "student_3", "expert")
# Published bounds of the paper's reference implementation on these runs (1e7 cells, 1.0 mm):
# position (mm), rotation (deg).
REFERENCE_BOUNDS = {"student_1": (3.30, 2.65), "student_2": (2.71, 1.61), "student_3": (3.01, 4.05),
                    "expert": (1.59, 1.16)}


@pytest.fixture(autouse=True)
def _solver_processes_end_with_their_test():
    """A test's solver processes (the wizard's own end on quit) do not outlive it."""
    yield
    SolverProcess.close_all()


@pytest.fixture(scope="module")
def loopback():
    """The child process that runs a test module's loopback UR controllers (``ur_loopback``)."""
    process = LoopbackProcess()
    yield process
    process.close()


@pytest.fixture(scope="session")
def real_data() -> Path:
    if not DATA.is_dir():
        pytest.skip(f"the paper's real data is not at {DATA} (it lives in ../shared beside the repository)")
    return DATA


def real_taps(data: Path, run: str) -> np.ndarray:
    """Ball centres (N, 3, m, base frame) of one user-study run with the published tip."""
    tip = read_pose_file(data / "calib" / "tcp_t_tip.pose")[:3, 3]
    return ball_centres_m(read_pose_dir(data / "samples" / run)[1], tip)


@pytest.fixture
def small_disk(tmp_path) -> Path:
    """A 64 KiB tmpfs to fill up (root can mount one); skipped where mounting is not permitted, where the
    simulated full-disk tests still cover the same paths."""
    mount_point = tmp_path / "disk"
    mount_point.mkdir()
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount_point)],
                            capture_output=True, check=False)
    if result.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here: {result.stderr.decode().strip()}")
    yield mount_point
    subprocess.run(["umount", "-l", str(mount_point)], check=True)


def piped(handle: int, data: bytes) -> threading.Thread:
    """A thread writing ``data`` into the pipe end ``handle`` (then closing it) until the reader closes its end; join
    it once the reading end is closed."""

    def feed() -> None:
        try:
            os.write(handle, data)
        except BrokenPipeError:
            pass
        finally:
            os.close(handle)

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    return feeder


def fill_disk(folder: Path) -> Path:
    """Fill the disk holding ``folder`` to the last byte with one file, returned (delete it to free space)."""
    filler = folder / "filler"
    handle = os.open(filler, os.O_WRONLY | os.O_CREAT)
    for chunk in (b"x" * 4096, b"x"):
        try:
            while True:
                os.write(handle, chunk)
        except OSError as error:
            assert error.errno == errno.ENOSPC
    os.close(handle)
    return filler
