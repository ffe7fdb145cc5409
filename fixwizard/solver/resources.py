"""How much memory a search needs, and the largest cell budget this machine can hold.

A search keeps, for every surviving cell of its finest level, an interval (two float32) and a face (int32) per
tap, ``BYTES_PER_CELL_TAP``, besides ``BYTES_PER_CELL`` of its own (rotation index, octree cell, the centre's
rotated position, the parent's row). A level's survivors can be as many as the cells it evaluated (taps that
reject nothing), at most the budget; while a level is filtered, its parents' intervals, the chunks' outputs and
their concatenation are held at once: ``PEAK_FACTOR`` times the survivors. A budget whose peak would pass
``MEMORY_SHARE`` of the memory available at the start is capped (the search then stops at coarser cells, and
says so).
"""

import os

BYTES_PER_CELL = 64
BYTES_PER_CELL_TAP = 12
PEAK_FACTOR = 2.5
MEMORY_SHARE = 0.6


def available_memory_bytes() -> float:
    """Memory (bytes) the system can give without swapping: ``MemAvailable`` of /proc/meminfo, else the physical
    memory."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass  # no /proc (not Linux): fall back to the physical memory
    return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


def search_peak_bytes(max_cells: float, taps: int) -> float:
    """The most memory (bytes) a search at ``max_cells`` with ``taps`` taps can hold at once."""
    return PEAK_FACTOR * max_cells * (BYTES_PER_CELL + BYTES_PER_CELL_TAP * taps)


def largest_cell_budget(taps: int, available_bytes: float) -> float:
    """The largest cell budget whose search fits in ``MEMORY_SHARE`` of ``available_bytes``."""
    return MEMORY_SHARE * available_bytes / search_peak_bytes(1.0, taps)
