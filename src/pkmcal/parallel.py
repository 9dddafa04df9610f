"""Parallel pieces of work: the ordered map every backend uses, and this process's threads.

* :func:`ordered_map` — a ``map`` over any executor's futures (a thread or process pool,
  Dask), results in order, at most a given number in flight.
* :data:`IN_PROCESS` — the chunk map of "in this process, one chunk after the other".

One shared thread pool serves the compiled kinematics and planning.

The compiled kernels (:mod:`pkmcal.mechanisms._hexapod_kernels`, the selection kernels)
and NumPy's large operations release the GIL, so rows of a batch can run on several
threads of one process. Everything here splits work into pieces computed exactly as they
would be alone, so the bits never depend on the number of threads.

* :func:`local_threads` — how many: numba's thread count (every core, unless
  ``NUMBA_NUM_THREADS`` or ``numba.set_num_threads`` says fewer), the one knob for all.
* :func:`run_rows` — ``fn(start, stop)`` over row chunks of [0, n), taken in turn by the
  calling thread and the pool's (the caller never waits for a piece nobody started, so it
  may be called from a pool thread).
* :func:`thread_map` — an ordered ``map`` on the pool with a bounded number in flight.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Iterator

#: Chunks per thread in :func:`run_rows`, for load balance when a core is busy elsewhere.
CHUNKS_PER_THREAD = 4
#: Items in flight per worker (thread, process or Dask worker), ahead of the one consumed.
LOOKAHEAD = 2
#: The ``chunk_map`` of "in this process": the built-in lazy ``map`` (chunks one after the
#: other, in order, none computed after the consumer stops). Work that this process does
#: better than chunk by chunk (the planning blocks: batches on local threads, written in
#: place) checks ``chunk_map is IN_PROCESS``.
IN_PROCESS = map

_POOL: ThreadPoolExecutor | None = None
_POOL_SIZE = 0
_POOL_PID = 0
_POOL_LOCK = threading.Lock()


def ordered_map(submit: Callable, result: Callable, depth: int) -> Callable:
    """A ``chunk_map(fn, chunks)`` that keeps at most ``depth`` chunks in flight
    (``submit(fn, chunk)`` → a future, ``result(future)`` → its value) and yields the
    results in the order of ``chunks``; the futures left when the consumer stops are
    cancelled."""

    def chunk_map(fn: Callable, chunks: Iterable) -> Iterator:
        pending: deque = deque()
        it = iter(chunks)
        try:
            for chunk in it:
                pending.append(submit(fn, chunk))
                if len(pending) >= depth:
                    yield result(pending.popleft())
            while pending:
                yield result(pending.popleft())
        finally:
            for fut in pending:
                fut.cancel()

    return chunk_map


def local_threads() -> int:
    """Threads for in-process work: numba's thread count (module docstring)."""
    import numba

    return int(numba.get_num_threads())


def pool(workers: int) -> ThreadPoolExecutor:
    """The shared pool of at least ``workers`` threads, (re)created when too small or after
    a fork (a forked child inherits the pool object but not its threads)."""
    global _POOL, _POOL_SIZE, _POOL_PID
    with _POOL_LOCK:
        if _POOL is None or _POOL_SIZE < workers or _POOL_PID != os.getpid():
            if _POOL is not None and _POOL_PID == os.getpid():
                _POOL.shutdown(wait=False)
            _POOL = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="pkmcal")
            _POOL_SIZE, _POOL_PID = workers, os.getpid()
        return _POOL


def run_rows(fn: Callable[[int, int], None], n: int, grain: int) -> None:
    """``fn(start, stop)`` over [0, n): on the calling thread for n < 2·grain, else in
    chunks shared by the calling thread and min(local_threads(), n // grain) − 1 pool
    threads, each chunk written in place by ``fn``."""
    workers = min(local_threads(), n // grain) if n >= 2 * grain else 1
    if workers <= 1:
        fn(0, n)
        return
    n_chunks = workers * CHUNKS_PER_THREAD
    bounds = [n * i // n_chunks for i in range(n_chunks + 1)]
    nxt = itertools.count().__next__  # atomic under the GIL

    def work():
        while (i := nxt()) < n_chunks:
            fn(bounds[i], bounds[i + 1])

    futures = [pool(workers - 1).submit(work) for _ in range(workers - 1)]
    work()
    for f in futures:  # every chunk is taken; wait only for those a worker started
        if not f.cancel():
            f.result()


def thread_map(fn: Callable, items: Iterable) -> Iterator:
    """``map(fn, items)`` on :func:`local_threads` threads, results in order, at most
    :data:`LOOKAHEAD` items per thread in flight (the built-in ``map`` on one thread).
    Not for use from a pool thread (its items would wait for the threads it holds)."""
    threads = local_threads()
    if threads <= 1:
        return map(fn, items)
    return ordered_map(pool(threads).submit, lambda fut: fut.result(), LOOKAHEAD * threads)(fn, items)


__all__ = ["CHUNKS_PER_THREAD", "LOOKAHEAD", "local_threads", "ordered_map", "pool", "run_rows", "thread_map"]
