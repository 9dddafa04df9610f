"""The calibration history database: embedded SQLite (stdlib :mod:`sqlite3`), one record per
calibration.

Where: ``--db PATH``, else the environment variable :data:`DB_ENV` (``PKMCAL_HISTORY_DB``),
else :func:`default_db_path`: ``$XDG_DATA_HOME/pkmcal/history.sqlite`` (``~/.local/share/
pkmcal/history.sqlite``), one database per user for every machine that user calibrates: a
print farm or a hexapod maker's test bay runs pkmcal under one account, and its whole fleet is
then in one file without an option on every command (set ``PKMCAL_HISTORY_DB`` in that
account's environment to put it elsewhere). SQLite's write-ahead log needs every writer on
the same host: keep the file on a local disk, not on a network share (sqlite.org/wal.html).

Schema (version :data:`SCHEMA_VERSION`, in table ``schema_version``; a database of a newer
version is refused, an older one migrated by :data:`_MIGRATIONS` in one transaction):

* ``calibrations``: one row per calibration: ``serial`` (the unit), ``model`` (the nominal
  machine it was calibrated from: a fleet is the serials of one model), ``machine`` (the
  calibrated machine's name), ``kind``, ``date`` (of the calibration, UTC ISO 8601),
  ``added``, ``pkmcal_version`` (that made the calibration), ``method``, ``instrument`` (the
  sensor kind) and ``setup`` (the identified setup, JSON), ``n_poses``, ``rms_residual``,
  ``reduced_chi2``, ``covariance_kind`` (which covariance: the record's ``std`` line,
  :attr:`pkmcal.identification.uncertainty.Uncertainty.description`), ``heldout`` (held-out
  figures, JSON, or NULL), ``inputs`` (the input files' paths, sizes and SHA-256, JSON),
  ``source`` and ``source_sha256`` (the calibrated machine file recorded), ``record`` (the
  whole calibration record, JSON), ``parameter_values`` and ``covariance``: the machine
  file's p parameters and p × p parameter covariance in internal units (mm, rad),
  little-endian float64, row-major (exact to the bit: SQLite's REAL turns −0.0 into 0.0), and
  ``null_space`` (the directions the calibration's setup cannot see, JSON, for comparing
  calibrations held in different gauges: :mod:`pkmcal.history.gauge`; NULL when not computed).
* ``parameters``: one row per parameter of a calibration (for SQL queries): ``name``,
  ``value`` (internal units: mm, rad), ``std`` (√Σ_ii; NULL where held), ``unit``
  (``mm``, ``rad``, ...), ``held`` (1 where the covariance row is zero: held by the fit,
  e.g. the gauge).

Writes: each calibration is one ``BEGIN IMMEDIATE`` transaction (its row and its parameter
rows appear together or not at all); the database is in WAL mode with
``synchronous=FULL`` (a committed record survives a power cut) and a busy timeout of
:data:`BUSY_TIMEOUT_S`, so concurrent writers wait for each other instead of failing
(tests/history/test_store.py: several processes writing at once, no record lost).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import sqlite3
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from pkmcal.errors import PkmcalError, one_line

#: Version of the database layout (module docstring).
SCHEMA_VERSION = 1
#: Environment variable naming the database when ``--db`` is not given.
DB_ENV = "PKMCAL_HISTORY_DB"
#: How long a writer waits for another one's transaction (s).
BUSY_TIMEOUT_S = 60.0

_SCHEMA = (
    "CREATE TABLE schema_version (version INTEGER NOT NULL)",
    """CREATE TABLE calibrations (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        serial TEXT NOT NULL, model TEXT NOT NULL, machine TEXT NOT NULL, kind TEXT NOT NULL,
        date TEXT NOT NULL, added TEXT NOT NULL, pkmcal_version TEXT NOT NULL,
        method TEXT, instrument TEXT, setup TEXT, n_poses INTEGER, rms_residual REAL, reduced_chi2 REAL,
        covariance_kind TEXT, heldout TEXT, inputs TEXT NOT NULL, source TEXT, source_sha256 TEXT,
        record TEXT NOT NULL, parameter_values BLOB NOT NULL, covariance BLOB NOT NULL, null_space TEXT)""",
    """CREATE TABLE parameters (
        calibration INTEGER NOT NULL REFERENCES calibrations(id) ON DELETE CASCADE,
        idx INTEGER NOT NULL, name TEXT NOT NULL, value REAL NOT NULL, std REAL, unit TEXT NOT NULL,
        held INTEGER NOT NULL, PRIMARY KEY (calibration, idx))""",
    "CREATE INDEX calibrations_by_serial ON calibrations (serial, date)",
    "CREATE INDEX calibrations_by_model ON calibrations (model, serial)",
)

#: version v → the statements that take a database from v to v + 1 (none yet).
_MIGRATIONS: dict[int, tuple[str, ...]] = {}


def default_db_path() -> Path:
    """``$PKMCAL_HISTORY_DB``, else ``$XDG_DATA_HOME/pkmcal/history.sqlite`` (XDG default
    ``~/.local/share``)."""
    env = os.environ.get(DB_ENV, "").strip()
    if env:
        return Path(env)
    base = os.environ.get("XDG_DATA_HOME", "").strip() or os.path.join(os.path.expanduser("~"), ".local", "share")
    return Path(base) / "pkmcal" / "history.sqlite"


def _now() -> str:
    return datetime.now(tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


@dataclass(frozen=True, eq=False)
class CalibrationRecord:
    """One calibration of one unit: ``values`` (p,) and ``covariance`` (p, p) in internal
    units (mm, rad; ``units`` says which), the covariance the machine file carries (which
    one: ``covariance_kind``); a parameter whose covariance row is zero was held."""

    serial: str
    model: str
    machine: str
    kind: str
    date: str
    pkmcal_version: str
    names: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray
    covariance: np.ndarray
    method: str | None = None
    instrument: str | None = None
    setup: dict | None = None
    n_poses: int | None = None
    rms_residual: float | None = None
    reduced_chi2: float | None = None
    covariance_kind: str | None = None
    heldout: dict | None = None
    inputs: dict = field(default_factory=dict)
    source: str | None = None
    source_sha256: str | None = None
    record: dict = field(default_factory=dict)
    null_space: dict | None = None
    id: int | None = None
    added: str | None = None

    @property
    def held(self) -> np.ndarray:
        """(p,) bool: the parameters whose covariance row and column are zero (held by the fit)."""
        c = self.covariance
        return ~(np.any(c != 0, axis=0) | np.any(c != 0, axis=1))

    @property
    def std(self) -> np.ndarray:
        """(p,) √Σ_ii, internal units (0 where held)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def label(self) -> str:
        return f"#{self.id} ({self.serial}, {self.date})"

    def display(self) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
        """(values, std, units) in file units: rad shown in deg."""
        angle = np.array([u == "rad" for u in self.units])
        scale = np.where(angle, np.rad2deg(1.0), 1.0)
        return self.values * scale, self.std * scale, tuple("deg" if a else u for a, u in zip(angle, self.units))

    def to_dict(self) -> dict:
        """JSON-ready: the record's facts and its parameters in file units (mm, deg) with σ
        (None where held); the covariance in internal units (mm, rad)."""
        v, s, u = self.display()
        held = self.held
        return {
            "id": self.id, "serial": self.serial, "model": self.model, "machine": self.machine, "kind": self.kind,
            "date": self.date, "added": self.added, "pkmcal_version": self.pkmcal_version, "method": self.method,
            "instrument": self.instrument, "n_poses": self.n_poses, "rms_residual": self.rms_residual,
            "reduced_chi2": self.reduced_chi2, "covariance_kind": self.covariance_kind, "heldout": self.heldout,
            "inputs": self.inputs, "source": self.source, "source_sha256": self.source_sha256,
            "parameters": [{"name": n, "value": float(x), "std": None if h else float(e), "unit": un, "held": bool(h)}
                           for n, x, e, un, h in zip(self.names, v, s, u, held)],
            "covariance": {"unit": "internal: mm, rad (the parameters' 'units' before display)",
                           "units": list(self.units), "matrix": self.covariance.tolist()},
        }


def record_from_machine(machine, *, serial: str, source: str | None = None, source_sha256: str | None = None,
                        model: str | None = None, heldout: dict | None = None,
                        inputs: dict | None = None) -> CalibrationRecord:
    """The history record of a calibrated machine written by ``pkmcal identify`` (its
    ``calibration`` record and covariance): ``serial`` names the unit, ``model`` the fleet
    (default: the machine it was calibrated from), ``heldout`` the held-out figures (e.g.
    ``pkmcal verify --json`` of it)."""
    where = f"{source}: " if source else f"machine '{machine.name}': "
    cal = dict(machine.metadata.get("calibration") or {})
    if not cal:
        raise PkmcalError(f"{where}no calibration record: record a calibrated machine file written by 'pkmcal "
                          "identify'")
    if machine.covariance is None:
        raise PkmcalError(f"{where}no parameter covariance: record a calibrated machine file written by 'pkmcal "
                          "identify'")
    if not str(serial).strip():
        raise PkmcalError("--serial '': give the unit's serial number, e.g. --serial KM-0042")
    _check_text("--serial", serial)
    angle = np.array(machine.param_is_angle, dtype=bool)
    units = tuple("rad" if a else str(u) for a, u in zip(angle, machine.param_units))
    setup = machine.metadata.get("setup")
    instrument = None
    if isinstance(setup, dict):
        from pkmcal.io._yaml import dump_yaml, parse_yaml, plain

        setup = plain(parse_yaml(dump_yaml(setup))[0])     # the setup block as plain JSON values
        instrument = setup.get("sensor")

    def num(key):
        v = cal.get(key)
        return None if v is None else float(v)

    return CalibrationRecord(
        serial=str(serial), model=str(model or cal.get("calibrated_from") or machine.name), machine=machine.name,
        kind=machine.kind, date=str(cal.get("date") or _now()), pkmcal_version=str(cal.get("pkmcal_version", "?")),
        names=tuple(machine.param_names), units=units, values=np.array(machine.params, dtype=float),
        covariance=np.array(machine.covariance, dtype=float), method=cal.get("method"), instrument=instrument,
        setup=setup if isinstance(setup, dict) else None,
        n_poses=None if cal.get("n_poses") is None else int(cal["n_poses"]), rms_residual=num("rms_residual"),
        reduced_chi2=num("reduced_chi2"), covariance_kind=cal.get("std"), heldout=heldout,
        inputs=dict(inputs if inputs is not None else cal.get("inputs") or {}), source=source,
        source_sha256=source_sha256, record=cal)


def add_calibrated_file(path: str | os.PathLike, *, serial: str, db: str | os.PathLike | None = None,
                        model: str | None = None, heldout: dict | None = None,
                        allow_duplicate: bool = False) -> CalibrationRecord:
    """Record the calibrated machine file ``path`` (written by ``pkmcal identify``) for unit
    ``serial`` in the history ``db`` (:func:`open_history`); the stored record, with its id.
    The file's SHA-256 is kept (``source_sha256``) beside its calibration record's inputs."""
    from pkmcal.workflow.provenance import input_record
    from pkmcal.io.lookup import load_machine

    shown = one_line(os.fspath(path))
    if not os.path.isfile(path):
        raise PkmcalError(f"{shown}: no such file; give the calibrated machine file written by 'pkmcal identify'")
    machine = load_machine(path)
    src = input_record(path)
    from pkmcal.history.gauge import null_space_of

    rec = record_from_machine(machine, serial=serial, source=os.fspath(path), source_sha256=src["sha256"],
                              model=model, heldout=heldout)
    cal = rec.record
    extra = [str(n) for n in list(cal.get("free") or []) + list(cal.get("gauge") or [])]
    rec = dataclasses.replace(rec, null_space=null_space_of(machine, (path, cal.get("setup")), rec.method, extra,
                                                                 record=cal))
    with open_history(db) as hist:
        new_id = hist.add(rec, allow_duplicate=allow_duplicate)
        return hist.get(new_id)


def record_identified(path: str | os.PathLike, db: str | os.PathLike, serial: str | None,
                      validation=None) -> CalibrationRecord:
    """What ``pkmcal identify --history DB --serial SERIAL`` does after writing ``path``:
    :func:`add_calibrated_file` with the held-out validation of ``--held-out`` (its
    ``to_dict()``) as the record's held-out figures."""
    if serial is None:
        raise PkmcalError("--history records the calibration under the unit's serial number: give --serial SERIAL")
    try:
        return add_calibrated_file(path, serial=serial, db=db,
                                   heldout=None if validation is None else validation.to_dict())
    except PkmcalError as exc:
        raise PkmcalError(f"wrote {path} but did not record it in the history: {exc}; record it with 'pkmcal "
                          f"history add {path} --serial {serial} --db {db}'") from None


def check_history_request(db, serial: str | None, to_stdout: bool) -> None:
    """Refuse ``identify --history`` without ``--serial`` or with the machine file on standard
    output, before anything is computed."""
    if db is None:
        if serial is not None:
            raise PkmcalError("--serial names the unit for --history DB; give both, or neither")
        return
    if serial is None:
        raise PkmcalError("--history records the calibration under the unit's serial number: give --serial SERIAL")
    if to_stdout:
        raise PkmcalError("--history records the calibrated machine file: write it to a file with -o CALIBRATED.yaml")
    _check_text("--serial", serial)
    if os.path.exists(db):                         # a database that cannot take the record: refused before the fit
        open_history(db, create=False).close()
    else:
        _check_new_path(db, explicit=True)


def _check_text(option: str, text: str) -> None:
    from pkmcal.errors import line_problem

    problem = line_problem(str(text), 200)
    if problem:
        raise PkmcalError(f"{option}: {problem}")


class History:
    """An open history database (:func:`open_history`); a context manager that closes it."""

    def __init__(self, path: Path, conn: sqlite3.Connection):
        self.path = path
        self._conn = conn

    def __enter__(self) -> History:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._conn.close()

    def _fail(self, exc: sqlite3.Error, doing: str) -> PkmcalError:
        return _db_error(self.path, exc, doing)

    # -- writing ------------------------------------------------------------------------------
    def add(self, rec: CalibrationRecord, allow_duplicate: bool = False) -> int:
        """Store ``rec`` in one transaction; its id. The same calibrated file (SHA-256)
        recorded again for the same serial is refused unless ``allow_duplicate``."""
        cov = np.ascontiguousarray(rec.covariance, dtype="<f8")
        p = len(rec.names)
        if rec.values.shape != (p,) or cov.shape != (p, p):
            raise ValueError("values and covariance do not match the parameter names")
        held = rec.held
        std = rec.std
        try:
            self._conn.execute("BEGIN IMMEDIATE")
            try:
                if rec.source_sha256 and not allow_duplicate:
                    row = self._conn.execute("SELECT id FROM calibrations WHERE serial = ? AND source_sha256 = ?",
                                             (rec.serial, rec.source_sha256)).fetchone()
                    if row is not None:
                        raise PkmcalError(f"{rec.source or 'this calibration'} is already recorded for serial "
                                          f"'{rec.serial}' as #{row[0]} (same SHA-256); nothing added (give "
                                          "--allow-duplicate to record it again)")
                cur = self._conn.execute(
                    "INSERT INTO calibrations (serial, model, machine, kind, date, added, pkmcal_version, method, "
                    "instrument, setup, n_poses, rms_residual, reduced_chi2, covariance_kind, heldout, inputs, source, "
                    "source_sha256, record, parameter_values, covariance, null_space) VALUES (?, ?, ?, ?, ?, ?, ?, ?, "
                    "?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (rec.serial, rec.model, rec.machine, rec.kind, rec.date, rec.added or _now(), rec.pkmcal_version,
                     rec.method, rec.instrument, _json(rec.setup), rec.n_poses, rec.rms_residual, rec.reduced_chi2,
                     rec.covariance_kind, _json(rec.heldout), _json(rec.inputs), rec.source, rec.source_sha256,
                     _json(rec.record), np.ascontiguousarray(rec.values, dtype="<f8").tobytes(), cov.tobytes(),
                     _json(rec.null_space)))
                new_id = int(cur.lastrowid)
                self._conn.executemany(
                    "INSERT INTO parameters (calibration, idx, name, value, std, unit, held) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?)",
                    [(new_id, i, n, float(v), None if h else float(s), u, int(h))
                     for i, (n, v, s, u, h) in enumerate(zip(rec.names, rec.values, std, rec.units, held))])
            except BaseException:
                with contextlib.suppress(sqlite3.Error):
                    self._conn.execute("ROLLBACK")
                raise
            self._conn.execute("COMMIT")
        except sqlite3.Error as exc:
            raise self._fail(exc, "recording the calibration") from None
        return new_id

    # -- reading ------------------------------------------------------------------------------
    _COLUMNS = ("id, serial, model, machine, kind, date, added, pkmcal_version, method, instrument, setup, n_poses, "
                "rms_residual, reduced_chi2, covariance_kind, heldout, inputs, source, source_sha256, record, "
                "parameter_values, covariance, null_space")

    def _records(self, where: str = "", args: tuple = ()) -> list[CalibrationRecord]:
        try:
            rows = self._conn.execute(f"SELECT {self._COLUMNS} FROM calibrations {where} ORDER BY date, id",
                                      args).fetchall()
            out = []
            for row in rows:
                params = self._conn.execute("SELECT name, value, unit FROM parameters WHERE calibration = ? "
                                            "ORDER BY idx", (row[0],)).fetchall()
                out.append(_record_of(row, params))
            return out
        except sqlite3.Error as exc:
            raise self._fail(exc, "reading the calibrations") from None

    def records(self, serial: str | None = None, model: str | None = None) -> list[CalibrationRecord]:
        """The calibrations (of ``serial``, of ``model``), oldest first (date, then id)."""
        cond, args = [], []
        if serial is not None:
            cond.append("serial = ?")
            args.append(serial)
        if model is not None:
            cond.append("model = ?")
            args.append(model)
        return self._records("WHERE " + " AND ".join(cond) if cond else "", tuple(args))

    def get(self, ref: str | int) -> CalibrationRecord:
        """A calibration by reference: its id (``12`` or ``#12``), a serial (its latest
        calibration) or ``SERIAL~N`` (the N-th before its latest, as git counts; a serial
        made of digits only is named ``SERIAL~0``)."""
        text = str(ref).strip()
        if text.lstrip("#").isdigit():
            found = self._records("WHERE id = ?", (int(text.lstrip("#")),))
            if found:
                return found[0]
            raise PkmcalError(f"no calibration #{text.lstrip('#')} in {self.path}; 'pkmcal history list' shows them")
        serial, back = text, 0
        if "~" in text:
            serial, _, n = text.rpartition("~")
            if not n.isdigit():
                raise PkmcalError(f"calibration '{one_line(text)}': write SERIAL~N with N a whole number (SERIAL~1 "
                                  "is the calibration before the latest)")
            back = int(n)
        recs = self.records(serial=serial)
        if not recs:
            raise PkmcalError(f"no calibration of serial '{one_line(serial)}' in {self.path}; give an id or a serial "
                              "that 'pkmcal history list' shows")
        if back >= len(recs):
            raise PkmcalError(f"serial '{one_line(serial)}' has {len(recs)} calibration(s); {one_line(text)} asks "
                              f"for the one {back} before the latest")
        return recs[-1 - back]

    def latest_per_serial(self, model: str | None = None) -> list[CalibrationRecord]:
        """Each serial's latest calibration (of ``model``), by serial."""
        latest: dict[str, CalibrationRecord] = {}
        for r in self.records(model=model):
            latest[r.serial] = r
        return [latest[s] for s in sorted(latest)]


def _json(obj) -> str | None:
    from pkmcal.io.json_out import json_text

    return None if obj is None else json_text(obj, indent=None, sort_keys=True)


def _record_of(row, params) -> CalibrationRecord:
    (rid, serial, model, machine, kind, date, added, version, method, instrument, setup, n_poses, rms, chi2,
     cov_kind, heldout, inputs, source, sha, record, values, cov, null_space) = row
    p = len(params)
    return CalibrationRecord(
        serial=serial, model=model, machine=machine, kind=kind, date=date, pkmcal_version=version,
        names=tuple(r[0] for r in params), units=tuple(r[2] for r in params),
        values=np.frombuffer(values, dtype="<f8").astype(float),
        covariance=np.frombuffer(cov, dtype="<f8").reshape(p, p).astype(float), method=method,
        instrument=instrument, setup=None if setup is None else json.loads(setup), n_poses=n_poses,
        rms_residual=rms, reduced_chi2=chi2, covariance_kind=cov_kind,
        heldout=None if heldout is None else json.loads(heldout), inputs=json.loads(inputs), source=source,
        source_sha256=sha, record=json.loads(record), null_space=None if null_space is None else json.loads(null_space),
        id=int(rid), added=added)


def _db_error(path, exc: BaseException, doing: str) -> PkmcalError:
    text = str(exc)
    if "not a database" in text or "malformed" in text:
        return PkmcalError(f"{path}: not a readable pkmcal history database ({text}) while {doing}; give another "
                           "--db, or restore the file from a backup")
    if "locked" in text or "busy" in text:
        return PkmcalError(f"{path}: the database stayed locked by another writer for {BUSY_TIMEOUT_S:g} s while "
                           f"{doing}; try again when the other pkmcal command has finished")
    if "readonly" in text or "read-only" in text:
        return PkmcalError(f"{path}: the database or its folder is read-only ({text}) while {doing}; give a --db "
                           "you can write")
    return PkmcalError(f"{path}: {text} while {doing}; check the --db path (a file in a folder you can write)")


def _check_new_path(path, explicit: bool) -> bool:
    """Refuse a database path that cannot be one (empty, ending in '/', a folder, an explicit
    path in a missing folder); whether it exists."""
    text = os.fspath(path)
    shown = one_line(text)
    if not text.strip():
        raise PkmcalError("--db '': give the history database's file name, e.g. --db history.sqlite")
    if text.endswith(("/", os.sep)) or os.path.isdir(text):
        raise PkmcalError(f"--db {shown} is a folder; give a file name, e.g. {shown.rstrip('/')}/history.sqlite")
    if os.path.exists(text):
        return True
    parent = os.path.dirname(text) or "."
    if explicit and not os.path.isdir(parent):
        raise PkmcalError(f"--db {shown}: the folder {one_line(parent)} does not exist; create it or give another "
                          "path")
    return False


def open_history(path: str | os.PathLike | None = None, create: bool = True) -> History:
    """Open (``create``: and make if missing, with its folder for the default path) the
    history database ``path`` (None: :func:`default_db_path`); checks its schema version and
    migrates an older one."""
    explicit = path is not None
    db = Path(path) if explicit else default_db_path()
    shown = one_line(str(db))
    exists = _check_new_path(path if explicit else db, explicit)
    if not exists:
        if not create:
            hint = "" if explicit else f" (or give --db; {DB_ENV} sets the default)"
            raise PkmcalError(f"no calibration history at {shown}: record a calibration first with 'pkmcal history "
                              f"add CALIBRATED.yaml --serial SERIAL'{hint}")
        if not db.parent.exists():
            try:
                db.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise PkmcalError(f"cannot create the folder of the history database {shown} ({exc.strerror}); "
                                  f"give --db PATH or set {DB_ENV}") from None
    elif not os.path.isfile(db):
        raise PkmcalError(f"--db {shown} is not a regular file; give a database file")
    try:
        conn = sqlite3.connect(os.fspath(db), timeout=BUSY_TIMEOUT_S, isolation_level=None)
    except sqlite3.Error as exc:
        raise _db_error(shown, exc, "opening it") from None
    try:
        conn.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
        conn.execute("PRAGMA foreign_keys = ON")
        _ensure_schema(conn, shown)
        if conn.execute("PRAGMA journal_mode").fetchone()[0].lower() != "wal":
            conn.execute("PRAGMA journal_mode = WAL")
        conn.execute("PRAGMA synchronous = FULL")
    except sqlite3.Error as exc:
        conn.close()
        raise _db_error(shown, exc, "opening it") from None
    except BaseException:
        conn.close()
        raise
    return History(db, conn)


def _schema_state(conn: sqlite3.Connection, shown: str) -> int | None:
    """The database's schema version; None for an empty database (refused: another
    program's database, a damaged or newer one)."""
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if not tables:
        return None
    if "schema_version" not in tables:
        raise PkmcalError(f"{shown} is an SQLite database but not a pkmcal history (no schema_version table); "
                          "give another --db")
    row = conn.execute("SELECT version FROM schema_version").fetchone()
    version = None if row is None else row[0]
    if not isinstance(version, int):
        raise PkmcalError(f"{shown}: its schema_version table holds no version; the file is damaged: restore it "
                          "from a backup or give another --db")
    if version > SCHEMA_VERSION:
        raise PkmcalError(f"{shown} was written by a newer pkmcal (history schema {version}, this pkmcal reads up "
                          f"to {SCHEMA_VERSION}); upgrade pkmcal")
    return version


def _ensure_schema(conn: sqlite3.Connection, shown: str) -> None:
    """Check the version of the database; create the tables in an empty one and migrate an
    older one in one ``BEGIN IMMEDIATE`` transaction (two processes creating the same new
    database: one creates, the other then finds it made). An up-to-date database is only
    read: a reader neither waits for a writer nor needs write access."""
    if _schema_state(conn, shown) == SCHEMA_VERSION:
        return
    conn.execute("BEGIN IMMEDIATE")
    try:
        version = _schema_state(conn, shown)
        if version is None:
            for stmt in _SCHEMA:
                conn.execute(stmt)
            conn.execute("INSERT INTO schema_version (version) VALUES (?)", (SCHEMA_VERSION,))
        else:
            while version < SCHEMA_VERSION:
                for stmt in _MIGRATIONS[version]:
                    conn.execute(stmt)
                version += 1
                conn.execute("UPDATE schema_version SET version = ?", (version,))
    except BaseException:
        with contextlib.suppress(sqlite3.Error):
            conn.execute("ROLLBACK")
        raise
    conn.execute("COMMIT")


__all__ = ["BUSY_TIMEOUT_S", "DB_ENV", "SCHEMA_VERSION", "CalibrationRecord", "History", "add_calibrated_file",
           "check_history_request", "default_db_path", "open_history", "record_from_machine", "record_identified"]
