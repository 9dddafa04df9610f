"""The C allocator of a pkmcal command's process: keep freed temporaries for reuse.

NumPy takes its arrays from ``malloc``. With glibc's defaults, a block of more than a few
megabytes (the per-batch temporaries of the planning blocks and the selection passes,
2-10 MB each) is handed back to the kernel when freed, and the next batch's block is faulted
in again, page by page, and zeroed. On this project's VMs a minor page fault costs ~3 µs: the
110-of-100,000 plan took 220,000 faults, 0.9-1.4 s of system time, for 0.46 GB of peak
memory. :func:`keep_freed_memory` raises glibc's limits so that such blocks stay in the
heap and are reused (``mallopt``: mmap threshold 32 MB, the largest glibc accepts; trim
threshold 256 MB): the same plan then takes 44,000 faults (first touches of its arrays)
and 0.3-0.7 s of system time, at the same peak memory (0.48 GB).

Called by the command-line entry point only (the process is pkmcal's; a library does not
tune its host's allocator). Worker processes forked from it inherit the setting. A no-op
where ``mallopt`` does not exist (macOS, Windows) or refuses the values.
"""

from __future__ import annotations

#: mallopt parameters (glibc's malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3

#: Blocks up to this size come from the heap (glibc's upper bound for the threshold).
MMAP_THRESHOLD = 32 * 2**20
#: Free memory at the top of the heap kept for reuse before it is returned.
TRIM_THRESHOLD = 256 * 2**20


def keep_freed_memory() -> bool:
    """Set the thresholds (module docstring); True when the allocator took them."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
