"""``pkmcal history``: every calibration of a fleet kept (:mod:`pkmcal.history`).

* ``add CALIBRATED.yaml --serial S``: record a calibrated machine file of ``pkmcal identify``
  (its calibration record, parameters and covariance, the file's SHA-256; ``--verification
  VERIFY.json``: the held-out figures of ``pkmcal verify --json``).
* ``list``, ``show REF``: the records; ``compare A B``: whether two calibrations differ
  beyond their combined uncertainty (z per parameter, joint χ²; :mod:`pkmcal.history.stats`);
  ``fleet``: units outside the spread of their fleet; ``plot SERIAL -o FILE``: a unit's
  parameters over time with σ bars.

The database: ``--db PATH``, else ``$PKMCAL_HISTORY_DB``, else
``~/.local/share/pkmcal/history.sqlite`` (:mod:`pkmcal.history.store`). A calibration is
named by its id (``12``), a serial (its latest) or ``SERIAL~N`` (N before the latest).
"""

from __future__ import annotations

import json
import os

import click

from pkmcal.cli.option_types import FiniteFloat
from pkmcal.cli.options import examples, option
from pkmcal.errors import InputFileError, PkmcalError, one_line


def _db_option(command):
    return click.option("--db", "db", metavar="PATH",
                        help="History database (SQLite). Default: $PKMCAL_HISTORY_DB, else "
                             "~/.local/share/pkmcal/history.sqlite ($XDG_DATA_HOME/pkmcal/history.sqlite).")(command)


def _json_option(command):
    return click.option("--json", "as_json", is_flag=True, help="Print JSON.")(command)


def _alpha_option(command):
    return click.option("--alpha", type=FiniteFloat(min=0.0, max=1.0, min_open=True, max_open=True), default=1e-3,
                        show_default=True, help="False-alarm probability of each test when nothing changed "
                                                "(family-wise: Bonferroni over the parameters).")(command)


def _print_json(obj) -> None:
    from pkmcal.io.json_out import json_text

    click.echo(json_text(obj))


def _read_heldout(path: str) -> dict:
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except OSError as exc:
        raise PkmcalError(f"--verification {one_line(path)}: {exc.strerror}; give the JSON that 'pkmcal verify ... --json' "
                          "wrote") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputFileError(path, f"not JSON ({exc.msg}); give the output of 'pkmcal verify ... --json'",
                             line=exc.lineno) from None
    if not isinstance(doc, dict):
        raise InputFileError(path, "not a JSON object; give the output of 'pkmcal verify ... --json'")
    return doc


@click.group("history", epilog=examples(
    "pkmcal history add calibrated.yaml --serial KM-0042 --db farm.sqlite",
    "pkmcal history list --db farm.sqlite",
    "pkmcal history show KM-0042 --db farm.sqlite",
    "pkmcal history fleet --db farm.sqlite",
    "pkmcal history plot KM-0042 -o km-0042.png --db farm.sqlite"))
def history_group() -> None:
    """Keep every calibration of a fleet and compare them (SQLite database).

    One record per calibration: serial, model, date, parameters with their covariance,
    instrument, held-out figures, the input files' SHA-256 and the pkmcal version. A
    calibration is named by its id (12), a serial (its latest) or SERIAL~N (N before the
    latest; a serial of digits only as SERIAL~0). The database: --db PATH, else $PKMCAL_HISTORY_DB, else
    ~/.local/share/pkmcal/history.sqlite.
    """


@history_group.command("add", epilog=examples(
    "pkmcal history add calibrated.yaml --serial KM-0042 --db farm.sqlite",
    "pkmcal history add recalibrated.yaml --serial KM-0042 --verification verify.json --db farm.sqlite --json"))
@click.argument("calibrated", metavar="CALIBRATED.yaml")
@click.option("--serial", required=True, metavar="SERIAL", help="The unit's serial number (one unit = one serial).")
@click.option("--model", metavar="MODEL", help="The fleet the unit belongs to (default: the machine it was "
                                               "calibrated from, calibration.calibrated_from).")
@option("--verification", "heldout", old=("--heldout",), metavar="VERIFY.json",
        help="Held-out figures to keep with it: the output of 'pkmcal verify CALIBRATED.yaml --held-out "
             "HELDOUT.csv --json'.")
@click.option("--allow-duplicate", is_flag=True, help="Record the file even if the same file (SHA-256) is already "
                                                      "recorded for this serial.")
@_db_option
@_json_option
def add_cmd(calibrated, serial, model, heldout, allow_duplicate, db, as_json) -> None:
    """Record CALIBRATED.yaml (written by 'pkmcal identify') as a calibration of --serial."""
    from pkmcal.history.store import add_calibrated_file

    doc = None if heldout is None else _read_heldout(heldout)
    rec = add_calibrated_file(calibrated, serial=serial, db=db, model=model, heldout=doc,
                              allow_duplicate=allow_duplicate)
    if as_json:
        _print_json({"id": rec.id, "serial": rec.serial, "model": rec.model, "date": rec.date,
                     "db": os.fspath(_db_path(db))})
        return
    held = int(rec.held.sum())
    click.echo(f"recorded #{rec.id}: serial {rec.serial}, model {rec.model}, calibrated {rec.date} "
               f"({len(rec.names) - held} parameters estimated, {held} held) in {_db_path(db)}")


def _g(value) -> str:
    return "-" if value is None else f"{value:.4g}"


def _db_path(db):
    from pkmcal.history.store import default_db_path

    return db if db is not None else default_db_path()


def _open(db):
    from pkmcal.history.store import open_history

    return open_history(db, create=False)


@history_group.command("list", epilog=examples("pkmcal history list --db farm.sqlite",
                                               "pkmcal history list --serial KM-0042 --db farm.sqlite --json"))
@click.option("--serial", metavar="SERIAL", help="Only this unit.")
@click.option("--model", metavar="MODEL", help="Only this model's units.")
@_db_option
@_json_option
def list_cmd(serial, model, db, as_json) -> None:
    """List the recorded calibrations, oldest first."""
    with _open(db) as hist:
        recs = hist.records(serial=serial, model=model)
    if as_json:
        _print_json([{k: v for k, v in r.to_dict().items() if k not in ("parameters", "covariance")} for r in recs])
        return
    if not recs:
        click.echo("no calibration recorded" + (" for these filters" if serial or model else ""))
        return
    click.echo(f"{'id':>4}  {'serial':<12} {'model':<18} {'date':<20} {'method':<12} {'instrument':<12} "
               f"{'poses':>5} {'chi2/dof':>8}  held-out")
    for r in recs:
        chi2 = "-" if r.reduced_chi2 is None else f"{r.reduced_chi2:.3g}"
        click.echo(f"{r.id:>4}  {r.serial:<12} {r.model:<18} {r.date:<20} {r.method or '-':<12} "
                   f"{r.instrument or '-':<12} {r.n_poses if r.n_poses is not None else '-':>5} {chi2:>8}  "
                   f"{'yes' if r.heldout else '-'}")


@history_group.command("show", epilog=examples("pkmcal history show KM-0042 --db farm.sqlite",
                                               "pkmcal history show 1 --db farm.sqlite --json"))
@click.argument("ref", metavar="REF")
@_db_option
@_json_option
def show_cmd(ref, db, as_json) -> None:
    """Show one calibration (REF: id, serial or SERIAL~N): facts, parameters with σ."""
    with _open(db) as hist:
        rec = hist.get(ref)
    if as_json:
        _print_json(rec.to_dict())
        return
    click.echo(f"#{rec.id}: serial {rec.serial}, model {rec.model}, machine {rec.machine} ({rec.kind})")
    click.echo(f"calibrated {rec.date} with pkmcal {rec.pkmcal_version} (recorded {rec.added}); method "
               f"{rec.method or '-'}, instrument {rec.instrument or '-'}, {rec.n_poses} poses, rms residual "
               f"{_g(rec.rms_residual)}, chi2/dof {_g(rec.reduced_chi2)}")
    click.echo(f"covariance: {rec.covariance_kind or '-'}")
    click.echo(f"file: {rec.source or '-'} (sha256 {rec.source_sha256 or '-'})")
    for role, inp in sorted(rec.inputs.items()):
        what = inp.get("builtin") and f"built-in {inp['builtin']}" or f"{inp.get('file')} (sha256 {inp.get('sha256')})"
        click.echo(f"input {role}: {what}")
    if rec.heldout:
        after = rec.heldout.get("after") if isinstance(rec.heldout.get("after"), dict) else None
        figures = [f"{k} {v:.4g}" for k, v in (after or {}).items() if isinstance(v, (int, float))]
        click.echo("held-out, after calibration: " + (", ".join(figures) if figures else "recorded (see --json)"))
    v, s, u = rec.display()
    w = max(len(n) for n in rec.names)
    click.echo(f"{'parameter':<{w}}  {'value':>14}  {'sigma':>10}")
    for n, x, e, un, h in zip(rec.names, v, s, u, rec.held):
        click.echo(f"{n:<{w}}  {x:>14.8g}  {'held' if h else format(e, '.3g'):>10}  {un}")


@history_group.command("compare", epilog=examples("pkmcal history compare KM-0042~1 KM-0042 --db farm.sqlite",
                                                  "pkmcal history compare 1 2 --alpha 0.01 --db farm.sqlite --json"))
@click.argument("a", metavar="A")
@click.argument("b", metavar="B")
@_alpha_option
@_db_option
@_json_option
def compare_cmd(a, b, alpha, db, as_json) -> None:
    """Whether calibrations A and B differ beyond their combined uncertainty.

    Per parameter z = (B - A)/sqrt(sigma_A^2 + sigma_B^2) against the Bonferroni limit, and
    jointly chi2 = d^T (C_A + C_B)^+ d over the identifiable subspace; held parameters (the
    gauge) are not tested. Calibrations in different gauges are compared after B is
    re-expressed in A's gauge along the unidentifiable directions recorded with it (said in
    the output), else not compared (the reason and the --fix that avoids it are printed).
    """
    from pkmcal.history.stats import compare

    with _open(db) as hist:
        ra, rb = hist.get(a), hist.get(b)
    result = compare(ra, rb, alpha)
    if as_json:
        _print_json(result.to_dict())
        return
    for line in result.lines():
        click.echo(line)


@history_group.command("fleet", epilog=examples("pkmcal history fleet --db farm.sqlite",
                                                "pkmcal history fleet --model kossel-mini --db farm.sqlite --json"))
@click.option("--model", metavar="MODEL", help="Only this model (default: every model in the database).")
@_alpha_option
@_db_option
@_json_option
def fleet_cmd(model, alpha, db, as_json) -> None:
    """Flag units whose parameters fall outside the spread of their fleet.

    Each serial's latest calibration against the other units of its model: t =
    (x - mean)/(s sqrt(1 + 1/(n-1))) with the others' mean and spread, Student t with n-2
    dof, Bonferroni over parameters and units (false-alarm probability --alpha per fleet).
    """
    from pkmcal.history.stats import fleet

    with _open(db) as hist:
        models = [model] if model else sorted({r.model for r in hist.records()})
        reports = [fleet(hist.latest_per_serial(m), alpha, model=m) for m in models]
    if model and not reports[0].units:
        raise PkmcalError(f"no calibration of model '{one_line(model)}' in {_db_path(db)}; 'pkmcal history list' "
                          "shows the models")
    if as_json:
        _print_json([r.to_dict() for r in reports])
        return
    for rep in reports:
        for line in rep.lines():
            click.echo(line)


@history_group.command("plot", epilog=examples("pkmcal history plot KM-0042 -o km-0042.png --db farm.sqlite",
                                               "pkmcal history plot KM-0042 -o km-0042.svg --parameter endstop_b "
                                               "--db farm.sqlite"))
@click.argument("serial", metavar="SERIAL")
@click.option("-o", "--output", required=True, metavar="FIGURE.png|svg", help="Figure to write (PNG or SVG).")
@click.option("--parameter", "parameters", multiple=True, metavar="NAMES",
              help="Parameters to draw (comma separated; repeatable). Default: every estimated one.")
@click.option("--k", "k", type=FiniteFloat(min=0.0, min_open=True), default=1.0, show_default=True,
              help="Error bars of ±k sigma.")
@_db_option
@_json_option
def plot_cmd(serial, output, parameters, k, db, as_json) -> None:
    """Plot a unit's parameters over time with their uncertainty (±k sigma bars)."""
    from pkmcal.cli.options import check_output
    from pkmcal.history.plot import plot_history

    check_output(output, [db] if db else [])
    names = [n for p in parameters for n in p.replace(",", " ").split()] or None
    with _open(db) as hist:
        recs = hist.records(serial=serial)
    if not recs:
        raise PkmcalError(f"no calibration of serial '{one_line(serial)}' in {_db_path(db)}; 'pkmcal history list' "
                          "shows the serials")
    drawn = plot_history(recs, output, names, k)
    if as_json:
        _print_json({"output": output, "serial": serial, "calibrations": [r.id for r in recs], "parameters": drawn,
                     "k": k})
    else:
        click.echo(f"wrote {output}: {len(drawn)} parameter(s) of {serial} over {len(recs)} calibration(s)")
