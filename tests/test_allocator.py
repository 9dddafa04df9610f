"""pkmcal.allocator: a freed multi-megabyte temporary is reused, not faulted in again."""

from __future__ import annotations

import subprocess
import sys

import pytest

from pkmcal.allocator import keep_freed_memory

#: Minor page faults of the first allocation and fill of an 8 MB array (fresh memory: about
#: 2048 faults of 4 kB pages, or about 500 with transparent huge pages) and of the second,
#: in a fresh interpreter (the test process's allocator is left alone), with or without
#: the setting.
_PROBE = """
import resource, sys
import numpy as np
took = False
if sys.argv[1] == "1":
    from pkmcal.allocator import keep_freed_memory
    took = keep_freed_memory()
faults = []
for _ in range(2):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.ones(2**20)
    del a
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(int(took), *faults)
"""


def _faults(setting: bool) -> tuple[bool, int, int]:
    """(whether the allocator took the setting, faults of the first fill, of the second)."""
    out = subprocess.run([sys.executable, "-c", _PROBE, "1" if setting else "0"], capture_output=True, text=True,
                         check=True)
    took, first, second = map(int, out.stdout.split())
    return bool(took), first, second


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="mallopt is glibc's")
def test_a_freed_block_is_reused_without_page_faults():
    took, first, second = _faults(True)
    if not took:
        pytest.skip("this C library refuses mallopt (not glibc)")
    assert first > 100                  # the first fill touched fresh pages: the probe sees faults
    assert second < first / 20          # the freed block came back from the heap
    # glibc's default hands the block back to the kernel: the second fill faults again
    _, default_first, default_second = _faults(False)
    assert default_second > default_first / 2


def test_no_mallopt_is_not_an_error(monkeypatch):
    monkeypatch.setattr(sys, "platform", "darwin")
    assert keep_freed_memory() is False


_ADVICE = """
from pkmcal.allocator import configure_process_memory
configure_process_memory()
import numpy as np
core = getattr(np, "_core", None) or np.core      # NumPy 2 / 1.x
print(int(core.multiarray._get_madvise_hugepage()))
"""


@pytest.mark.parametrize("user_value, advised", [(None, 0), ("1", 1)])
def test_numpy_huge_page_advice_is_off_unless_the_user_set_it(user_value, advised):
    import os

    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if user_value is not None:
        env["NUMPY_MADVISE_HUGEPAGE"] = user_value
    out = subprocess.run([sys.executable, "-c", _ADVICE], capture_output=True, text=True, check=True, env=env)
    assert int(out.stdout) == advised


def test_huge_page_advice_is_left_alone_once_numpy_is_imported(monkeypatch):
    import numpy  # noqa: F401  (imported: too late to change)

    from pkmcal.allocator import no_huge_page_advice

    monkeypatch.delenv("NUMPY_MADVISE_HUGEPAGE", raising=False)
    assert no_huge_page_advice() is False
