"""Where a plan's chunks run: in this process, on local worker processes, or on a Dask cluster.

A plan checks its candidates and computes their planning blocks chunk by chunk
(:func:`~pkmcal.planning.candidates.generate_candidates`,
:func:`~pkmcal.planning.plan.candidate_blocks`), each chunk a picklable unit of work mapped
by a ``chunk_map(fn, chunks)`` that yields the results in order. :func:`chunk_map` opens
one on the backends of ``pkmcal study`` (:mod:`pkmcal.study.backends`: the same core count
and the same Dask client):

* in this process (``workers`` None or 1, no ``dask``): :data:`pkmcal.parallel.IN_PROCESS`,
  the built-in lazy ``map``;
* ``workers`` N > 1: a :class:`concurrent.futures.ProcessPoolExecutor` of N processes,
  forked on Linux (the workers start with the modules and the compiled kernels loaded), spawned
  elsewhere;
* ``dask``: a scheduler address, or ``"local"`` for a LocalCluster of ``workers`` (default: all
  local cores) single-threaded processes.

Work that needs no pickling — the planning blocks of the accepted candidates, the
selection's passes over all of them — runs in this process on its threads
(:func:`pkmcal.parallel.thread_map`, :func:`pkmcal.parallel.run_rows`): NumPy's large operations and the compiled
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

from pkmcal.errors import PkmcalError
from pkmcal.parallel import IN_PROCESS, LOOKAHEAD, ordered_map

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
        yield IN_PROCESS
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


__all__ = ["LOOKAHEAD", "chunk_map", "ordered_map"]
