"""``pkmcal study STUDY.yaml -o RESULTS/``: a Monte Carlo study of simulated calibration
campaigns (:mod:`pkmcal.study`; docs/studies.md). Only click is imported at start-up."""

from __future__ import annotations


import click

from pkmcal.cli.option_types import SEED
from pkmcal.cli.options import check_output_folder, examples


@click.command("study", epilog=examples(
    "pkmcal study examples/study-quick.yaml -o quick-results --workers 1"))
@click.argument("study_file", type=click.Path(dir_okay=False), metavar="STUDY.yaml")
@click.option("-o", "--output", required=True, type=click.Path(file_okay=False), metavar="RESULTS/",
              help="Results folder (created; never overwritten: use --resume to continue one).")
@click.option("--seed", type=SEED, default=None, help="Override the study file's seed (same seed, same results).")
@click.option("--trials", type=click.IntRange(min=1), default=None, help="Override the number of trials per configuration.")
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="Local worker processes (1 = in this process; default: all local cores); with --dask local, "
                   "the LocalCluster's workers.")
@click.option("--dask", "dask_address", default=None, metavar="ADDRESS|local",
              help="Run on a Dask cluster: a scheduler address (tcp://host:8786) or 'local' for a LocalCluster "
                   "(needs pip install 'pkmcal[dask]').")
@click.option("--resume", is_flag=True, help="Continue an interrupted study in RESULTS/ (runs only the missing trials).")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar and no summary on stdout.")
@click.option("--no-figures", is_flag=True, help="Skip the figures and the HTML page.")
def study(study_file, output, seed, trials, workers, dask_address, resume, quiet, no_figures) -> None:
    """Run the Monte Carlo study STUDY.yaml (plan, simulate, identify, verify per trial) into RESULTS/.

    RESULTS/ gets trials.csv (one row per trial × configuration), summary.csv (statistics
    with 95 % intervals), figures/ and index.html.

    Same seed, same bits, whatever the number of workers or the backend. The progress bar
    (stderr) shows only on a terminal.
    """
    from pkmcal.api import study as run_study
    from pkmcal.errors import PkmcalError, one_line
    from pkmcal.progress import bars_enabled
    from pkmcal.study import load_study

    check_output_folder(output, "the study's output")
    if workers is not None and dask_address not in (None, "local"):
        raise PkmcalError("--workers applies to local runs and to --dask local; a Dask scheduler's workers are "
                          "started with 'dask worker'")
    spec = load_study(study_file)
    show = bars_enabled(quiet)
    result = run_study(spec, output, seed=seed, trials=trials, workers=workers, dask=dask_address, resume=resume,
                       progress=show, figures=not no_figures)
    if trials is not None:
        spec = spec.with_trials(trials)      # for the summary line
    if quiet:
        return
    n_cfg = len({int(c) for c in result.columns["config"]})
    click.echo(f"study '{one_line(spec.name)}': {n_cfg} configuration(s) x {spec.trials} trials; ran {result.trials_run} "
               f"trial(s) in {result.seconds:.1f} s ({result.backend}, {result.workers} worker(s))")
    shown = {"heldout_position_rms_mm": ("position", "mm"), "heldout_tilt_rms_deg": ("tilt", "deg"),
             "heldout_height_rms_mm": ("height", "mm"),
             "heldout_orientation_rms_deg": ("orientation", "deg"),   # shown without a tilt (a planar plate angle)
             "heldout_reading_rms_mm": ("reading", "mm")}             # indicators, a Z probe compared on readings
    by_config: dict[int, dict] = {}
    for row in result.summary:
        by_config.setdefault(int(row["config"]), {})[row["metric"]] = row
    for rows in by_config.values():
        r0 = next(iter(rows.values()))
        parts = [f"{name} {rows[m]['median']:.4g} {unit}" for m, (name, unit) in shown.items()
                 if m in rows and rows[m]["n"] and not (name == "orientation" and "heldout_tilt_rms_deg" in rows)]
        compared = r0.get("heldout_compare") or "commanded"
        labels = " | ".join(one_line(str(r0[k])) for k in ("machine", "setup", "plan"))   # labels may hold a newline
        click.echo(f"  {labels} {int(r0['n_poses'])} | {one_line(str(r0['method']))}: "
                   f"held-out rms after, median: {', '.join(parts) or 'no trial completed'}"
                   + ("" if compared == "commanded" else f" (compared: {compared})"))
    failed = [r for r in result.summary if r["metric"] == "failed" and r["mean"] > 0]
    for r in failed:
        click.echo(f"  note: {r['mean']:.1%} of the trials of configuration {int(r['config'])} failed "
                   "(column 'message' of trials.csv says why)")
    click.echo(f"results: {output}/trials.csv, summary.csv" + ("" if no_figures else ", index.html"))
