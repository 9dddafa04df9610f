"""Running a study end to end: prepare, pilot, run the missing trials, write the results.

:func:`run_study` (what ``pkmcal study`` calls):

1. :func:`pkmcal.study.trial.prepare` plans the candidate pools, the ``once`` selections
   and the held-out poses (in this process);
2. the Dask cluster is reached (``dask``), then the results folder is opened
   (:class:`~pkmcal.study.results.ResultFolder`; its location was tried before step 1): new,
   or ``resume`` — then only the trials missing from its part files are run. A run that
   fails before any trial finished removes what it created (an unreachable scheduler
   creates nothing), so the same command can be run again; once a trial has finished, the
   folder is kept and the message says to continue with ``--resume``;
3. a pilot runs the first missing trial of every campaign here, which times a trial per
   campaign for the batch sizes (:func:`pkmcal.study.backends.batches`) and is kept as
   the first part of that campaign (same bits as in any worker);
4. the backend runs the rest; every finished batch becomes a part file at once, and
   the progress bar shows the trials done and the running median held-out position
   error after calibration;
5. with every trial done: ``trials.csv``, ``summary.csv``, the figures and ``index.html``
   (:mod:`pkmcal.study.plots`, :mod:`pkmcal.study.page`), then the manifest says
   complete. ``run.json`` records the backend, workers and times (the only output whose
   bytes depend on the run, not on the seed).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.progress import Progress
from pkmcal.io.atomic import atomic_write_text, check_output_dir
from pkmcal.study import backends
from pkmcal.study.results import (
    ResultFolder,
    format_summary,
    parse_table,
    summarise,
)
from pkmcal.study.schema import Study
from pkmcal.study.trial import prepare, run_batch


@dataclass(frozen=True)
class StudyRun:
    """What :func:`run_study` did: the folder, the trial columns and the summary rows."""

    path: Path
    columns: dict
    summary: list
    trials_run: int
    seconds: float
    backend: str
    workers: int
    run_seconds: float = float("nan")


class _Progress:
    """tqdm bar of trials done with the running median held-out error (stderr); silent
    when disabled."""

    def __init__(self, total: int, done: int, enabled: bool, names: tuple[str, ...]):
        self.bar = None
        self.values: list[float] = []
        # the position error, or the reading error of a row compared on readings (indicators)
        self.cols = (names.index("heldout_position_rms_mm"), names.index("heldout_reading_rms_mm"))
        self.n_methods = 1
        if enabled:
            from tqdm import tqdm

            tqdm.monitor_interval = 0   # no monitor thread: the local pool forks this process
            self.bar = tqdm(total=total, initial=done, unit="trial", file=sys.stderr, dynamic_ncols=True,
                            desc="study")

    def update(self, trials: int, lines: list[str]) -> None:
        if self.bar is None:
            return
        import csv

        for row in csv.reader(lines):
            cell = next((row[c] for c in self.cols if row[c]), "")
            if cell:
                self.values.append(float(cell))
        if self.values:
            self.bar.set_postfix_str(f"median held-out error {np.median(self.values):.4g} mm", refresh=False)
        self.bar.update(trials)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run_study(study: Study, out: str | Path, *, workers: int | None = None, dask: str | None = None,
              resume: bool = False, progress: "bool | Progress" = False, figures: bool = True,
              client=None) -> StudyRun:
    """Run ``study`` into folder ``out`` (module docstring).

    ``workers``: 1 = in this process; N = a local process pool of N; None = all local cores
    (or, with ``dask``, the cluster's workers). ``dask``: a scheduler address or ``"local"``;
    ``client``: an existing ``distributed.Client`` (tests). ``progress``: True shows the
    study's own bar (trials and the running median error); a :data:`pkmcal.progress.Progress`
    callback is called with (trials done, total) after every batch instead.
    """
    t0 = time.perf_counter()
    if workers is not None and workers < 1:
        raise PkmcalError(f"--workers must be at least 1; got {workers}")
    out = Path(out)
    check_output_dir(out, "-o")
    ctx = prepare(study)
    backend, n_workers, own_client, cluster = "inprocess", 1, None, None
    if dask is not None and client is None:     # before the folder: an unreachable cluster leaves nothing
        client, cluster = backends.dask_client(dask, workers)
        own_client = client
    folder = ResultFolder(out, study.fingerprint(), ctx.names)
    try:
        folder.open(resume, study.name, study.trials)
    except BaseException:
        _close(own_client, cluster)
        raise
    done = folder.done()
    todo = {c.index: [t for t in range(study.trials) if t not in done.get(c.index, ())] for c in ctx.campaigns}
    todo = {c: v for c, v in todo.items() if v}
    n_todo = sum(len(v) for v in todo.values())
    total = study.trials * len(ctx.campaigns)
    callback = progress if callable(progress) else None
    bar = _Progress(total, total - n_todo, progress is True, ctx.names)
    finished = [total - n_todo]

    def on_batch(c, first, last, lines, seconds):
        folder.write_part(c, first, last, lines)
        bar.update(last - first + 1, lines)
        finished[0] += last - first + 1
        if callback is not None:
            callback(finished[0], total)

    t_run = time.perf_counter()
    try:
        # pilot: the first missing trial of every campaign, here (times the batches)
        per_trial: dict[int, float] = {}
        for c in list(todo):
            first = todo[c].pop(0)
            res = run_batch(ctx, c, first, first)
            per_trial[c] = res[4]
            on_batch(*res)
        todo = {c: v for c, v in todo.items() if v}
        if client is not None:
            backend = "dask"
            n_workers = backends.dask_workers(client)
            work = backends.batches(todo, per_trial, n_workers, backends.TARGET_SECONDS_DASK)
            if work:
                backends.run_dask(ctx, work, on_batch, client, folder.fingerprint)
        else:
            n_workers = backends.local_cores() if workers is None else workers
            work = backends.batches(todo, per_trial, n_workers, backends.TARGET_SECONDS)
            if n_workers == 1 or len(work) <= 1:
                backends.run_inprocess(ctx, work, on_batch)
            else:
                backend = "pool"
                backends.run_pool(ctx, work, on_batch, min(n_workers, len(work)))
    except KeyboardInterrupt:
        bar.close()
        if not folder.discard():
            raise PkmcalError(f"interrupted before any trial finished; nothing was kept in '{out}'") from None
        raise PkmcalError(f"interrupted; the finished trials are in '{out}': run the same command with --resume "
                          "to continue") from None
    except PkmcalError as exc:
        bar.close()
        if not folder.discard():
            raise
        raise _resumable(exc, out, "continue") from None
    except BaseException:
        bar.close()
        folder.discard()
        raise
    finally:
        bar.close()
        _close(own_client, cluster)
    run_seconds = time.perf_counter() - t_run
    try:
        return _finish(study, ctx, folder, figures, n_todo, total, backend, n_workers, t0, run_seconds)
    except PkmcalError as exc:      # every trial is done: --resume writes the results without running any
        raise _resumable(exc, out, "write the results") from None


def _finish(study: Study, ctx, folder: ResultFolder, figures: bool, n_todo: int, total: int, backend: str,
            n_workers: int, t0: float, run_seconds: float) -> StudyRun:
    """Step 5 (module docstring): the results of the finished trials in ``folder``."""
    out = folder.path
    lines = folder.read_parts(study.trials)
    if len(lines) != study.trials * ctx.n_configs:
        raise PkmcalError(f"'{out}': {len(lines)} result rows for {study.trials * ctx.n_configs} expected; the part "
                          "files are inconsistent: run again with --resume or choose another -o")
    header = ctx.names
    atomic_write_text(out / "trials.csv", ",".join(header) + "\n" + "".join(x + "\n" for x in lines))
    cols = parse_table(header, lines)
    summary = summarise(cols, absent=ctx.absent_metrics())
    atomic_write_text(out / "summary.csv", format_summary(summary))
    if figures:
        from pkmcal.study.page import write_page

        write_page(study, ctx, cols, summary, out)
    seconds = time.perf_counter() - t0
    atomic_write_text(out / "run.json", json.dumps({
        "backend": backend, "workers": n_workers, "trials_run": n_todo, "trials_total": total,
        "configurations": ctx.n_configs,
        "seconds": seconds, "run_seconds": run_seconds,
        "trials_per_second": n_todo / run_seconds if run_seconds > 0 else None}, indent=2) + "\n")
    folder.write_manifest(study.name, study.trials, complete=True,
                          extra={"files": ["trials.csv", "summary.csv"] + (["index.html"] if figures else [])})
    return StudyRun(out, cols, summary, n_todo, seconds, backend, n_workers, run_seconds)


def _resumable(exc: PkmcalError, out: Path, what: str) -> PkmcalError:
    """``exc`` saying that the finished trials are kept in ``out`` for ``--resume``."""
    if "--resume" in str(exc):
        return exc
    return PkmcalError(f"{exc}; the finished trials are in '{out}': run the same command with --resume to {what}")


def _close(client, cluster) -> None:
    """Close the Dask client and cluster this run started (None: nothing)."""
    if client is not None:
        client.close()
    if cluster is not None:
        cluster.close()


__all__ = ["StudyRun", "run_study"]
