"""The memory policy of a pkmcal command's process: freed temporaries kept for reuse, no huge-page advice.

NumPy takes its arrays from ``malloc``. With glibc's defaults, a block of more than a few
megabytes (the per-batch temporaries of the planning blocks and the selection passes,
2-10 MB each) is handed back to the kernel when freed, and the next batch's block is faulted
in again, page by page, and zeroed. On this project's VMs a minor page fault costs ~3 µs: the
110-of-100,000 plan took 220,000 faults, 0.9-1.4 s of system time, for 0.46 GB of peak
memory. :func:`keep_freed_memory` raises glibc's limits so that such blocks stay in the
heap and are reused (``mallopt``: mmap threshold 32 MB, the largest glibc accepts; trim
threshold 256 MB): the same plan then takes 44,000 faults (first touches of its arrays)
and 0.3-0.7 s of system time, at the same peak memory (0.48 GB).

NumPy also advises the kernel to back arrays of 4 MB or more with transparent huge pages.
Where the kernel compacts memory to find them when a page is first touched (``defrag`` set
to ``madvise``, the default of many distributions and of this project's VMs), the 200 MB of
blocks of that plan took 0.5-0.75 s of system time to fault in, against 0.1-0.2 s in 4 kB
pages; alternated over 7 runs of the whole plan, 2.71 s median wall without the advice
against 2.80 s with it. :func:`no_huge_page_advice` turns it off (NumPy's documented
``NUMPY_MADVISE_HUGEPAGE``, before NumPy is imported; a value the user set is kept).

:func:`configure_process_memory` does both. It is called by the command-line entry point
only (the process is pkmcal's; a library does not tune its host's allocator); worker
processes forked or spawned from it inherit the settings. A no-op where ``mallopt`` does
not exist (macOS, Windows) or refuses the values.
"""

from __future__ import annotations

import os
import sys

#: mallopt parameters (glibc's malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3

#: Blocks up to this size come from the heap (glibc's upper bound for the threshold).
MMAP_THRESHOLD = 32 * 2**20
#: Free memory at the top of the heap kept for reuse before it is returned.
TRIM_THRESHOLD = 256 * 2**20


def configure_process_memory() -> None:
    """:func:`keep_freed_memory` and :func:`no_huge_page_advice` (module docstring)."""
    keep_freed_memory()
    no_huge_page_advice()


def no_huge_page_advice() -> bool:
    """NumPy without its huge-page advice (module docstring); False when NumPy is already
    imported (too late: it reads the setting once) or the user chose a value."""
    if "numpy" in sys.modules or "NUMPY_MADVISE_HUGEPAGE" in os.environ:
        return False
    os.environ["NUMPY_MADVISE_HUGEPAGE"] = "0"
    return True


def keep_freed_memory() -> bool:
    """Set the thresholds (module docstring); True when the allocator took them."""
    import ctypes

    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
