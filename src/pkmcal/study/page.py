"""The study's HTML page (``RESULTS/index.html``) and figure files (``RESULTS/figures/``).

One self-contained page: what was studied (machines and their error models, setups with
their noise, plans, methods, held-out set, seed, trials), the figures of
:mod:`pkmcal.study.plots` inline (SVG, also written as SVG and PNG files), a table of the
headline statistics per configuration with their 95 % intervals, and the meaning of every
column of ``trials.csv``. No clock or host information: the same results give the same
bytes.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from pkmcal import __version__
from pkmcal.io.atomic import atomic_write_bytes, atomic_write_text, make_folder
from pkmcal.report.html import CSS, inline_svg
from pkmcal.study.plots import study_figures
from pkmcal.study.results import COLUMNS, SCALE_COLUMNS, summary_lookup

#: Headline columns of the page's table: (metric, heading, statistic).
HEADLINE = (
    ("heldout_position_rms_mm", "held-out position rms after, mm (median, 95 % CI)", "median"),
    ("heldout_position_rms_before_mm", "before, mm (median)", "median_only"),
    ("heldout_orientation_rms_deg", "held-out orientation rms after, deg (median)", "median_only"),
    ("heldout_reading_rms_mm", "held-out reading rms after, mm (median; compared on readings)", "median_only"),
    ("heldout_reading_rms_before_mm", "before, mm (median)", "median_only"),
    ("param_error_rms_mm", "parameter error rms, mm (median, 95 % CI)", "median"),
    ("coverage_fraction", "per-parameter coverage (mean, 95 % CI)", "mean"),
    ("ellipsoid_within_95", "joint-ellipsoid coverage (fraction, Wilson 95 % CI)", "mean"),
    ("failed", "failed trials (fraction)", "mean_only"),
)


def _esc(s) -> str:
    return html.escape(str(s), quote=True)


def _g(v) -> str:
    return "—" if v is None or not np.isfinite(v) else f"{v:.4g}"


def _stat(s: dict | None, kind: str) -> str:
    if s is None or not s["n"]:
        return "—"
    if kind == "median":
        return f"{_g(s['median'])} [{_g(s['median_ci_low'])}, {_g(s['median_ci_high'])}]"
    if kind == "median_only":
        return _g(s["median"])
    if kind == "mean_only":
        return _g(s["mean"])
    return f"{_g(s['mean'])} [{_g(s['mean_ci_low'])}, {_g(s['mean_ci_high'])}]"


def _setup_text(setup, spec) -> str:
    """The setup's line of facts; ``spec`` its :class:`~pkmcal.study.schema.SetupSpec`."""
    n = setup.noise
    return (f"sensor '{setup.sensor.kind}', {n.distribution} noise, reading std "
            f"{np.array2string(np.asarray(n.reading_std), precision=4)}, actuator std "
            f"{np.array2string(np.asarray(n.actuator_std), precision=4)} (mm, rad)"
            + (f"; the plan's poses are probe points, with the 12 distances of Klipper's calibration object at scale "
               f"{spec.object_scale:g}" if setup.sensor.reads_pose_pairs else "")
            + ("; probe points lowered onto the bed" if spec.on_bed else ""))


def _table(header, rows) -> str:
    head = "".join(f"<th>{_esc(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def render_page(study, ctx, cols: dict, summary: list, figs) -> str:
    look = summary_lookup(summary)
    p: list[str] = []
    add = p.append
    add("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<title>{_esc(study.name)}: pkmcal study</title>\n<style>{CSS}</style>\n</head>\n<body>")
    add(f"<h1>Study {_esc(study.name)}</h1>")
    if study.description:
        add(f"<p>{_esc(study.description)}</p>")
    n_cfg = ctx.n_configs
    facts = [("pkmcal version", __version__), ("seed", study.seed), ("trials per configuration", study.trials),
             ("configurations", n_cfg), ("held-out poses", f"{len(ctx.heldout[0])} per machine "
                                        + ("(file)" if study.heldout_file is not None else "(random, reachable)"))]
    for m in study.machines:
        facts.append((f"machine {m.label}", f"nominal '{m.nominal.name}'; {m.describe()}"
                      + (f"; real-machine limits not checked: {', '.join(m.ignore_limits)}" if m.ignore_limits else "")))
    for s in study.setups:
        texts = {m.label: _setup_text(b, s) for m, b in zip(study.machines, s.bound) if b is not None}
        if len(set(texts.values())) <= 1:
            facts.append((f"setup {s.label}", _setup_text(s.setup, s)
                          + (f"; machines {', '.join(texts)}" if s.bound and len(texts) < len(study.machines) else "")))
        else:   # bound otherwise per machine (a planar tracker on rotary and on linear actuators)
            facts += [(f"setup {s.label}, machine {label}", text) for label, text in texts.items()]
    for pl in study.plans:
        facts.append((f"plan {pl.label}", f"algorithm '{pl.algorithm}', poses {', '.join(map(str, pl.poses))}; "
                      f"pool of {pl.candidates if pl.algorithm != 'corners' else 'the box corners'} candidates; "
                      + ("new selection every trial" if pl.resample == "trial" else "one selection for all trials")))
    for me in study.methods:
        facts.append((f"method {me.label}", f"{me.method}, {'weighted' if me.weighted else 'unweighted'}"
                      + (f", free {', '.join(me.free)}" if me.free else "")
                      + (f", fix {me.fix if isinstance(me.fix, str) else ', '.join(me.fix)}" if me.fix else "")
                      + (f"; machines {', '.join(me.machines)}" if me.machines is not None else "")
                      + (f"; setups {', '.join(me.setups)}" if me.setups is not None else "")))
    add(_table(["item", "value"], [[_esc(k), _esc(v)] for k, v in facts]))
    add("<p>Files: <a href=\"trials.csv\">trials.csv</a> (one row per trial × configuration), "
        "<a href=\"summary.csv\">summary.csv</a> (statistics with 95 % intervals per configuration and metric).</p>")
    for f in figs:
        add(f"<figure>{inline_svg(f.svg, f.name)}<figcaption>{_esc(f.caption)}</figcaption></figure>")
    add("<h2>Summary</h2>")
    cfg = cols["config"].astype(int)
    rows = []
    for c in np.unique(cfg):
        i = np.flatnonzero(cfg == c)[0]
        name = f"{cols['machine'][i]} | {cols['setup'][i]} | {cols['plan'][i]} {int(cols['n_poses'][i])} | {cols['method'][i]}"
        rows.append([_esc(name), _esc(cols["heldout_compare"][i])]
                    + [_esc(_stat(look.get((int(c), m)), kind)) for m, _, kind in HEADLINE])
    add(_table(["configuration", "held-out errors compare"] + [h for _, h, _ in HEADLINE], rows))
    add("<p>Held-out errors compare (column <code>heldout_compare</code>): <b>commanded</b>, the platform poses "
        "as commanded, where the calibration fixed no gauge (its frames are the instrument's); <b>sensor</b>, "
        "what the instrument reads at the reached pose against what each model predicts its instrument reads, "
        "where a gauge left the frames a choice (poses as commanded would compare frames the gauge made "
        "arbitrary); <b>aligned</b> (" + ("on request; the default with a printed object, whose geometry it is"
                                          if study.reads_pose_pairs else "on request")
        + "), the platform poses after the best rigid alignment of each "
        "model's base and platform frames; <b>tool</b>, the tool on the tracker, for a machine at static "
        "equilibrium.</p>")
    add("<p>Intervals: Student-t for means, binomial order statistics for medians, Wilson score for fractions. "
        "θ* is the real machine's parameters in the fit's gauge (the noise-free fit of the same poses when a "
        "parameter held fixed differs from its true value); coverage uses the reported covariance of the free "
        "parameters only (gauge-fixed parameters are not estimated, so not counted).</p>")
    add("<h2>Columns of trials.csv</h2>")
    glossary = COLUMNS | (SCALE_COLUMNS if study.reads_pose_pairs else {})
    add(_table(["column", "meaning"], [[_esc(k), _esc(d)] for k, (_, d) in glossary.items()]
               + [[_esc(k), "extra metric of this study"] for k in study.extra_columns]))
    add("</body>\n</html>\n")
    return "\n".join(p)


def write_page(study, ctx, cols: dict, summary: list, out: Path) -> Path:
    """Write the figures and ``index.html`` into ``out``; returns the page's path."""
    figs = study_figures(cols, summary)
    make_folder(out / "figures", "the figure folder")
    for f in figs:
        atomic_write_bytes(out / "figures" / f"{f.name}.svg", f.svg)
        if f.png is not None:
            atomic_write_bytes(out / "figures" / f"{f.name}.png", f.png)
    page = out / "index.html"
    atomic_write_text(page, render_page(study, ctx, cols, summary, figs))
    return page


__all__ = ["render_page", "write_page"]
