"""Where the trials run: in this process, on all local cores, or on a Dask cluster.

Work is cut into batches (one campaign, a run of consecutive trials): :func:`batches`
sizes them from a measured trial time so that each task runs for about
:data:`TARGET_SECONDS` (local pool) or :data:`TARGET_SECONDS_DASK` (Dask), which keeps the
per-task cost (pickling the lines back, scheduling: ~1 ms locally, a few ms with Dask)
well under 5 % of the time, while leaving at least four batches per worker for load
balance. Batching never changes the numbers: each trial draws from its own seed
(:mod:`pkmcal.study.trial`).

* ``inprocess``: a loop (``--workers 1``).
* ``pool``: :class:`concurrent.futures.ProcessPoolExecutor`. On Linux the workers are
  forked from this process, so they start warm: modules imported, numba kernels loaded,
  the :class:`~pkmcal.study.trial.Context` already in memory (a spawned worker needs
  1.5–2.5 s to import pkmcal and load the kernels on this 2-core machine, which halved the
  parallel efficiency of a 1000-trial study). Forking is safe here: the parent holds no
  lock-owning threads at that moment (no progress-bar monitor thread, no Dask client;
  OpenBLAS re-initialises its thread pool in the child). Elsewhere the ``spawn`` start
  method is used and the context is pickled once per worker through the initializer.
* ``dask``: ``dask.distributed`` (optional dependency ``pkmcal[dask]``), a scheduler
  address or ``"local"`` for a :class:`distributed.LocalCluster` of single-threaded worker
  processes. Batches are futures; each finished one is written as soon as it arrives, and
  the scheduler re-runs the batches of a worker that dies (nothing finished is lost).
  The context travels as one pickled ``bytes`` argument per task and is unpickled once
  per worker process (:func:`_context_from_bytes`).

Each finished batch goes to ``on_batch(campaign, first, last, lines, seconds)`` in the
calling process, in completion order; the results folder orders them.
"""

from __future__ import annotations

import math
import os
import pickle
import sys
from typing import Callable

from pkmcal.errors import PkmcalError
from pkmcal.study.trial import Context, run_batch

TARGET_SECONDS = 0.5
TARGET_SECONDS_DASK = 2.0
MAX_BATCH = 5000
OnBatch = Callable[[int, int, int, list, float], None]


def local_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def batches(todo: dict[int, list[int]], seconds_per_trial: dict[int, float], workers: int,
            target: float) -> list[tuple[int, int, int]]:
    """``(campaign, first, last)`` runs of consecutive missing trials, each about
    ``target`` seconds long, at least ``4 × workers`` batches in all when there is enough
    work, in campaign order."""
    total = sum(len(v) for v in todo.values())
    cap = max(1, math.ceil(total / (4 * max(1, workers))))
    out = []
    for c, trials in sorted(todo.items()):
        size = max(1, min(MAX_BATCH, cap, math.ceil(target / max(seconds_per_trial.get(c, 0.01), 1e-6))))
        run: list[int] = []
        for t in sorted(trials):
            if run and (t != run[-1] + 1 or len(run) >= size):
                out.append((c, run[0], run[-1]))
                run = []
            run.append(t)
        if run:
            out.append((c, run[0], run[-1]))
    return out


def run_inprocess(ctx: Context, work: list[tuple[int, int, int]], on_batch: OnBatch) -> None:
    for c, first, last in work:
        on_batch(*run_batch(ctx, c, first, last))


# -- process pool ------------------------------------------------------------------------

_WORKER_CONTEXT: Context | None = None


def _init_worker(data: bytes) -> None:
    global _WORKER_CONTEXT
    _WORKER_CONTEXT = pickle.loads(data)


def _pool_batch(campaign: int, first: int, last: int):
    return run_batch(_WORKER_CONTEXT, campaign, first, last)


def process_context():
    """The multiprocessing context of the process pools (module docstring): fork on Linux
    (workers inherit the parent's imports and data), spawn elsewhere."""
    import multiprocessing

    return multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")


def run_pool(ctx: Context, work: list[tuple[int, int, int]], on_batch: OnBatch, workers: int) -> None:
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    global _WORKER_CONTEXT
    mp = process_context()
    if mp.get_start_method() == "fork":
        init, args = None, ()
        _WORKER_CONTEXT = ctx
    else:
        init, args = _init_worker, (pickle.dumps(ctx),)
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp, initializer=init, initargs=args) as pool:
        pending = {pool.submit(_pool_batch, *w) for w in work}
        try:
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    on_batch(*fut.result())
        except BrokenProcessPool:
            raise PkmcalError("a worker process died; the finished trials are saved: run the same command with "
                              "--resume to continue") from None
        finally:
            for fut in pending:
                fut.cancel()
            _WORKER_CONTEXT = None


# -- dask ----------------------------------------------------------------------------------

_DASK_CONTEXTS: dict[int, Context] = {}


def _context_from_bytes(data: bytes) -> Context:
    key = hash(data)
    ctx = _DASK_CONTEXTS.get(key)
    if ctx is None:
        _DASK_CONTEXTS.clear()
        ctx = _DASK_CONTEXTS[key] = pickle.loads(data)
    return ctx


def _dask_batch(data: bytes, campaign: int, first: int, last: int):
    return run_batch(_context_from_bytes(data), campaign, first, last)


def dask_client(address: str, workers: int | None):
    """A :class:`distributed.Client` for ``address`` or, for ``"local"``, a new
    :class:`distributed.LocalCluster` of ``workers`` single-threaded processes."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise PkmcalError("--dask needs dask.distributed: pip install 'pkmcal[dask]'") from None
    if address == "local":
        cluster = LocalCluster(n_workers=workers or local_cores(), threads_per_worker=1, processes=True,
                               dashboard_address=":0")
        return Client(cluster), cluster
    try:
        return Client(address, timeout="20s"), None
    except (OSError, TimeoutError) as exc:
        raise PkmcalError(f"cannot reach the Dask scheduler at '{address}': {exc}; start one with "
                          "'dask scheduler' or use --dask local") from None


def run_dask(ctx: Context, work: list[tuple[int, int, int]], on_batch: OnBatch, client, fingerprint: str) -> None:
    from distributed import as_completed

    data = pickle.dumps(ctx)
    futures = [client.submit(_dask_batch, data, c, first, last, pure=False,
                             key=f"pkmcal-study-{fingerprint[:12]}-c{c}-t{first}-{last}")
               for c, first, last in work]
    try:
        for fut in as_completed(futures):
            on_batch(*fut.result())
            fut.release()
    finally:
        for fut in futures:
            fut.cancel()


def dask_workers(client) -> int:
    return max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()))


__all__ = ["batches", "dask_client", "local_cores", "run_dask", "run_inprocess", "run_pool"]
