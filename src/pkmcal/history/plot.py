"""A unit's parameters over time: one panel per estimated parameter, the value of each
calibration at its date with ±k σ bars (k = 1 by default; σ = √Σ_ii of the covariance each
calibration recorded), in file units (mm, deg). PNG or SVG by the file name, written
atomically (:func:`pkmcal.io.atomic.atomic_write_bytes`)."""

from __future__ import annotations

import io
import os
from datetime import datetime

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.history.store import CalibrationRecord


def _when(date: str) -> datetime:
    try:
        return datetime.strptime(date, "%Y-%m-%dT%H:%M:%SZ")
    except ValueError:
        return datetime.fromisoformat(date.replace("Z", "+00:00")).replace(tzinfo=None)


def plot_history(records: list[CalibrationRecord], path: str | os.PathLike, names: list[str] | None = None,
                 k: float = 1.0) -> list[str]:
    """Write the figure of ``records`` (one unit, oldest first) to ``path``; the parameters
    drawn (``names``, default: every parameter some calibration estimated)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in (".png", ".svg"):
        raise PkmcalError(f"-o {path}: use a .png or .svg file name")
    if not records:
        raise PkmcalError("no calibration to plot")
    ref = records[0]
    if any(r.names != ref.names for r in records):
        raise PkmcalError(f"serial '{ref.serial}' has calibrations of different machine kinds; plot one at a time")
    estimated = np.any([~r.held for r in records], axis=0)
    if names is None:
        idx = list(np.flatnonzero(estimated))
    else:
        unknown = [n for n in names if n not in ref.names]
        if unknown:
            raise PkmcalError(f"--parameter {', '.join(unknown)}: not a parameter of '{ref.model}' (its parameters: "
                              f"{', '.join(ref.names)})")
        idx = [ref.names.index(n) for n in names]
    if not idx:
        raise PkmcalError(f"serial '{ref.serial}': no calibration estimated any parameter; nothing to plot")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pkmcal.io.atomic import atomic_write_bytes
    from pkmcal.report.figures import style

    dates = [_when(r.date) for r in records]
    ncol = min(3, len(idx))
    nrow = -(-len(idx) // ncol)
    with style():
        fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 2.6 * nrow), squeeze=False, sharex=True,
                                 constrained_layout=True)
        for ax in axes.flat[len(idx):]:
            ax.set_visible(False)
        for ax, i in zip(axes.flat, idx):
            vals, errs = [], []
            for r in records:
                v, s, u = r.display()
                vals.append(v[i])
                errs.append(np.nan if r.held[i] else k * s[i])
            unit = records[-1].display()[2][i]
            ax.errorbar(dates, vals, yerr=np.nan_to_num(errs), fmt="o-", ms=4, lw=1, capsize=3)
            held = [d for d, e, v in zip(dates, errs, vals) if np.isnan(e)]
            if held:
                ax.plot(held, [v for e, v in zip(errs, vals) if np.isnan(e)], "x", color="grey", label="held")
                ax.legend(fontsize=7)
            ax.set_title(f"{ref.names[i]} ({unit})")
            ax.ticklabel_format(axis="y", useOffset=False)
            ax.tick_params(axis="x", labelrotation=30, labelsize=7)
        fig.suptitle(f"{ref.serial} ({ref.model}): {len(records)} calibration(s), bars ±{k:g} sigma")
        buf = io.BytesIO()
        fig.savefig(buf, format=ext[1:], metadata={"Date": None} if ext == ".svg" else None)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
    return [ref.names[i] for i in idx]


__all__ = ["plot_history"]
