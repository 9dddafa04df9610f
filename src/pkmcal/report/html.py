"""The calibration report: one self-contained HTML file, plus its figures beside it.

:func:`write_report` draws the figures of :mod:`pkmcal.report.figures` from a
:class:`~pkmcal.report.data.ReportData`, writes each as ``<name>.svg`` and ``<name>.png``
into the output folder, and writes ``report.html`` with inline CSS and every figure
embedded as inline SVG (element ids prefixed per figure so they cannot collide): no
JavaScript, no external URL, one file to mail or archive. Same input → same bytes.

Sections: what was achieved (before → after on held-out data, in people's units) and what
to do next (the export command for the machine's controller, what to measure to improve,
from the identifiability of the fit); machine and setup; pose plan (machine in a few poses, pose cloud);
identifiability (rank, singular values, fixed gauge, weak directions, paper 2 §4 /
paper 3 §3); identified parameters ± 1σ against nominal (and the simulation's truth when
known), each in its unit: mm, degrees for the parameters declared angles with the correlation matrix ρ_ij = C_ij/√(C_ii C_jj); residuals per pose and per
reading; held-out errors before/after (rms = √(mean e²), p95, max), also pose by pose; error
maps. With a known truth (simulation) the error of every parameter against it.
"""

from __future__ import annotations

import html
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pkmcal import __version__
from pkmcal.conventions import angle_text, length_text
from pkmcal.errors import PkmcalError
from pkmcal.io.atomic import atomic_write_bytes, make_folder
from pkmcal.report import figures as F
from pkmcal.report.data import PosePoints, ReportData, pose_points, summarise

REPORT_NAME = "report.html"

CSS = """
body { font-family: "DejaVu Sans", Helvetica, Arial, sans-serif; font-size: 14px; color: #222;
       max-width: 1100px; margin: 0 auto; padding: 16px 24px 48px; line-height: 1.45; background: #fff; }
h1 { font-size: 24px; border-bottom: 2px solid #1f77b4; padding-bottom: 6px; }
h2 { font-size: 19px; margin-top: 34px; border-bottom: 1px solid #ccc; padding-bottom: 3px; }
h3 { font-size: 15px; margin-top: 20px; }
pre { background: #f5f5f5; padding: 8px 10px; overflow-x: auto; font-size: 12px; }
table { border-collapse: collapse; margin: 8px 0 14px; font-size: 12.5px; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
th { background: #eef3f8; }
td.l, th.l { text-align: left; }
tr.fixed td { color: #888; }
figure { margin: 14px 0 22px; }
figure svg { max-width: 100%; height: auto; display: block; }
figcaption { font-size: 12.5px; color: #555; margin-top: 4px; }
.headline { font-size: 16px; background: #eef6ee; border-left: 4px solid #2ca02c; padding: 8px 12px; }
.warn { background: #fff4e5; border-left: 4px solid #ff7f0e; padding: 6px 10px; }
.muted { color: #777; font-size: 12px; }
nav a { margin-right: 12px; }
"""

ARCSEC = F.ARCSEC_PER_RAD


@dataclass(frozen=True)
class ReportFiles:
    """What :func:`write_report` wrote: the HTML file and the figure files (SVG, PNG)."""

    html: Path
    figures: tuple[Path, ...]


def _esc(s: object) -> str:
    return html.escape(str(s), quote=True)


def _fmt(v: float, spec: str = ".4f") -> str:
    return "—" if v is None or not np.isfinite(v) else format(float(v), spec)


_ID = re.compile(r'\bid="([^"]+)"')
_HREF = re.compile(r'(href=")#([^"]+)"')
_URL = re.compile(r"url\(#([^)]+)\)")


def inline_svg(svg: bytes, prefix: str) -> str:
    """Matplotlib SVG bytes as an inline ``<svg>`` element: XML prologue removed, every id
    and reference to it prefixed with ``prefix`` so that several figures can share a page."""
    text = svg.decode("utf-8")
    start = text.find("<svg")
    if start < 0:
        raise PkmcalError(f"report: figure '{prefix}' is not an SVG document")
    text = text[start:]
    seen: dict[str, int] = {}

    def new_id(m: re.Match) -> str:
        # matplotlib names images by a hash of their pixels, so two identical colour bars
        # share an id; later duplicates (never referenced) get a suffix.
        k = seen[m.group(1)] = seen.get(m.group(1), 0) + 1
        return f'id="{prefix}-{m.group(1)}"' if k == 1 else f'id="{prefix}-{m.group(1)}-{k}"'

    text = _ID.sub(new_id, text)
    text = _HREF.sub(lambda m: f'{m.group(1)}#{prefix}-{m.group(2)}"', text)
    text = _URL.sub(lambda m: f"url(#{prefix}-{m.group(1)})", text)
    return text.replace("<svg ", f'<svg role="img" aria-label="{prefix}" class="figure" ', 1)


def _held_out_points(data: ReportData) -> PosePoints | None:
    """The held-out poses' :class:`PosePoints`: poses of the nominal machine, or of the
    single machine when the measurements were pose pairs."""
    from pkmcal.mechanisms.pose_pairs import single_machine

    if data.held_out_poses is None:
        return None
    for mechanism in (data.nominal, single_machine(data.nominal)):
        if data.held_out_poses.shape[1] == len(mechanism.pose_names):
            return pose_points(mechanism, data.held_out_poses)
    return None


def _plan_extent(shown: PosePoints, n: int) -> str:
    """The plan section's line: how many poses and where (mm, degrees)."""
    p = shown.points if shown.second is None else np.concatenate([shown.points, shown.second])
    text = f"{n} poses; " + ", ".join(f"{c} {p[:, i].min():.1f}…{p[:, i].max():.1f} mm" for i, c in enumerate("xyz"))
    if shown.tilt is not None:
        text += f"; tilt up to {np.rad2deg(shown.tilt).max():.1f}°"
    if shown.yaw is not None:
        text += f", yaw {np.rad2deg(shown.yaw).min():.1f}…{np.rad2deg(shown.yaw).max():.1f}°"
    return text


def build_figures(data: ReportData, png: bool = True) -> list[F.RenderedFigure]:
    """All figures of the report, rendered (deterministic bytes)."""
    out: list[F.RenderedFigure] = []
    nominal = data.nominal
    if "drawing" in nominal.abilities:
        shown = F.pick_display_poses(nominal, data.poses)
        titles = ["home", "most tilted", "farthest from home"][: len(shown)]
        out.append(F.render(F.machine_poses_figure(nominal, shown, titles), "machine-poses",
                            f"{nominal.name} drawn in {len(shown)} of its poses: base (grey), platform (blue), "
                            "legs (red).", png))
    points = pose_points(nominal, data.poses)
    if points is not None and len(data.poses):
        held = _held_out_points(data)
        what = (f"The {len(data.poses)} measurement poses" if points.second is None else
                f"The {len(data.poses)} measurements: probe points, and the pairs of points whose distance was "
                "measured (joined)")
        out.append(F.render(F.pose_cloud_figure(points, held), "pose-cloud",
                            what + ("" if points.tilt is None else ", coloured by platform tilt")
                            + ("" if held is None else f"; crosses: the {len(held.points)} held-out poses") + ".",
                            png))
    ident = data.identifiability
    if ident.singular_values.size:
        out.append(F.render(F.singular_values_figure(ident.singular_values, ident.rank), "singular-values",
                            "Singular values of the column-scaled identification Jacobian.", png))
    out.append(F.render(F.parameter_figure(data.parameters), "parameters",
                        "Identified deviation from nominal, ±2σ; open circles: the true deviation "
                        "(simulation only).", png))
    t = data.parameters
    if t.true is not None and np.any(t.free & np.isfinite(t.true)):
        shown = t.free & np.isfinite(t.true)
        names = tuple(n for n, k in zip(t.names, shown) if k)
        errs = {"before (nominal)": (t.nominal - t.true)[shown], "after (identified)": (t.identified - t.true)[shown]}
        out.append(F.render(F.parameter_errors_figure(names, errs, t.is_angle[shown],
                                                      "Error of every identified parameter against the truth"),
                            "parameter-errors", "|nominal − true| and |identified − true| of every free parameter "
                            "(simulation only; paper 1 Fig. 10), log scale.", png))
    if len(data.correlation_names) > 1:
        out.append(F.render(F.correlation_figure(data.correlation, data.correlation_names), "correlation",
                            "Correlation of the identified parameters (from their covariance).", png))
    if data.residuals.values.size:
        out.append(F.render(F.residual_pose_figure(data.residuals), "residuals-per-pose",
                            "Residuals (measured − predicted) of every reading, per pose.", png))
        out.append(F.render(F.residual_sensor_figure(data.residuals), "residuals-per-reading",
                            "Residual distribution of each reading (box: quartiles; whiskers: 1.5 IQR).", png))
    if data.held_out is not None and data.held_out.n_poses:
        out.append(F.render(F.held_out_figure(data.held_out), "held-out",
                            "Errors at held-out poses with the nominal (before) and identified (after) model.",
                            png))
        h = data.held_out
        out.append(F.render(F.per_pose_errors_figure(
            {"before (nominal)": h.position_before, "after (identified)": h.position_after},
            {"before (nominal)": h.orientation_before, "after (identified)": h.orientation_after},
            "Errors at every held-out pose"), "held-out-per-pose",
            "Position and orientation error of every held-out pose, before and after (paper 1 Fig. 11), log "
            "scale.", png))
    if data.error_map is not None:
        out.append(F.render(F.error_map_figure(data.error_map), "error-map",
                            "Position error over the workspace, before and after calibration.", png))
    return out


def _figure_html(fig: F.RenderedFigure) -> str:
    return (f'<figure id="fig-{fig.name}">\n{inline_svg(fig.svg, fig.name)}\n'
            f"<figcaption>{_esc(fig.caption)} <span class=\"muted\">(file: {_esc(fig.name)}.svg)</span>"
            "</figcaption>\n</figure>")


def _table(header: list[str], rows: list[list[str]], left: int = 1, row_class: list[str] | None = None) -> str:
    th = "".join(f'<th class="l">{_esc(h)}</th>' if i < left else f"<th>{_esc(h)}</th>" for i, h in enumerate(header))
    body = []
    for r, row in enumerate(rows):
        cls = f' class="{row_class[r]}"' if row_class and row_class[r] else ""
        tds = "".join(f'<td class="l">{c}</td>' if i < left else f"<td>{c}</td>" for i, c in enumerate(row))
        body.append(f"<tr{cls}>{tds}</tr>")
    return f"<table>\n<tr>{th}</tr>\n" + "\n".join(body) + "\n</table>"


@dataclass(frozen=True)
class Achieved:
    """One line of what a calibration achieved: ``quantity`` (e.g. "position error, rms"),
    its value ``before`` and ``after`` calibration in internal units (mm, or rad when
    ``angle``), over ``n`` poses of ``source``."""

    quantity: str
    before: float
    after: float
    angle: bool
    n: int
    source: str

    def text(self) -> str:
        """``position error, rms: 4.921 mm → 13.33 µm`` (people's units:
        :func:`pkmcal.conventions.length_text`, :func:`~pkmcal.conventions.angle_text`)."""
        show = angle_text if self.angle else length_text
        ratio = (f" ({self.before / self.after:.3g}× smaller)" if self.after > 0 and self.before > self.after
                 else "")
        return f"{self.quantity}: {show(self.before)} → {show(self.after)}{ratio}"


def achieved(data: ReportData) -> list[Achieved]:
    """Before → after of the calibration, from the best evidence the report has: the
    held-out poses against the true machine (simulation), else the measured held-out data
    (``identify --held-out``); empty when neither was given (the fit's residuals are no
    measure of accuracy)."""
    out: list[Achieved] = []
    h = data.held_out
    if h is not None and h.n_poses:
        s = h.summary()
        src = "held-out poses against the true machine (simulation)"
        out.append(Achieved("position error, rms", s["position_before"]["rms"], s["position_after"]["rms"], False,
                            h.n_poses, src))
        out.append(Achieved("position error, largest", s["position_before"]["max"], s["position_after"]["max"], False,
                            h.n_poses, src))
        if np.isfinite(s["orientation_before"]["rms"]) and s["orientation_before"]["rms"] > 0:
            out.append(Achieved("orientation error, rms", s["orientation_before"]["rms"],
                                s["orientation_after"]["rms"], True, h.n_poses, src))
        return out
    v = data.measured_validation
    if v is not None and "before" in v and "after" in v:
        src = f"measured held-out data ({v['measurements']})"
        for text, unit, key in v["rows"]:
            if not text.endswith(("rms", "max")) or v["before"].get(key) is None or v["after"].get(key) is None:
                continue
            angle = unit == "deg"
            conv = np.deg2rad if angle else float
            quantity, stat = text.rsplit(" ", 1)           # "position rms", "reading residual max"
            what = (f"{quantity}{'' if quantity.startswith('reading') else ' error'}, "
                    f"{'largest' if stat == 'max' else 'rms'}")
            out.append(Achieved(what, float(conv(v["before"][key])), float(conv(v["after"][key])), angle,
                                int(v["n_poses"]), src))
    return out


def export_command(data: ReportData) -> str:
    """The command that writes this calibration for the machine's controller: LinuxCNC's
    genhexkins files for a hexapod it runs, Klipper's config for a delta printer (Marlin:
    ``--format marlin``), else the JSON record."""
    cal = data.calibrated_file or "CALIBRATED.yaml"
    m = data.identified
    if "linuxcnc" in m.abilities:
        return f"pkmcal export {cal} --format linuxcnc -o kinematics.hal --ini joints.ini"
    if m.kind in ("linear-delta", "rotary-delta"):
        return f"pkmcal export {cal} --format klipper -o printer-calibrated.cfg"
    return f"pkmcal export {cal} --format json -o calibration.json"


def next_steps(data: ReportData) -> list[tuple[str, str | None]]:
    """What to do next, as (plain line, command or None): export; what to measure to improve,
    from the identifiability of the fit (the combinations the data do not see, the weak ones)
    and the calibration record's undetermined directions; held-out data when none was given."""
    m = data.identified
    steps: list[tuple[str, str | None]] = []
    where = {"linuxcnc": "LinuxCNC (genhexkins HAL and INI settings; --update-ini MACHINE.ini writes them into a "
                         "copy of your INI)",
             "linear-delta": "Klipper (the sections SAVE_CONFIG writes; --config printer.cfg updates your file; "
                             "Marlin: --format marlin)",
             "rotary-delta": "Klipper (the sections SAVE_CONFIG writes)"}
    key = "linuxcnc" if "linuxcnc" in m.abilities else m.kind
    steps.append((f"Export the calibration to {where.get(key, 'a JSON record of the parameters')}:",
                  export_command(data)))
    ident = data.identifiability
    setup = data.setup_name or "SETUP"
    suggest = f"pkmcal identifiability {data.nominal.name} --setup {setup} --poses POSES.csv --suggest"
    record = (m.metadata or {}).get("calibration") or {} if isinstance(m.metadata, dict) else {}
    undetermined = [str(e.get("text") or e.get("meaning")) for e in record.get("undetermined") or ()]
    if ident.rank < ident.n_params or undetermined:
        seen = list(ident.null_space[:3]) + undetermined[:3]
        steps.append(("To improve, measure what this sensor and pose set do not see"
                      + (f" ({'; '.join(seen)})" if seen else "")
                      + ": rank the instruments, printed distances and poses that would see it:", suggest))
    elif ident.weak:
        steps.append((f"To improve, measure what is weakly determined ({'; '.join(ident.weak[:3])}): rank the "
                      "instruments and poses that determine it best:", suggest))
    else:
        steps.append(("Every parameter direction is determined; to shrink the uncertainties further, add poses or a "
                      "more precise instrument: rank what would shrink them most:", suggest))
    if data.held_out is None and data.measured_validation is None:
        cal = data.calibrated_file or "CALIBRATED.yaml"
        steps.append(("No held-out data verified this calibration: measure poses that are not used for the fit and "
                      "validate on them:", f"pkmcal verify {cal} --held-out HELDOUT.csv --setup {cal}"))
    return steps


def _opening(data: ReportData) -> str:
    """The report's first section: what was achieved (before → after, people's units) and
    what to do next (the export command, what to measure to improve)."""
    out = ['<section id="summary">', "<h2>What was achieved</h2>"]
    got = achieved(data)
    if got:
        out.append("<ul>" + "".join(f"<li>{_esc(a.text())}</li>" for a in got) + "</ul>")
        out.append(f'<p class="muted">Over {got[0].n} {_esc(got[0].source)}; '
                   f'<span style="color:{F.BEFORE_COLOUR}">before</span>: the nominal machine, '
                   f'<span style="color:{F.AFTER_COLOUR}">after</span>: the calibrated one (these colours in every '
                   "figure).</p>")
    else:
        out.append('<p class="warn">No held-out data: the accuracy of the calibrated machine has not been '
                   "verified (the fit's residuals below show only how well the model explains the data it was "
                   "fitted to).</p>")
    out.append("<h2>What to do next</h2>\n<ol>")
    for text, command in next_steps(data):
        out.append(f"<li>{_esc(text)}" + (f"<pre>{_esc(command)}</pre>" if command else "") + "</li>")
    out.append("</ol>\n</section>")
    return "\n".join(out)


def _held_out_rows(data: ReportData) -> tuple[str, list[list[str]]]:
    s = data.held_out.summary()
    rows = []
    for what, unit, scale in (("position", "µm", 1000.0), ("orientation", "arcsec", ARCSEC)):
        b, a = s[f"{what}_before"], s[f"{what}_after"]
        ratio = b["rms"] / a["rms"] if a["rms"] > 0 else float("inf")
        rows.append([f"{what} ({unit})", _fmt(b["rms"] * scale, ".2f"), _fmt(b["p95"] * scale, ".2f"),
                     _fmt(b["max"] * scale, ".2f"), _fmt(a["rms"] * scale, ".2f"), _fmt(a["p95"] * scale, ".2f"),
                     _fmt(a["max"] * scale, ".2f"), _fmt(ratio, ".1f") + "×"])
    pb, pa = s["position_before"], s["position_after"]
    ob, oa = s["orientation_before"], s["orientation_after"]
    headline = (f"Held-out position error (rms): {pb['rms'] * 1000:.1f} µm before → {pa['rms'] * 1000:.2f} µm after "
                f"calibration; max {pb['max'] * 1000:.1f} → {pa['max'] * 1000:.2f} µm. Orientation error (rms): "
                f"{ob['rms'] * ARCSEC:.1f}″ before → {oa['rms'] * ARCSEC:.2f}″ after; max {ob['max'] * ARCSEC:.1f}″ → "
                f"{oa['max'] * ARCSEC:.2f}″ ({data.held_out.n_poses} poses not used for identification"
                + _held_out_count(data) + ").")
    return headline, rows


def _held_out_count(data: ReportData) -> str:
    """" of K given (n left out, see Verification)" when poses were left out of the comparison."""
    total = data.held_out_total
    if total is None or total == data.held_out.n_poses:
        return ""
    return f" of {total} given ({total - data.held_out.n_poses} left out, see Verification)"


#: Per display unit of a parameter: digits of its values, and the scale of its error
#: against the truth (to µm for mm, to arc-seconds for degrees).
_PARAM_FORMAT = {"mm": (4, 1000.0), "deg": (6, 3600.0)}
#: Other units (a hexapod's leg gains, "1" or "mm/rev"): 6 digits, error in parts per million.
_OTHER_PARAM_FORMAT = (6, 1e6)


def _parameter_rows(t) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the identified-parameters table: each row in its own unit (mm, or
    degrees for the angles of ``t.is_angle``), values, deviation and σ converted alike."""
    nominal, identified, dev, std = (t.display(v) for v in (t.nominal, t.identified, t.deviation, t.std))
    header = ["parameter", "unit", "nominal", "identified", "deviation", "± 1σ"]
    if t.true is not None:
        true = t.display(t.true)
        other = any(u not in _PARAM_FORMAT for u in t.units)
        header += ["true", "error (µm; arcsec for deg" + ("; ppm for the other units)" if other else ")")]
    rows = []
    for i, (name, unit) in enumerate(zip(t.names, t.units)):
        digits, err_scale = _PARAM_FORMAT.get(unit, _OTHER_PARAM_FORMAT)
        row = [_esc(name), unit, _fmt(nominal[i], f".{digits}f"), _fmt(identified[i], f".{digits}f"),
               _fmt(dev[i], f"+.{digits}f"), _fmt(std[i], f".{digits}f") if t.free[i] else "fixed"]
        if t.true is not None:
            row += [_fmt(true[i], f".{digits}f"), _fmt((identified[i] - true[i]) * err_scale, "+.2f")]
        rows.append(row)
    return header, rows


def _outlier_section(data: ReportData) -> str:
    """The Outliers section: threshold, loss, rejection and one row per flagged pose."""
    sc = data.screening
    out = ['<h2 id="outliers">Outliers</h2>']
    if sc is None:
        out.append("<p>No noise model to normalise the residuals with: no outlier screening.</p>")
        return "\n".join(out)
    text = (f"Normalised residual of each pose: √(‖W r‖²/k) over its k residual rows, whitened with the noise "
            f"model (1 on average for a pose as noisy as the setup says); median {_fmt(sc.median_sigma, '.3g')}, "
            f"max {_fmt(sc.max_sigma, '.3g')}. Threshold {sc.threshold:g} σ. ")
    if sc.loss != "linear":
        text += (f"Robust loss {sc.loss} (scipy.optimize.least_squares) with f_scale {sc.f_scale:g} σ: flagged poses "
                 "are down-weighted, and χ² and the covariance are taken over the poses within the threshold. ")
    if sc.reject is not None:
        text += (f"Rejection at {sc.reject:g} σ: {sum(o.dropped for o in sc.outliers)} pose(s) dropped in "
                 f"{sc.rounds} fit(s), each refit without them. ")
    out.append(f"<p>{_esc(text)}Pose numbers: data rows of the measurement file, counted from 1.</p>")
    if not sc.outliers:
        out.append(f"<p>No pose beyond {sc.threshold:g} σ.</p>")
        return "\n".join(out)
    rows = [[str(o.pose), _fmt(o.sigma, ".3g"), _esc(o.reading), _fmt(o.reading_sigma, "+.3g"),
             "dropped" if o.dropped else ("down-weighted" if sc.loss != "linear" else "kept"), str(o.round)]
            for o in sc.outliers]
    out.append(_table(["pose", "σ (pose)", "worst row", "σ (row)", "in the fit", "round"], rows, left=3))
    if any(not o.dropped for o in sc.outliers) and sc.loss == "linear":
        out.append('<p class="warn">Poses beyond the threshold are still in the fit and pull the estimate: check '
                   "them, drop them (identify --reject K) or bound their influence (identify --loss soft_l1).</p>")
    return "\n".join(out)


def _prior_section(data: ReportData) -> str:
    """The Priors section (only when the fit had Gaussian priors)."""
    if not data.priors:
        return ""
    rows = [[_esc(p.parameter), p.unit, _fmt(p.mean, ".6g"), _fmt(p.std, ".4g"), _fmt(p.estimate, ".6g"),
             _fmt(p.posterior_std, ".4g"), _fmt(p.pull, "+.2f"), _esc(p.source)] for p in data.priors]
    return "\n".join([
        '<h2 id="priors">Priors</h2>',
        "<p>Gaussian priors (maximum a posteriori): each adds the residual row (θ − μ)/σ to the fit, and the "
        "standard deviations of this report are the posterior ones, (JᵀWJ + P)⁻¹. A parameter whose "
        "posterior σ is close to its prior σ is determined by the prior, not by the measurements; "
        "pull = (estimate − mean)/σ.</p>",
        _table(["parameter", "unit", "prior mean", "prior σ", "estimate", "posterior σ", "pull", "source"], rows,
               left=2)])


def render_html(data: ReportData, figs: list[F.RenderedFigure]) -> str:
    """The report page (a string) for ``data`` with the rendered figures ``figs``."""
    by_name = {f.name: f for f in figs}
    fig = lambda name: _figure_html(by_name[name]) if name in by_name else ""  # noqa: E731
    parts: list[str] = []
    add = parts.append
    add("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
        f"<title>{_esc(data.title)}</title>\n<style>{CSS}</style>\n</head>\n<body>")
    add(f"<h1>{_esc(data.title)}</h1>")
    add(_opening(data))
    add('<nav><a href="#summary">Summary</a><a href="#machine">Machine</a><a href="#plan">Pose plan</a><a href="#identifiability">'
        'Identifiability</a><a href="#parameters">Parameters</a>'
        + ('<a href="#priors">Priors</a>' if data.priors else '')
        + '<a href="#residuals">Residuals</a><a href="#outliers">Outliers</a>'
        '<a href="#verification">Verification</a></nav>')
    if data.held_out is not None and data.held_out.n_poses:
        headline, held_rows = _held_out_rows(data)

    # -- machine -----------------------------------------------------------------------
    add('<h2 id="machine">Machine and measurement setup</h2>')
    facts = [("pkmcal version", __version__), ("nominal machine", data.nominal.name),
             ("identified machine", data.identified.name), ("measured poses", str(len(data.poses)))]
    facts += list(data.facts)
    add(_table(["item", "value"], [[_esc(k), _esc(v)] for k, v in facts], left=2))
    add(f"<pre>{_esc(data.machine_summary)}</pre>")
    if data.setup_summary:
        add(f"<h3>Measurement setup</h3>\n<pre>{_esc(data.setup_summary)}</pre>")

    # -- plan --------------------------------------------------------------------------
    add('<h2 id="plan">Pose plan</h2>')
    shown = pose_points(data.nominal, data.poses) if len(data.poses) else None
    if shown is not None:
        add(f"<p>{_plan_extent(shown, len(data.poses))}.</p>")
    add(fig("machine-poses"))
    add(fig("pose-cloud"))

    # -- identifiability ---------------------------------------------------------------
    ident = data.identifiability
    add('<h2 id="identifiability">Identifiability</h2>')
    rows = [["rank", f"{ident.rank} of {ident.n_params} candidate parameters"],
            ["condition number (σ₁/σ_rank)", _fmt(ident.condition_number, ".4g") if ident.condition_number else "—"],
            ["fixed (gauge and user)", _esc(", ".join(ident.fixed) or "none")],
            ["weak directions", _esc("; ".join(ident.weak) or "none")],
            ["null space", _esc("; ".join(ident.null_space) or "none (full rank)")]]
    if ident.basis:
        rows.append(["Jacobian evaluated at", _esc(ident.basis)])
    add(_table(["quantity", "value"], rows, left=2))
    if ident.rank < ident.n_params:
        add(f'<p class="warn">The data determine only {ident.rank} of {ident.n_params} parameter directions. '
            "The combinations listed under null space cannot be seen by this sensor and pose set; a gauge "
            "of parameters (listed as fixed) was held at nominal so that the rest is identifiable.</p>")
    add(fig("singular-values"))

    # -- parameters --------------------------------------------------------------------
    t = data.parameters
    add('<h2 id="parameters">Identified parameters</h2>')
    add(fig("parameters"))
    add(fig("parameter-errors"))
    add(_table(*_parameter_rows(t), left=2, row_class=["" if f else "fixed" for f in t.free]))
    if len(data.correlation_names) > 1:
        c = np.array(data.correlation, dtype=float)
        iu = np.triu_indices(len(data.correlation_names), k=1)
        vals = np.abs(c[iu])
        order = np.lexsort((iu[1], iu[0], -np.nan_to_num(vals, nan=-1.0)))[:8]
        strong = [[_esc(data.correlation_names[iu[0][k]]), _esc(data.correlation_names[iu[1][k]]),
                   _fmt(c[iu][k], "+.3f")] for k in order if np.isfinite(vals[k])]
        add(fig("correlation"))
        if strong:
            add("<h3>Strongest correlations</h3>")
            add(_table(["parameter", "parameter", "correlation"], strong, left=2))

    add(_prior_section(data))

    # -- residuals ---------------------------------------------------------------------
    r = data.residuals
    add('<h2 id="residuals">Residuals</h2>')
    if r.values.size:
        rrows = []
        for k, name in enumerate(r.names):
            unit, scale = F.residual_display(r.units[k])
            s = summarise(np.abs(r.values[:, k]))
            rrows.append([_esc(name), unit, _fmt(s["rms"] * scale, ".3f"), _fmt(s["p95"] * scale, ".3f"),
                          _fmt(s["max"] * scale, ".3f")])
        add(_table(["reading", "unit", "rms", "p95 |r|", "max |r|"], rrows, left=2))
        if "1" in r.units:
            add("<p>Rows of unit 1 combine readings (the projection method, paper 3 eq. 8): divided by the "
                "noise σ in a weighted fit, else mixing mm and rad; shown as computed.</p>")
        scales = np.array([F.residual_display(u)[1] for u in r.units])
        worst = np.argsort(-np.sqrt(np.mean((r.values * scales) ** 2, axis=1)), kind="stable")[:3]
        add(f"<p>Poses with the largest residuals: {', '.join(str(int(r.pose_numbers[w])) for w in worst)} "
            "(pose numbers: data rows of the measurement file, counted from 1).</p>")
    add(fig("residuals-per-pose"))
    add(fig("residuals-per-reading"))
    add(_outlier_section(data))

    # -- verification ------------------------------------------------------------------
    add('<h2 id="verification">Verification on held-out poses</h2>')
    if data.held_out is not None and data.held_out.n_poses:
        add(f'<p class="headline">{_esc(headline)}</p>')
        add(f"<p>{data.held_out.n_poses} held-out poses compared"
            + (f" of {data.held_out_total} given" if data.held_out_total is not None else "")
            + ": the poses the real machine reaches when commanded through both models, so that before and "
            "after are taken over the same poses.</p>")
        if data.held_out_dropped:
            add("<p>Left out (held-out pose number, counted from 1: why; the model named is the one whose "
                "commands the real machine could not follow):</p>")
            add(_table(["pose", "reason"], [[str(k), _esc(w)] for k, w in data.held_out_dropped], left=2))
        add(_table(["error", "before rms", "before p95", "before max", "after rms", "after p95", "after max",
                    "rms ratio"], held_rows))
        add(fig("held-out"))
        add(fig("held-out-per-pose"))
    elif data.measured_validation is None:
        add("<p>No held-out poses were given.</p>")
    add(_measured_validation_section(data.measured_validation))
    if data.error_map is not None:
        add("<h3>Error map</h3>")
        add(fig("error-map"))
    add(f'<p class="muted">Written by pkmcal {_esc(__version__)}. Figures are also saved beside this file as SVG '
        "and PNG.</p>\n</body>\n</html>\n")
    return "\n".join(x for x in parts if x)


def _measured_validation_section(v: dict | None) -> str:
    """The section on measured held-out data (``identify --held-out``): before / after /
    after_reregistered, the poses left out and the registrations."""
    if v is None:
        return ""
    labels = [k for k in ("before", "after", "after_reregistered") if k in v]
    out = ['<h3 id="measured-validation">Validation on measured held-out data</h3>',
           f"<p>{v['n_poses']} of {v['n_poses_file']} held-out measurements of {_esc(v['measurements'])} predicted "
           f"from their actuator readings (FK, then the sensor) and compared with what was measured; "
           f"{_esc(v['measured_as'])}. <em>before</em>: the nominal machine with its sensor frames registered on the "
           "calibration data; <em>after</em>: the calibrated machine and the identified sensor; "
           "<em>after_reregistered</em>: the calibrated machine with only the sensor's free parameters refitted on "
           "the held-out data (what no re-registration of the instrument removes).</p>"]
    rows = [[_esc(f"{text} ({unit})")] + ["-" if v[lab][key] is None else f"{v[lab][key]:.4g}" for lab in labels]
            for text, unit, key in v["rows"]]
    out.append(_table(["error"] + labels, rows))
    regs = [[_esc(lab), _esc(v[lab]["registration"])] for lab in labels if v[lab].get("registration")]
    if regs:
        out.append(_table(["model", "sensor frames"], regs, left=2))
    if v["failed"]:
        out.append("<p>Not compared (held-out pose number, counted from 1: why):</p>")
        out.append(_table(["pose", "reason"], [[str(f["pose"]), _esc(f["reason"])] for f in v["failed"]], left=2))
    for n in v["notes"]:
        out.append(f'<p class="muted">{_esc(n)}</p>')
    return "\n".join(out)


def write_report(data: ReportData, out_dir: str | os.PathLike, png: bool = True) -> ReportFiles:
    """Write ``report.html`` and its figures (``<name>.svg``, ``<name>.png``) into
    ``out_dir`` (created if needed); every file is written atomically."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise PkmcalError(f"report folder '{out}' exists and is not a folder; choose another -o/--report path")
    make_folder(out, "the report folder")
    figs = build_figures(data, png=png)
    written = []
    for f in figs:
        path = out / f"{f.name}.svg"
        atomic_write_bytes(path, f.svg)
        written.append(path)
        if f.png is not None:
            path = out / f"{f.name}.png"
            atomic_write_bytes(path, f.png)
            written.append(path)
    page = out / REPORT_NAME
    atomic_write_bytes(page, render_html(data, figs).encode("utf-8"))
    return ReportFiles(html=page, figures=tuple(written))
