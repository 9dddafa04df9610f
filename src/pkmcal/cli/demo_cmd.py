"""``pkmcal demo``: plan, simulate, identify, verify, export and report in one command
(:mod:`pkmcal.demo`)."""

from __future__ import annotations

import time

import click

from pkmcal.cli.option_types import SEED
from pkmcal.demo import DEMO_MACHINE, DEMO_OUT, DEMO_REAL, DEMO_SETUP, DemoConfig, run_demo


@click.command("demo")
@click.option("--out", default=DEMO_OUT, show_default=True, metavar="DIR",
              help="Folder for the report and the exported files (created if needed).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed (same seed, same bytes).")
@click.option("--poses", "n_poses", type=click.IntRange(min=1), default=DemoConfig.n_poses, show_default=True,
              help="Number of poses to plan and measure.")
@click.option("--held-out", "n_held_out", type=click.IntRange(min=1), default=DemoConfig.n_held_out,
              show_default=True, help="Number of held-out verification poses.")
@click.option("--setup", default=DEMO_SETUP, show_default=True, metavar="SETUP",
              help="Measurement setup: a setup YAML file or built-in name (full-pose-paper1, indicators-prototype, "
                   "laser-tracker).")
@click.option("--machine", default=DEMO_MACHINE, show_default=True, metavar="MACHINE",
              help="Nominal machine (file or built-in name).")
@click.option("--real", default=DEMO_REAL, show_default=True, metavar="REAL",
              help="The simulated real machine (file or built-in name).")
@click.option("--no-png", is_flag=True, help="Write the figures as SVG only.")
@click.option("-q", "--quiet", is_flag=True, help="Print only the closing summary.")
def demo(out, seed, n_poses, n_held_out, setup, machine, real, no_png, quiet) -> None:
    """Calibrate the built-in prototype end to end on a simulated 'real' machine.

    Plans the measurement poses (D-optimal), simulates the campaign on REAL, identifies the
    kinematic parameters, verifies on held-out poses, exports the calibrated machine (YAML,
    LinuxCNC HAL, JSON) and writes an HTML report into DIR/report.html. The default setup
    measures the full pose (paper 1); indicators-prototype is paper 2's three dial indicators.
    """
    from pkmcal.io.atomic import check_output_dir

    check_output_dir(out, "--out")  # before anything runs: an uncreatable folder is refused at once
    t0 = time.perf_counter()
    config = DemoConfig(machine=machine, real=real, setup=setup, out=out, seed=seed, n_poses=n_poses,
                        n_held_out=n_held_out, png=not no_png)
    starts: dict[str, float] = {}

    def progress(k: int, n: int, step: str, message: str) -> None:
        if quiet:
            return
        if not message:
            starts[step] = time.perf_counter()
            click.echo(f"[{k}/{n}] {step:<9}...", nl=False, err=True)
        else:
            dt = time.perf_counter() - starts.get(step, t0)
            click.echo(f" {dt:5.1f} s  {message}", err=True)

    if not quiet:
        click.echo(f"pkmcal demo: calibrating '{machine}' against the simulated '{real}' with setup '{setup}', "
                   f"seed {seed}", err=True)
    result = run_demo(config, progress)
    click.echo(result.summary())
    click.echo(f"Done in {time.perf_counter() - t0:.1f} s.")
