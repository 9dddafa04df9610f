"""The history database: a record's round trip (parameters and covariance bit for bit, from
the calibrated machine file through SQLite), several processes writing at once without
losing a record, and the user errors of a bad or foreign database (one line, exit code 2)."""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import sqlite3

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from helpers import assert_user_error

import pkmcal
from pkmcal.cli.main import cli
from pkmcal.history.store import (
    SCHEMA_VERSION,
    CalibrationRecord,
    add_calibrated_file,
    open_history,
    record_from_machine,
)


def _calibrated_file(tmp_path, seed: int, name="cal.yaml"):
    """A calibrated hexapod file: random parameters and a random covariance with a held
    gauge (zero rows), and a calibration record."""
    rng = np.random.default_rng(seed)
    m = pkmcal.load_machine("stewart-prototype")
    p = len(m.param_names)
    a = rng.normal(size=(p, p)) * 10.0 ** rng.uniform(-4, -1, size=p)[:, None]
    cov = a @ a.T
    held = [0, 1, 3]            # b1.x, b1.y, a1.x
    cov[held, :] = 0.0
    cov[:, held] = 0.0
    gains = [i for i, n in enumerate(m.param_names) if n.startswith("gain")]
    cov[gains, :] = 0.0
    cov[:, gains] = 0.0
    params = m.params + np.where(np.isin(np.arange(p), held + gains), 0.0, rng.normal(0, 0.1, size=p))
    cal = dataclasses.replace(m.with_params(params, name=f"hexapod-{seed}"), covariance=cov, metadata={
        "calibration": {"name": f"hexapod-{seed}", "calibrated_from": "stewart-prototype",
                        "date": f"2026-11-{seed % 28 + 1:02d}T10:00:00Z", "pkmcal_version": "0.1.0",
                        "method": "ik-residual", "n_poses": 30, "rms_residual": 0.01, "reduced_chi2": 1.1,
                        "std": "a-priori covariance", "inputs": {"machine": {"builtin": "stewart-prototype"}},
                        "gauge": ["b1.x", "b1.y", "a1.x"]}})
    path = tmp_path / name
    pkmcal.save_machine(cal, path)
    return path


def test_a_record_round_trips_exactly(tmp_path):
    path = _calibrated_file(tmp_path, 3)
    loaded = pkmcal.load_machine(path)
    rec = add_calibrated_file(path, serial="HX-3", db=tmp_path / "h.sqlite")
    assert rec.id == 1 and rec.serial == "HX-3" and rec.model == "stewart-prototype"
    assert rec.names == tuple(loaded.param_names)
    assert np.array_equal(rec.values, loaded.params)                # bit for bit
    assert np.array_equal(rec.covariance, loaded.covariance)
    assert [n for n, h in zip(rec.names, rec.held) if h] == ["b1.x", "b1.y", "a1.x"] + \
        [n for n in rec.names if n.startswith("gain")]
    assert rec.date == "2026-11-04T10:00:00Z" and rec.pkmcal_version == "0.1.0"
    assert len(rec.source_sha256) == 64
    with open_history(tmp_path / "h.sqlite") as hist:             # and read again by a new connection
        again = hist.get("HX-3")
    assert np.array_equal(again.values, loaded.params) and np.array_equal(again.covariance, loaded.covariance)
    # the parameters table is queryable with plain SQL
    con = sqlite3.connect(tmp_path / "h.sqlite")
    (v,) = con.execute("SELECT value FROM parameters WHERE calibration = 1 AND name = 'L0_3'").fetchone()
    assert v == loaded.params[list(loaded.param_names).index("L0_3")]
    assert con.execute("SELECT version FROM schema_version").fetchone() == (SCHEMA_VERSION,)
    assert con.execute("PRAGMA journal_mode").fetchone() == ("wal",)
    con.close()


def test_the_same_file_is_not_recorded_twice_by_mistake(tmp_path):
    path = _calibrated_file(tmp_path, 4)
    db = tmp_path / "h.sqlite"
    add_calibrated_file(path, serial="HX-4", db=db)
    res = CliRunner().invoke(cli, ["history", "add", str(path), "--serial", "HX-4", "--db", str(db)])
    assert_user_error(res, "already recorded", "#1", "--allow-duplicate")
    res = CliRunner().invoke(cli, ["history", "add", str(path), "--serial", "HX-4", "--db", str(db),
                                   "--allow-duplicate"])
    assert res.exit_code == 0, res.output
    with open_history(db) as hist:
        assert [r.id for r in hist.records()] == [1, 2]


def _synthetic(writer: int, k: int) -> CalibrationRecord:
    p = 4
    rng = np.random.default_rng(1000 * writer + k)
    a = rng.normal(size=(p, p))
    return CalibrationRecord(serial=f"W{writer}", model="m", machine="m", kind="test",
                             date=f"2026-12-01T00:{k // 60:02d}:{k % 60:02d}Z", pkmcal_version="t",
                             names=("a", "b", "c", "d"), units=("mm",) * p, values=rng.normal(size=p),
                             covariance=a @ a.T, record={"writer": writer, "k": k})


def _writer(db, writer, n, barrier):
    barrier.wait()                                  # every process starts writing at the same moment
    for k in range(n):
        with open_history(db) as hist:              # a new connection per record, as separate commands do
            hist.add(_synthetic(writer, k))


def test_several_processes_writing_at_once_lose_no_record(tmp_path):
    db = tmp_path / "new.sqlite"                    # created by the writers themselves, concurrently
    n_proc, n_each = 4, 15
    ctx = multiprocessing.get_context("spawn")     # no fork of a threaded test process
    barrier = ctx.Barrier(n_proc)
    procs = [ctx.Process(target=_writer, args=(db, w, n_each, barrier)) for w in range(n_proc)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0] * n_proc
    with open_history(db, create=False) as hist:
        recs = hist.records()
    assert len(recs) == n_proc * n_each
    assert sorted((r.record["writer"], r.record["k"]) for r in recs) == \
        [(w, k) for w in range(n_proc) for k in range(n_each)]
    for r in recs:                                   # every record whole, parameters with it
        want = _synthetic(r.record["writer"], r.record["k"])
        assert np.array_equal(r.values, want.values) and np.array_equal(r.covariance, want.covariance)
    assert len({r.id for r in recs}) == len(recs)


def test_record_from_a_machine_without_calibration_record_is_refused():
    from pkmcal.errors import PkmcalError

    with pytest.raises(PkmcalError, match="no calibration record"):
        record_from_machine(pkmcal.load_machine("kossel-mini"), serial="X")


@pytest.mark.parametrize("case", ["missing-folder", "folder", "slash", "corrupt", "foreign", "newer", "absent"])
def test_a_bad_database_is_a_one_line_user_error(tmp_path, case):
    path = _calibrated_file(tmp_path, 5)
    db = tmp_path / "h.sqlite"
    command = ["history", "add", str(path), "--serial", "S"]
    expect = {}
    if case == "missing-folder":
        db = tmp_path / "no" / "h.sqlite"
        expect = ("does not exist",)
    elif case == "folder":
        db = tmp_path
        expect = ("is a folder",)
    elif case == "slash":
        db = str(tmp_path / "new") + "/"
        expect = ("is a folder",)
    elif case == "corrupt":
        db.write_bytes(b"this is not SQLite at all\n" * 200)
        expect = ("not a readable pkmcal history database",)
    elif case == "foreign":
        con = sqlite3.connect(db)
        con.execute("CREATE TABLE orders (id INTEGER)")
        con.commit()
        con.close()
        expect = ("not a pkmcal history",)
    elif case == "newer":
        add_calibrated_file(path, serial="S0", db=db)
        con = sqlite3.connect(db)
        con.execute("UPDATE schema_version SET version = ?", (SCHEMA_VERSION + 1,))
        con.commit()
        con.close()
        expect = ("newer pkmcal", "upgrade")
    elif case == "absent":
        command = ["history", "list"]
        expect = ("no calibration history",)
    before = None if case == "slash" or not db.is_file() else db.read_bytes()
    res = CliRunner().invoke(cli, command + ["--db", str(db)])
    assert_user_error(res, *expect)
    if before is not None:
        assert db.read_bytes() == before            # an input is never damaged
    if case in ("absent", "slash"):
        assert not os.path.exists(db)


def test_the_default_database_comes_from_the_environment(tmp_path, monkeypatch):
    from pkmcal.history.store import default_db_path

    monkeypatch.setenv("PKMCAL_HISTORY_DB", str(tmp_path / "farm.sqlite"))
    assert default_db_path() == tmp_path / "farm.sqlite"
    monkeypatch.delenv("PKMCAL_HISTORY_DB")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    assert default_db_path() == tmp_path / "data" / "pkmcal" / "history.sqlite"
    path = _calibrated_file(tmp_path, 6)
    res = CliRunner().invoke(cli, ["history", "add", str(path), "--serial", "S", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["db"] == str(tmp_path / "data" / "pkmcal" / "history.sqlite")
    assert (tmp_path / "data" / "pkmcal" / "history.sqlite").is_file()


def test_an_older_schema_is_migrated_in_place(tmp_path, monkeypatch):
    """The migration mechanism: a version-1 database opened by a pkmcal whose schema is 2
    (a column added) is migrated, its records kept, and opened again as version 2."""
    from pkmcal.history import store

    db = tmp_path / "h.sqlite"
    first = add_calibrated_file(_calibrated_file(tmp_path, 7), serial="HX-7", db=db)
    monkeypatch.setattr(store, "SCHEMA_VERSION", 2)
    monkeypatch.setattr(store, "_MIGRATIONS", {1: ("ALTER TABLE calibrations ADD COLUMN note TEXT",)})
    with store.open_history(db, create=False) as hist:
        again = hist.get("HX-7")
    assert np.array_equal(again.covariance, first.covariance)
    con = sqlite3.connect(db)
    assert con.execute("SELECT version FROM schema_version").fetchall() == [(2,)]
    assert "note" in [r[1] for r in con.execute("PRAGMA table_info(calibrations)")]
    con.close()


def test_a_serial_of_digits_is_named_with_a_tilde(tmp_path):
    db = tmp_path / "h.sqlite"
    add_calibrated_file(_calibrated_file(tmp_path, 8, "a.yaml"), serial="A", db=db)
    add_calibrated_file(_calibrated_file(tmp_path, 9, "b.yaml"), serial="1234", db=db)
    with open_history(db) as hist:
        assert hist.get("1").serial == "A" and hist.get("#2").serial == "1234"
        assert hist.get("1234~0").id == 2


def test_a_reader_does_not_wait_for_a_writer(tmp_path, monkeypatch):
    """WAL mode, and an up-to-date database only read when opened: 'list' while another
    process holds a write transaction answers at once (here with a busy timeout of 0)."""
    from pkmcal.history import store

    db = tmp_path / "h.sqlite"
    add_calibrated_file(_calibrated_file(tmp_path, 10), serial="HX", db=db)
    writer = sqlite3.connect(db, isolation_level=None)
    writer.execute("BEGIN IMMEDIATE")
    writer.execute("UPDATE calibrations SET serial = 'changing'")
    monkeypatch.setattr(store, "BUSY_TIMEOUT_S", 0.0)
    with store.open_history(db, create=False) as hist:
        assert [r.serial for r in hist.records()] == ["HX"]      # the last committed state
    writer.execute("ROLLBACK")
    writer.close()


_FLOATS = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=40, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.data(), p=st.integers(1, 8), serial=st.text(min_size=1, max_size=30).filter(lambda t: t.isprintable()
                                                                                            and t.strip()))
def test_any_record_round_trips_bit_for_bit(tmp_path_factory, data, p, serial):
    """Values (−0.0, subnormals, 1e308 included), covariance, serial text: stored and read
    back to the bit."""
    values = np.array(data.draw(st.lists(_FLOATS, min_size=p, max_size=p)))
    cov = np.array(data.draw(st.lists(_FLOATS, min_size=p * p, max_size=p * p))).reshape(p, p)
    rec = CalibrationRecord(serial=serial, model="m", machine="m", kind="test", date="2026-12-01T00:00:00Z",
                            pkmcal_version="t", names=tuple(f"q{i}" for i in range(p)), units=("mm",) * p,
                            values=values, covariance=cov, record={"k": serial})
    db = tmp_path_factory.mktemp("rt") / "h.sqlite"
    with open_history(db) as hist:
        new_id = hist.add(rec)
    with open_history(db, create=False) as hist:
        back = hist.get(new_id)
    assert back.values.tobytes() == values.astype("<f8").tobytes()
    assert back.covariance.tobytes() == cov.astype("<f8").tobytes()
    assert back.serial == serial and back.record == {"k": serial} and back.names == rec.names
