"""Study figures (matplotlib, rendered deterministically by :func:`pkmcal.report.figures.render`).

* ``error-vs-poses``: per machine and method, the median held-out position error (for a
  line compared on readings that are no position, its reading error: :data:`TOP_ROW`) and tilt
  error after calibration (the tilt is what dial indicators calibrate; for a machine
  without tilt its height error, or its orientation error: :data:`MIDDLE_ROW`) and the median rms
  parameter error (θ̂ − θ* over the free length parameters) against the number of planned poses, one line per setup × plan, with
  the 95 % intervals of the medians (binomial order statistics) as bars; log-log axes.
  Paper 2 Fig. 6 is this plot for random poses.
* ``distributions``: box plots of the held-out position error after calibration per
  configuration (box: quartiles; whiskers: 5 %–95 %), log axis, with the median error
  before calibration as a cross.
* ``coverage``: per configuration, the mean fraction of free parameters inside their
  reported 95 % interval (t interval) and the fraction of trials whose truth lies inside
  the joint 95 % ellipsoid (Wilson interval); both should be 0.95 when the reported
  covariance is right.
"""

from __future__ import annotations

import numpy as np

from pkmcal.report.figures import RenderedFigure, render, style
from pkmcal.study.results import summary_lookup, t_interval, wilson_interval


def _configs(cols: dict) -> list[tuple[int, str]]:
    cfg = cols["config"].astype(int)
    out = []
    for c in np.unique(cfg):
        i = np.flatnonzero(cfg == c)[0]
        out.append((int(c), f"{cols['machine'][i]} | {cols['setup'][i]} | {cols['plan'][i]} "
                            f"{int(cols['n_poses'][i])} | {cols['method'][i]}"))
    return out


def _bar(m: float, lo: float, hi: float) -> list[list[float]]:
    """Error-bar lengths of the interval [lo, hi] about ``m``: 0 where the interval is
    undefined (NaN) or, by rounding, on the wrong side of ``m`` (a Wilson interval of 0/n)."""
    return [[m - lo if m - lo > 0 else 0.0], [hi - m if hi - m > 0 else 0.0]]


def _finite(v: np.ndarray) -> np.ndarray:
    return v[np.isfinite(v)]


#: The top row of ``error-vs-poses``: the held-out position error, or for a configuration
#: compared on readings that are no position (dial indicators, a Z probe) the reading error.
TOP_ROW = (("heldout_position_rms_mm", "held-out position error, rms (mm)"),
           ("heldout_reading_rms_mm", "held-out reading error, rms (mm)"))
#: The middle row of ``error-vs-poses``: the first of these the machine has (a hexapod the
#: tilt, which dial indicators calibrate; a delta the height, which a Z probe does; a planar
#: machine with a plate angle its orientation).
MIDDLE_ROW = (("heldout_tilt_rms_deg", "held-out tilt error, rms (deg)"),
              ("heldout_height_rms_mm", "held-out height error, rms (mm)"),
              ("heldout_orientation_rms_deg", "held-out orientation error, rms (deg)"))


def _row(choices: tuple, look: dict, configs: list[int]) -> tuple:
    """(metric, axis label) of a row for a panel of ``configs``: the first of ``choices``
    summarised for them, (None, None) when none is."""
    for metric, label in choices:
        if any((c, metric) in look for c in configs):
            return metric, label
    return None, None


def error_vs_poses(cols: dict, summary: list) -> RenderedFigure | None:
    """The ``error-vs-poses`` figure, or None when no plan has several pose counts."""
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    look = summary_lookup(summary)
    cfg = cols["config"].astype(int)
    groups: dict[tuple[str, str], dict[tuple[str, str], list[tuple[int, int]]]] = {}
    for c in np.unique(cfg):
        i = np.flatnonzero(cfg == c)[0]
        panel = (cols["machine"][i], cols["method"][i])
        line = (cols["setup"][i], cols["plan"][i])
        groups.setdefault(panel, {}).setdefault(line, []).append((int(cols["n_poses"][i]), int(c)))
    if not any(len(pts) > 1 for lines in groups.values() for pts in lines.values()):
        return None
    with style():
        fig, axes = plt.subplots(3, len(groups), figsize=(4.6 * len(groups), 8.4), squeeze=False, sharex="col")
        for k, ((machine, method), lines) in enumerate(sorted(groups.items())):
            configs = [c for pts in lines.values() for _, c in pts]
            for row, metric, label in ((0,) + _row(TOP_ROW, look, configs),
                                       (1,) + _row(MIDDLE_ROW, look, configs),
                                       (2, "param_error_rms_mm", "parameter error θ̂ − θ*, rms (mm)")):
                ax = axes[row, k]
                if metric is None:
                    ax.text(0.5, 0.5, "no such held-out error\nfor these configurations", ha="center",
                            va="center", fontsize=8, transform=ax.transAxes)
                    ax.set_yticks([])
                    continue
                mixed = False
                for (setup, plan), pts in sorted(lines.items()):
                    pts.sort()
                    # the top row: a line compared on readings (indicators) shows its reading error
                    line_metric = (_row(TOP_ROW, look, [c for _, c in pts])[0] or metric) if row == 0 else metric
                    tag = " (reading)" if line_metric != metric else ""
                    mixed |= bool(tag)
                    x, y, lo, hi = [], [], [], []
                    for n, c in pts:
                        s = look.get((c, line_metric))
                        if s is None or not s["n"]:
                            continue
                        x.append(n)
                        y.append(s["median"])
                        lo.append(s["median"] - s["median_ci_low"] if np.isfinite(s["median_ci_low"]) else 0.0)
                        hi.append(s["median_ci_high"] - s["median"] if np.isfinite(s["median_ci_high"]) else 0.0)
                    if x:
                        ax.errorbar(x, y, yerr=[lo, hi], marker="o", ms=3, capsize=2, label=f"{setup}, {plan}{tag}")
                ax.set_xscale("log")
                ax.set_yscale("log")
                ax.set_ylabel(label + ("\n(reading): rms reading error (mm)" if mixed else ""))
                counts = sorted({n for pts in lines.values() for n, _ in pts})
                ax.set_xticks(counts, [str(n) for n in counts])
                ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
                if row == 0:
                    ax.set_title(f"{machine}, {method}")
                    if ax.get_legend_handles_labels()[0]:   # no line: every trial of the panel failed
                        ax.legend(fontsize=7)
                elif row == 2:
                    ax.set_xlabel("planned poses")
        fig.tight_layout()
    return render(fig, "error-vs-poses", "Median errors after calibration against the number of poses "
                  "(bars: 95 % intervals of the medians)")


def distributions(cols: dict) -> RenderedFigure:
    import matplotlib.pyplot as plt

    configs = _configs(cols)
    cfg = cols["config"].astype(int)
    with style():
        fig = plt.figure(figsize=(8.0, 1.2 + 0.32 * len(configs)))
        ax = fig.add_subplot(1, 1, 1)
        data = [_finite(cols["heldout_position_rms_mm"][cfg == c]) for c, _ in configs]
        keep = [k for k, d in enumerate(data) if d.size]
        if keep:
            import matplotlib

            horizontal = ({"orientation": "horizontal"} if tuple(int(x) for x in matplotlib.__version__.split(".")[:2])
                          >= (3, 10) else {"vert": False})
            ax.boxplot([data[k] for k in keep], positions=keep, whis=(5, 95), showfliers=False, widths=0.6,
                       **horizontal)
            before = [np.median(_finite(cols["heldout_position_rms_before_mm"][cfg == configs[k][0]]))
                      for k in keep]
            ax.plot(before, keep, "x", color="#d62728", label="median before calibration")
            ax.set_xscale("log")
            ax.legend(fontsize=7, loc="lower right")
        ax.set_yticks(range(len(configs)))
        ax.set_yticklabels([name for _, name in configs], fontsize=7)
        ax.invert_yaxis()
        ax.set_xlabel("held-out position error after calibration, rms (mm)")
        fig.tight_layout()
    return render(fig, "distributions", "Held-out position error after calibration per configuration "
                  "(box: quartiles, whiskers: 5-95 %)")


def coverage(cols: dict) -> RenderedFigure:
    import matplotlib.pyplot as plt

    configs = _configs(cols)
    cfg = cols["config"].astype(int)
    with style():
        fig = plt.figure(figsize=(8.0, 1.4 + 0.32 * len(configs)))
        ax = fig.add_subplot(1, 1, 1)
        for k, (c, _) in enumerate(configs):
            frac = _finite(cols["coverage_fraction"][cfg == c])
            if frac.size:
                lo, hi = t_interval(frac)
                m = frac.mean()
                ax.errorbar([m], [k - 0.15], xerr=_bar(m, lo, hi), fmt="o", ms=3, color="#1f77b4",
                            label="per-parameter 95 % intervals" if k == 0 else None)
            ell = _finite(cols["ellipsoid_within_95"][cfg == c])
            if ell.size:
                kk = int(ell.sum())
                lo, hi = wilson_interval(kk, ell.size)
                m = kk / ell.size
                ax.errorbar([m], [k + 0.15], xerr=_bar(m, lo, hi), fmt="s", ms=3, color="#2ca02c",
                            label="joint 95 % ellipsoid" if k == 0 else None)
        ax.axvline(0.95, color="k", lw=0.8, ls="--")
        ax.set_yticks(range(len(configs)))
        ax.set_yticklabels([name for _, name in configs], fontsize=7)
        ax.invert_yaxis()
        ax.set_xlim(0.0, 1.02)
        ax.set_xlabel("coverage (truth inside the reported 95 % region); target 0.95")
        ax.legend(fontsize=7, loc="lower left")
        fig.tight_layout()
    return render(fig, "coverage", "Coverage of the reported uncertainties (bars: 95 % intervals)")


def study_figures(cols: dict, summary: list) -> list[RenderedFigure]:
    figs = [error_vs_poses(cols, summary), distributions(cols), coverage(cols)]
    return [f for f in figs if f is not None]


__all__ = ["coverage", "distributions", "error_vs_poses", "study_figures"]
