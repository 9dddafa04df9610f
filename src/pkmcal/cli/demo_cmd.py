"""``pkmcal demo``: plan, simulate, identify, verify, export and report in one command
(:mod:`pkmcal.demo`). Its steps show as a progress bar on a terminal (:mod:`pkmcal.progress`)
and as one note per finished step on standard error; ``--quiet`` leaves only the summary, and
``--json`` prints it as one JSON object (the held-out errors before and after, mm and degrees;
the files written)."""

from __future__ import annotations

import json
import math
import time

import click

from pkmcal.cli.options import check_output_folder, count_or_poses_file, examples, option, quiet_option
from pkmcal.cli.option_types import SEED, FiniteFloat
from pkmcal.demo import DEMO_MACHINE, DEMO_OUT, DEMO_REAL, DEMO_SETUP, DemoConfig, run_demo


@click.command("demo", epilog=examples(
    "pkmcal demo",
    "pkmcal demo --setup indicators-prototype --n-poses 30 --n-held-out 20 --no-png -o demo-indicators --quiet --json"))
@option("-o", "--output", "out", old=("--out",), default=DEMO_OUT, show_default=True, metavar="DIR/",
              help="Folder for the report and the exported files (created if needed).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed (same seed, same bytes).")
@click.option("--n-poses", type=click.IntRange(min=1), default=None,
              help=f"Number of poses to plan and measure.  [default: {DemoConfig.n_poses}]")
@click.option("--poses", metavar="POSES.csv",
              help="Measure the poses of this file (x,y,z mm, a,b,c deg) instead of planning them.")
@option("--n-held-out", "n_held_out", old=("--held-out",), type=click.IntRange(min=1), default=DemoConfig.n_held_out,
              show_default=True, help="Number of held-out verification poses.")
@click.option("--setup", default=DEMO_SETUP, show_default=True, metavar="SETUP",
              help="Measurement setup: a setup YAML file or built-in name (full-pose-paper1, indicators-prototype, "
                   "laser-tracker).")
@click.option("--machine", default=DEMO_MACHINE, show_default=True, metavar="MACHINE",
              help="Nominal machine (file or built-in name).")
@click.option("--real", default=DEMO_REAL, show_default=True, metavar="REAL",
              help="The simulated real machine (file or built-in name).")
@click.option("--stroke-margin", type=FiniteFloat(min=0.0), metavar="MM",
              help="Safety margin of the plan on the stroke (default as 'pkmcal plan': 3 mm).")
@click.option("--tilt-margin", type=FiniteFloat(min=0.0), metavar="DEG",
              help="Safety margin of the plan on the joint tilts (default as 'pkmcal plan').")
@click.option("--no-png", is_flag=True, help="Write the figures as SVG only.")
@quiet_option
@click.option("--json", "as_json", is_flag=True,
              help="Print the summary as one JSON object (held-out errors before/after in mm and degrees, the "
                   "files written) instead of text.")
def demo(out, seed, n_poses, poses, n_held_out, setup, machine, real, stroke_margin, tilt_margin, no_png,
         quiet, as_json=False) -> None:
    """Calibrate the built-in prototype end to end on a simulated 'real' machine.

    Plans the measurement poses (D-optimal), simulates the campaign on REAL, identifies the
    kinematic parameters, verifies on held-out poses, exports the calibrated machine (YAML,
    LinuxCNC HAL, JSON) and writes an HTML report into DIR/report.html. The default setup
    measures the full pose (paper 1); indicators-prototype is paper 2's three dial indicators.
    """
    from pkmcal.io.atomic import check_output_dir
    from pkmcal.progress import ProgressBar

    check_output_folder(out, "the demo's output")
    check_output_dir(out, "-o")  # before anything runs: an uncreatable folder is refused at once
    t0 = time.perf_counter()
    n_poses, poses = count_or_poses_file(poses, n_poses, DemoConfig.n_poses)
    config = DemoConfig(machine=machine, real=real, setup=setup, out=out, seed=seed, n_poses=n_poses,
                        n_held_out=n_held_out, png=not no_png, stroke_margin=stroke_margin,
                        tilt_margin_deg=tilt_margin, poses=poses)
    starts: dict[str, float] = {}
    with ProgressBar("demo", quiet=quiet) as bar:
        bar.note(f"pkmcal demo: calibrating '{machine}' against the simulated '{real}' with setup '{setup}', "
                 f"seed {seed}")

        def progress(k: int, n: int, step: str, message: str) -> None:
            if not message:
                starts[step] = time.perf_counter()
                bar.stage(step)
                bar(k - 1, n)
            else:
                bar(k, n)
                bar.note(f"[{k}/{n}] {step:<9} {time.perf_counter() - starts.get(step, t0):5.1f} s  {message}")

        result = run_demo(config, progress)
    if as_json:
        click.echo(json.dumps(summary_json(result), indent=2, allow_nan=False))
        return
    click.echo(result.summary())
    click.echo(f"Done in {time.perf_counter() - t0:.1f} s.")


def summary_json(result) -> dict:
    """The closing summary as JSON: the held-out errors ``before`` and ``after``
    calibration (``position_rms_mm``, ``position_max_mm``, ``orientation_rms_deg``,
    ``orientation_max_deg``, as the keys of ``pkmcal verify --json``; null where not finite),
    the number of held-out poses used, the files written and the notes."""
    out: dict[str, dict] = {"before": {}, "after": {}}
    for key, v in result.headline.items():       # position_rms_before (mm), orientation_max_after (rad), ...
        quantity, stat, when = key.split("_")
        v = math.degrees(v) if quantity == "orientation" else float(v)
        out[when][f"{quantity}_{stat}_{'deg' if quantity == 'orientation' else 'mm'}"] = v if math.isfinite(v) else None
    return {"held_out_poses": int(result.verification.to_dict()["used"]), **out,
            "files": {k: str(p) for k, p in result.files.items()}, "notes": list(result.notes)}


__all__ = ["demo", "summary_json"]
