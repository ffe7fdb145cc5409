"""How fixwizard's Numba kernels (mesh distances, the search, the bounds) use both cores: the threading layer, and
one parallel kernel at a time."""

import threading

import numba

# OpenMP where the system has it, else Numba's own work queue, which never fails: TBB, whose version
# check warns on the terminal the wizard draws on, is never tried. Set before any parallel kernel runs
# (every module with one imports this module).
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]  # type: ignore[attr-defined]  # set at import

# Held around every parallel kernel call, whichever thread makes it: the work queue is not thread-safe.
PARALLEL_KERNEL_LOCK = threading.Lock()
