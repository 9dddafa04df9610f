"""pkmcal study on a real dask.distributed LocalCluster: the same bits as in one process,
and no finished trial lost when a worker is killed mid-study.

The cluster has 2 single-threaded worker *processes* (``processes=True``): that is how a
real cluster runs the trials (each worker its own interpreter, context and results
pickled across), and a worker can only be killed as a process (killing a thread worker
would end the test itself). Needs ``pip install 'pkmcal[dask]'``.
"""

from __future__ import annotations

import os
import signal
import textwrap

import pytest

distributed = pytest.importorskip("distributed")

from pkmcal.study import backends, load_study, run_study  # noqa: E402
from pkmcal.study.results import ResultFolder  # noqa: E402

STUDY = """\
name: dask-small
seed: 11
trials: 6
machines:
  - nominal: stewart-prototype
    errors:
      - {parameters: "*", distribution: uniform, size: 0.3}
    ignore_limits: [leg_collision]
setups:
  - {setup: full-pose-paper1, label: full-pose}
plans:
  - {algorithm: corners, poses: [13, 15]}
  - {algorithm: random, poses: [20], candidates: 300}
methods: [auto]
heldout: {poses: 6}
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    p = tmp_path_factory.mktemp("dask") / "study.yaml"
    p.write_text(textwrap.dedent(STUDY), encoding="utf-8")
    return load_study(p)


@pytest.fixture(scope="module")
def reference(study, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "r"
    run_study(study, out, workers=1, figures=False)
    return (out / "trials.csv").read_bytes()


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def test_dask_cluster_gives_the_same_bits(study, reference, client, tmp_path, monkeypatch):
    monkeypatch.setattr(backends, "TARGET_SECONDS_DASK", 1e-9)   # one trial per task: many tasks
    res = run_study(study, tmp_path / "r", client=client, figures=False)
    assert res.backend == "dask" and res.workers == 2
    assert (tmp_path / "r" / "trials.csv").read_bytes() == reference


def test_killed_worker_loses_no_finished_trial(study, reference, client, tmp_path, monkeypatch):
    """SIGKILL one of the two worker processes after the fifth finished batch: its running
    and queued batches are re-run elsewhere, the finished ones are already on disk, and
    the results equal the in-process run."""
    monkeypatch.setattr(backends, "TARGET_SECONDS_DASK", 1e-9)
    write = ResultFolder.write_part
    killed = []

    def write_and_kill(self, *args):
        write(self, *args)
        n = len(list((self.path / "parts").iterdir()))
        if n == 5 and not killed:
            busy = [w for w, tasks in client.processing().items() if tasks] or list(client.scheduler_info()["workers"])
            killed.append(busy[0])
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            os.kill(pid, signal.SIGKILL)

    monkeypatch.setattr(ResultFolder, "write_part", write_and_kill)
    run_study(study, tmp_path / "r", client=client, figures=False)
    assert killed
    assert killed[0] not in client.scheduler_info()["workers"]      # that process is gone
    assert (tmp_path / "r" / "trials.csv").read_bytes() == reference
