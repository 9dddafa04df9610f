"""Where a plan's chunks run: in this process, on local worker processes, or on a Dask cluster.

A plan checks its candidates and computes their planning blocks chunk by chunk
(:func:`~pkmcal.planning.candidates.generate_candidates`,
:func:`~pkmcal.planning.plan.candidate_blocks`), each chunk a picklable unit of work mapped
by a ``chunk_map(fn, chunks)`` that yields the results in order. :func:`chunk_map` opens
one on the backends of ``pkmcal study`` (:mod:`pkmcal.study.backends`: the same core count
and the same Dask client):

* in this process (``workers`` None or 1, no ``dask``): the built-in lazy ``map``;
* ``workers`` N > 1: a :class:`concurrent.futures.ProcessPoolExecutor` of N processes,
  forked on Linux (the workers start with the modules and the compiled kernels loaded), spawned
  elsewhere;
* ``dask``: a scheduler address, or ``"local"`` for a LocalCluster of ``workers`` (default: all
  local cores) single-threaded processes.

Work that needs no pickling — the planning blocks of the accepted candidates, the
selection's passes over all of them — runs in this process on :func:`local_threads`
threads (:func:`thread_map`, :func:`run_ranges`): NumPy's large operations and the compiled
kernels release the GIL, and each piece is computed exactly as it would be alone, so the
bits do not depend on the number of threads.

Chunks are submitted ahead of the one being consumed by at most :data:`LOOKAHEAD` per
worker, so memory stays bounded by a few chunks whatever the number of chunks (an
executor's own ``map`` would submit, and hold, all of them at once). Every chunk is
computed by the same deterministic code wherever it runs and the results arrive in
order, so the plan is the same whatever the backend and the number of workers.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Iterator

from pkmcal.errors import PkmcalError

#: Chunks in flight per worker, ahead of the one being consumed.
LOOKAHEAD = 2


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
    """Threads for in-process planning work: numba's thread count (every core, unless
    ``NUMBA_NUM_THREADS`` or ``numba.set_num_threads`` says fewer), the count the compiled
    kinematics use."""
    import numba

    return int(numba.get_num_threads())


_POOL: ThreadPoolExecutor | None = None
_POOL_KEY: tuple[int, int] = (0, 0)
_POOL_LOCK = threading.Lock()


def _thread_pool(threads: int) -> ThreadPoolExecutor:
    """The shared planning thread pool, (re)created for another size or after a fork (a
    forked child inherits the pool object but not its threads)."""
    global _POOL, _POOL_KEY
    with _POOL_LOCK:
        key = (threads, os.getpid())
        if _POOL is None or _POOL_KEY != key:
            if _POOL is not None and _POOL_KEY[1] == os.getpid():
                _POOL.shutdown(wait=False)
            _POOL = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="pkmcal-planning")
            _POOL_KEY = key
        return _POOL


def thread_map(fn: Callable, items: Iterable) -> Iterator:
    """``map(fn, items)`` on :func:`local_threads` threads, results in order, at most
    :data:`LOOKAHEAD` items per thread in flight (the built-in ``map`` on one thread)."""
    threads = local_threads()
    if threads <= 1:
        return map(fn, items)
    return ordered_map(_thread_pool(threads).submit, lambda fut: fut.result(), LOOKAHEAD * threads)(fn, items)


def run_ranges(fn: Callable[[int, int], None], n: int, grain: int) -> None:
    """Call ``fn(start, stop)`` on contiguous ranges covering [0, n), on up to
    :func:`local_threads` threads (one range per thread, none shorter than ``grain`` rows:
    below 2·grain the calling thread does it all); ``fn`` writes its rows' results in place."""
    threads = min(local_threads(), n // max(grain, 1))
    if threads <= 1:
        fn(0, n)
        return
    bounds = [n * i // threads for i in range(threads + 1)]
    futures = [_thread_pool(local_threads()).submit(fn, bounds[i], bounds[i + 1]) for i in range(1, threads)]
    fn(bounds[0], bounds[1])
    for f in futures:
        f.result()


@contextlib.contextmanager
def chunk_map(workers: int | None = None, dask: str | None = None):
    """A ``chunk_map`` on the backend asked for (module docstring), closed on exit."""
    if dask is not None:
        from pkmcal.study.backends import dask_client, dask_workers

        client, cluster = dask_client(dask, workers)
        try:
            depth = LOOKAHEAD * dask_workers(client)
            yield ordered_map(lambda fn, chunk: client.submit(fn, chunk, pure=False),
                              lambda fut: fut.result(), depth)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
        return
    if workers is None or workers <= 1:
        yield map
        return
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from pkmcal.study.backends import process_context

    with ProcessPoolExecutor(max_workers=workers, mp_context=process_context()) as pool:
        try:
            yield ordered_map(pool.submit, lambda fut: fut.result(), LOOKAHEAD * workers)
        except BrokenProcessPool:
            raise PkmcalError("a worker process died (out of memory?); run with fewer --workers or a smaller "
                              "--n-candidates") from None


__all__ = ["LOOKAHEAD", "chunk_map", "local_threads", "ordered_map", "run_ranges", "thread_map"]
