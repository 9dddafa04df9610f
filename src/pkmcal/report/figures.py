"""The report's figures, drawn with matplotlib (Agg) and rendered to deterministic bytes.

Every figure function takes plain data (arrays, :mod:`pkmcal.report.data` dataclasses) and
returns a :class:`matplotlib.figure.Figure`; :func:`render` turns one into SVG and PNG bytes
that are identical from run to run (``svg.hashsalt`` fixed, no creation date in the
metadata, fixed rcParams, no clock or random state involved).

Figures: the hexapod in a few poses (legs l_i = p + R a_i − b_i, paper 2 eq. 1, via
:meth:`~pkmcal.mechanisms.hexapod.Hexapod.leg_vectors`); the pose cloud coloured by tilt
(angle between the platform and base z axes, arccos R₃₃); the singular values of the
identification Jacobian (log scale); parameter deviations ρ̂ − ρ₀ with ±2σ bars (mm, and
degrees for the angle parameters); the parameter correlation matrix; residuals per pose and
per reading; histograms of held-out errors before and after; error maps before and after;
the error of every parameter against the truth and of every held-out pose (paper 1 Figs.
10–11); measurement paths and the error at every path point, forward and backward (paper 3
Figs. 4/5, 7/8).

Colours are defined once: every series of the state before calibration is drawn in
:data:`BEFORE_COLOUR`, every one after it in :data:`AFTER_COLOUR` (:func:`series_colour`,
by the label's "before"/"after"), and no other series uses them (:data:`OTHER_COLOURS`, the
default colour cycle); maps that are compared share one colour scale (:func:`shared_norm`).
"""

from __future__ import annotations

import io
from contextlib import contextmanager
from dataclasses import dataclass

import matplotlib

matplotlib.use("Agg", force=False)

import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.colors  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from pkmcal.report.data import (  # noqa: E402
    ErrorMap,
    HeldOutErrors,
    ParameterTable,
    PosePoints,
    Residuals,
    pose_points,
)

#: The two colours of the report: every series or bar of the state before calibration (the
#: nominal model) is drawn in BEFORE_COLOUR, every one after it (the identified model) in
#: AFTER_COLOUR, in every figure; no other series uses them (:data:`OTHER_COLOURS`).
BEFORE_COLOUR = "#d62728"
AFTER_COLOUR = "#1f77b4"
#: Colours of the series that are neither before nor after (the default colour cycle too).
OTHER_COLOURS = ("#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf")
#: The colour map of the error maps; compared maps share one scale (:func:`shared_norm`).
ERROR_CMAP = "magma"

#: Fixed style: the same bytes on every run and every machine with the same matplotlib.
RC = {
    "svg.hashsalt": "pkmcal-report",
    "svg.fonttype": "path",
    "font.family": "DejaVu Sans",
    "font.size": 9.0,
    "axes.titlesize": 10.0,
    "axes.labelsize": 9.0,
    "figure.dpi": 100.0,
    "savefig.dpi": 100.0,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "image.cmap": "viridis",
    "path.simplify": False,
    "axes.prop_cycle": matplotlib.cycler(color=list(OTHER_COLOURS)),
}
ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0
#: Residual unit (:class:`~pkmcal.report.data.Residuals`) → (display unit, scale).
RESIDUAL_DISPLAY = {"mm": ("µm", 1000.0), "rad": ("arcsec", ARCSEC_PER_RAD), "1": ("1", 1.0)}


def series_colour(label: str, k: int) -> str:
    """The colour of the ``k``-th series labelled ``label``: :data:`BEFORE_COLOUR` for a
    label that starts with "before", :data:`AFTER_COLOUR` for one that starts with "after",
    else the ``k``-th of :data:`OTHER_COLOURS`."""
    low = label.strip().lower()
    if low.startswith("before"):
        return BEFORE_COLOUR
    if low.startswith("after"):
        return AFTER_COLOUR
    return OTHER_COLOURS[k % len(OTHER_COLOURS)]


def shared_norm(*grids: np.ndarray) -> matplotlib.colors.Normalize:
    """One colour scale for maps that are compared: logarithmic from the smallest positive
    finite value of all ``grids`` to the largest (errors before and after differ by orders of
    magnitude), linear over [0, 1] when none is positive."""
    v = np.concatenate([np.ravel(np.asarray(g, dtype=float)) for g in grids])
    v = v[np.isfinite(v) & (v > 0)]
    if not v.size:
        return matplotlib.colors.Normalize(vmin=0.0, vmax=1.0)
    lo, hi = float(v.min()), float(v.max())
    return matplotlib.colors.LogNorm(vmin=lo, vmax=hi if hi > lo else lo * 10.0)


def residual_display(unit: str) -> tuple[str, float]:
    """(shown unit, scale) of a residual unit: :data:`RESIDUAL_DISPLAY`, else the unit itself
    (readings in a unit of their own: a hexapod's ``actuator_unit``, e.g. rev)."""
    return RESIDUAL_DISPLAY.get(unit, (unit, 1.0))


@contextmanager
def style():
    """Context in which all report figures are created and saved."""
    with matplotlib.rc_context(RC):
        yield


@dataclass(frozen=True)
class RenderedFigure:
    """A figure as bytes: ``name`` (file stem), ``caption``, ``svg`` and ``png``."""

    name: str
    caption: str
    svg: bytes
    png: bytes | None


def render(fig: Figure, name: str, caption: str, png: bool = True) -> RenderedFigure:
    """SVG (and PNG) bytes of ``fig``, deterministic; closes the figure."""
    with style():
        buf = io.BytesIO()
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": "pkmcal (matplotlib)"})
        svg = buf.getvalue()
        png_bytes = None
        if png:
            buf = io.BytesIO()
            fig.savefig(buf, format="png", metadata={"Software": "pkmcal (matplotlib)"})
            png_bytes = buf.getvalue()
    plt.close(fig)
    return RenderedFigure(name=name, caption=caption, svg=svg, png=png_bytes)


def _new(figsize, **kw) -> Figure:
    with style():
        return plt.figure(figsize=figsize, **kw)


def pick_display_poses(mechanism, poses: np.ndarray, k: int = 3) -> np.ndarray:
    """Up to ``k`` representative poses of ``mechanism``: home, the most tilted (where its
    poses tilt), the farthest from home."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    home = np.asarray(mechanism.home_pose, dtype=float)
    chosen = [home]
    shown = pose_points(mechanism, poses) if len(poses) else None
    if shown is not None:
        if shown.tilt is not None:
            chosen.append(poses[int(np.argmax(shown.tilt))])
        d = np.linalg.norm(shown.points - pose_points(mechanism, home).points, axis=1)
        chosen.append(poses[int(np.argmax(d))])
    return np.array(chosen[:k])


def machine_poses_figure(machine, poses: np.ndarray, titles: list[str] | None = None) -> Figure:
    """The hexapod drawn in each of a few poses: base and platform polygons (joint centres in
    leg order) and the six legs b_i → p + R a_i (:meth:`Hexapod.leg_vectors`)."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    _, Ra, legs = machine.leg_vectors(poses)
    base = np.asarray(machine.base)
    tops = base[None] + legs
    n = len(poses)
    with style():
        fig = _new((3.4 * n, 3.6))
        lo = np.minimum(base.min(axis=0), tops.reshape(-1, 3).min(axis=0))
        hi = np.maximum(base.max(axis=0), tops.reshape(-1, 3).max(axis=0))
        centre, half = (lo + hi) / 2, (hi - lo).max() / 2
        for k in range(n):
            ax = fig.add_subplot(1, n, k + 1, projection="3d")
            b = np.vstack([base, base[:1]])
            t = np.vstack([tops[k], tops[k, :1]])
            ax.plot(b[:, 0], b[:, 1], b[:, 2], color="0.35", lw=1.5)
            ax.plot(t[:, 0], t[:, 1], t[:, 2], color=OTHER_COLOURS[0], lw=1.8)
            for i in range(base.shape[0]):
                ax.plot([base[i, 0], tops[k, i, 0]], [base[i, 1], tops[k, i, 1]], [base[i, 2], tops[k, i, 2]],
                        color=OTHER_COLOURS[1], lw=1.2)
            p = poses[k, :3]
            ax.scatter([p[0]], [p[1]], [p[2]], color="k", s=8)
            for dim, setter in enumerate((ax.set_xlim, ax.set_ylim, ax.set_zlim)):
                setter(centre[dim] - half, centre[dim] + half)
            ax.set_box_aspect((1, 1, 1))
            ax.view_init(elev=22, azim=-60)
            ax.set_xlabel("x (mm)", labelpad=-6)
            ax.set_ylabel("y (mm)", labelpad=-6)
            ax.set_zlabel("z (mm)", labelpad=-6)
            ax.tick_params(labelsize=6, pad=-2)
            if titles is not None:
                ax.set_title(titles[k], fontsize=8)
        fig.tight_layout()
    return fig


def pose_cloud_figure(shown: PosePoints, held_out: PosePoints | None = None) -> Figure:
    """Measured tool positions in 3D, coloured by platform tilt (deg) where the poses have
    one; a pose pair's two points joined by a line (a printed-object distance; a pair of one
    point, a probe height, is one dot); held-out positions as crosses."""
    with style():
        fig = _new((6.4, 4.6))
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        p = shown.points
        pairs = np.zeros(len(p), dtype=bool) if shown.second is None else np.any(shown.second != p, axis=1)
        single = ~pairs
        colour = dict(color=OTHER_COLOURS[0]) if shown.tilt is None else dict(c=np.rad2deg(shown.tilt)[single],
                                                                           cmap="viridis")
        label = f"measured ({len(p)})" if shown.second is None else f"probe points ({int(single.sum())})"
        sc = ax.scatter(p[single, 0], p[single, 1], p[single, 2], s=16, depthshade=False, label=label, **colour)
        if pairs.any():
            q = shown.second
            for i in np.flatnonzero(pairs):
                ax.plot(*np.stack([p[i], q[i]]).T, color="0.55", lw=0.8)
            ends = np.concatenate([p[pairs], q[pairs]])
            ax.scatter(ends[:, 0], ends[:, 1], ends[:, 2], s=10, color=OTHER_COLOURS[1], depthshade=False,
                       label=f"distance pairs ({int(pairs.sum())})")
        if held_out is not None and len(held_out.points):
            h = held_out.points
            ax.scatter(h[:, 0], h[:, 1], h[:, 2], marker="x", color="0.4", s=14, depthshade=False,
                       label=f"held out ({len(h)})")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_zlabel("z (mm)")
        ax.tick_params(labelsize=7)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(matplotlib.ticker.MaxNLocator(5))
        ax.view_init(elev=22, azim=-60)
        if shown.tilt is not None:
            cb = fig.colorbar(sc, ax=ax, shrink=0.7, pad=0.12)
            cb.set_label("platform tilt (deg)")
        ax.legend(loc="upper left", fontsize=7)
        ax.set_title("Measurement poses")
    return fig


def singular_values_figure(singular_values: np.ndarray, rank: int) -> Figure:
    """Singular values of the (column-scaled) identification Jacobian, log scale; the ones
    beyond the numerical rank in grey."""
    s = np.asarray(singular_values, dtype=float)
    idx = np.arange(1, s.size + 1)
    with style():
        fig = _new((6.4, 3.2))
        ax = fig.add_subplot(1, 1, 1)
        pos = np.where(s > 0, s, np.nan)
        ax.semilogy(idx[:rank], pos[:rank], "o-", color=OTHER_COLOURS[0], ms=4, label=f"rank {rank}")
        if rank < s.size:
            ax.semilogy(idx[rank:], pos[rank:], "o", color="0.6", ms=4, label="beyond rank")
        ax.set_xlabel("index")
        ax.set_ylabel("singular value")
        ax.set_title("Identification Jacobian: singular values")
        ax.legend(fontsize=8)
        fig.tight_layout()
    return fig


def parameter_figure(table: ParameterTable) -> Figure:
    """Deviation from nominal ρ̂ − ρ₀ of every parameter with ±2σ error bars; the true
    deviation (simulation) as open circles; fixed parameters in grey. One panel per unit:
    lengths in mm, angles (``table.is_angle``) in degrees."""
    dev, std = table.display(table.deviation), table.display(table.std)
    true_dev = None if table.true is None else table.display(table.true - table.nominal)
    units = np.array(table.units)
    shown = ("mm", "deg") + tuple(u for u in dict.fromkeys(table.units) if u not in ("mm", "deg"))
    groups = [(u, np.flatnonzero(units == u)) for u in shown if np.any(units == u)] or [("mm", np.arange(0))]
    with style():
        width = max(6.4, 0.16 * max(len(cols) for _, cols in groups) + 1.5)
        fig = _new((width, 3.6 * len(groups)))
        for g, (unit, cols) in enumerate(groups):
            ax = fig.add_subplot(len(groups), 1, g + 1)
            idx = np.arange(len(cols))
            free = table.free[cols]
            err = np.where(free & np.isfinite(std[cols]), 2.0 * std[cols], 0.0)
            ax.errorbar(idx[free], dev[cols][free], yerr=err[free], fmt="o", ms=3.5, color=OTHER_COLOURS[0],
                        ecolor=OTHER_COLOURS[0], elinewidth=1, capsize=2, label="identified ± 2σ")
            if (~free).any():
                ax.plot(idx[~free], dev[cols][~free], "s", ms=3.5, color="0.6", label="fixed")
            if true_dev is not None:
                ax.plot(idx, true_dev[cols], "o", mfc="none", mec=OTHER_COLOURS[1], ms=6, label="true (simulation)")
            ax.axhline(0.0, color="0.3", lw=0.8)
            ax.set_xticks(idx)
            ax.set_xticklabels([table.names[c] for c in cols], rotation=90, fontsize=6)
            ax.set_xlim(-0.8, len(idx) - 0.2)
            ax.set_ylabel(f"deviation from nominal ({unit})")
            if g == 0:
                ax.set_title("Identified parameters")
            ax.legend(fontsize=8, loc="best")
        fig.tight_layout()
    return fig


def correlation_figure(corr: np.ndarray, names: tuple[str, ...]) -> Figure:
    """Heat map of the parameter correlation matrix ρ_ij = C_ij / sqrt(C_ii C_jj)."""
    corr = np.asarray(corr, dtype=float)
    n = len(names)
    size = min(9.0, max(4.5, 0.16 * n + 2.0))
    with style():
        fig = _new((size + 1.0, size))
        ax = fig.add_subplot(1, 1, 1)
        im = ax.imshow(np.ma.masked_invalid(corr), cmap="RdBu_r", vmin=-1.0, vmax=1.0, interpolation="nearest")
        ax.set_xticks(np.arange(n))
        ax.set_yticks(np.arange(n))
        fs = 6 if n > 20 else 8
        ax.set_xticklabels(names, rotation=90, fontsize=fs)
        ax.set_yticklabels(names, fontsize=fs)
        ax.grid(False)
        cb = fig.colorbar(im, ax=ax, shrink=0.8)
        cb.set_label("correlation")
        ax.set_title("Correlation of the identified parameters")
        fig.tight_layout()
    return fig


def _unit_groups(res: Residuals):
    """Residual columns grouped by unit: (label, scale, column indices)."""
    groups = []
    units = np.array(res.units)
    for unit in tuple(RESIDUAL_DISPLAY) + tuple(u for u in dict.fromkeys(res.units) if u not in RESIDUAL_DISPLAY):
        shown, scale = residual_display(unit)
        cols = np.flatnonzero(units == unit)
        if cols.size:
            label = "residual (whitened or mixed units)" if unit == "1" else f"residual ({shown})"
            groups.append((label, scale, cols))
    return groups


def residual_pose_figure(res: Residuals) -> Figure:
    """Residual of every reading against the pose number (its data row in the measurement
    file, 1-based; one marker series per reading)."""
    groups = _unit_groups(res)
    idx = res.pose_numbers
    with style():
        fig = _new((7.2, 2.8 * len(groups) + 0.4))
        for g, (label, scale, cols) in enumerate(groups):
            ax = fig.add_subplot(len(groups), 1, g + 1)
            for c in cols:
                ax.plot(idx, res.values[:, c] * scale, ".", ms=4, label=res.names[c])
            ax.axhline(0.0, color="0.3", lw=0.8)
            ax.set_ylabel(label)
            ax.legend(fontsize=7, ncol=min(6, len(cols)), loc="upper right")
            if g == len(groups) - 1:
                ax.set_xlabel("pose (data row of the measurement file, from 1)")
            if g == 0:
                ax.set_title("Residuals after identification, per pose")
        fig.tight_layout()
    return fig


def residual_sensor_figure(res: Residuals) -> Figure:
    """Distribution of the residuals of each reading (box plots) and their RMS."""
    groups = _unit_groups(res)
    with style():
        fig = _new((7.2, 2.8 * len(groups) + 0.4))
        for g, (label, scale, cols) in enumerate(groups):
            ax = fig.add_subplot(len(groups), 1, g + 1)
            data = [res.values[:, c] * scale for c in cols]
            ax.boxplot(data, showfliers=True, widths=0.5,
                       flierprops={"markersize": 3})
            ax.set_xticks(np.arange(1, len(cols) + 1))
            rms = [np.sqrt(np.mean(d**2)) for d in data]
            ax.set_xticklabels([f"{res.names[c]}\nrms {r:.3g}" for c, r in zip(cols, rms)], fontsize=7)
            ax.axhline(0.0, color="0.3", lw=0.8)
            ax.set_ylabel(label)
            if g == 0:
                ax.set_title("Residuals after identification, per reading")
        fig.tight_layout()
    return fig


def held_out_figure(err: HeldOutErrors) -> Figure:
    """Histograms of the held-out position (µm) and orientation (arcsec) errors, before
    (nominal model) and after (identified model), on log-spaced bins."""
    with style():
        fig = _new((7.2, 3.0))
        for k, (attr, label, scale) in enumerate(
            (("position", "position error (µm)", 1000.0), ("orientation", "orientation error (arcsec)", ARCSEC_PER_RAD))
        ):
            ax = fig.add_subplot(1, 2, k + 1)
            before = getattr(err, f"{attr}_before") * scale
            after = getattr(err, f"{attr}_after") * scale
            both = np.concatenate([before, after])
            both = both[np.isfinite(both) & (both > 0)]
            lo, hi = (float(both.min()), float(both.max())) if both.size else (1e-3, 1.0)
            # Errors before and after differ by orders of magnitude: log-spaced bins, log axis.
            bins = np.geomspace(lo / 1.2, hi * 1.2, 41)
            ax.hist(before, bins=bins, color=BEFORE_COLOUR, alpha=0.6, label="before (nominal)")
            ax.hist(after, bins=bins, color=AFTER_COLOUR, alpha=0.75, label="after (identified)")
            ax.set_xscale("log")
            ax.set_xlabel(label)
            ax.set_ylabel("held-out poses")
            ax.legend(fontsize=7)
        fig.suptitle(f"Held-out verification ({err.n_poses} poses)", fontsize=10)
        fig.tight_layout()
    return fig


def error_map_figure(em: ErrorMap) -> Figure:
    """Position error (µm) over an x–y grid at height z, before and after, on one colour
    scale (:func:`shared_norm`: the same limits for both maps, logarithmic), with one colour
    bar; each map's title in its colour (:data:`BEFORE_COLOUR`, :data:`AFTER_COLOUR`)."""
    with style():
        fig = _new((7.6, 3.3), layout="constrained")     # the colour bar shared by both maps
        extent = (em.x[0], em.x[-1], em.y[0], em.y[-1])
        grids = (em.before * 1000.0, em.after * 1000.0)
        norm = shared_norm(*grids)
        axes = []
        for k, (grid, label) in enumerate(zip(grids, ("before (nominal)", "after (identified)"))):
            ax = fig.add_subplot(1, 2, k + 1)
            shown = np.where(grid > 0, grid, np.nan) if isinstance(norm, matplotlib.colors.LogNorm) else grid
            im = ax.imshow(np.ma.masked_invalid(shown), origin="lower", extent=extent, cmap=ERROR_CMAP, norm=norm,
                           interpolation="nearest", aspect="equal")
            ax.set_xlabel("x (mm)")
            ax.set_ylabel("y (mm)")
            ax.grid(False)
            ax.set_title(label, fontsize=9, color=series_colour(label, k))
            axes.append(ax)
        cb = fig.colorbar(im, ax=axes, shrink=0.85)
        cb.set_label("position error (µm), one scale for both")
        a, b, c = np.rad2deg(em.abc)
        fig.suptitle(f"Error map at z = {em.z:.1f} mm, a b c = {a:.1f} {b:.1f} {c:.1f}°", fontsize=10)
    return fig


def _log_positive(values: np.ndarray) -> np.ndarray:
    """``values`` with zeros and non-finite entries as NaN, for a log axis."""
    v = np.asarray(values, dtype=float)
    return np.where(np.isfinite(v) & (v > 0), v, np.nan)


def parameter_errors_figure(names, errors: dict[str, np.ndarray], is_angle=None,
                            title: str = "Parameter errors against the truth") -> Figure:
    """|estimate − truth| of every parameter for one or more estimates (``errors``: label →
    (n,) internal units), log scale; lengths in mm, angles (``is_angle``) in degrees, one
    panel per unit (paper 1 Fig. 10: the identified parameters against the real ones)."""
    names = tuple(names)
    ang = np.zeros(len(names), dtype=bool) if is_angle is None else np.asarray(is_angle, dtype=bool)
    groups = [(u, np.flatnonzero(ang == a)) for u, a in (("mm", False), ("deg", True)) if np.any(ang == a)]
    markers = "os^Dv<>"
    with style():
        width = max(6.4, 0.16 * max(len(c) for _, c in groups) + 1.5)
        fig = _new((width, 3.4 * len(groups)))
        for g, (unit, cols) in enumerate(groups):
            ax = fig.add_subplot(len(groups), 1, g + 1)
            idx = np.arange(len(cols))
            for k, (label, e) in enumerate(errors.items()):
                e = np.abs(np.asarray(e, dtype=float)[cols])
                e = np.rad2deg(e) if unit == "deg" else e
                mean = np.nanmean(e) if np.isfinite(e).any() else float("nan")
                ax.semilogy(idx, _log_positive(e), markers[k % len(markers)], ms=4, mfc="none" if k else None,
                            color=series_colour(label, k), label=f"{label} (mean {mean:.3g} {unit})")
            ax.set_xticks(idx)
            ax.set_xticklabels([names[c] for c in cols], rotation=90, fontsize=6)
            ax.set_xlim(-0.8, len(idx) - 0.2)
            ax.set_ylabel(f"|error| ({unit})")
            if g == 0:
                ax.set_title(title)
            ax.legend(fontsize=7, loc="best")
        fig.tight_layout()
    return fig


def per_pose_errors_figure(position: dict[str, np.ndarray], orientation: dict[str, np.ndarray] | None = None,
                           title: str = "Errors at the held-out poses", xlabel: str = "held-out pose") -> Figure:
    """Position (µm) and orientation (arcsec) error of every pose, one marker series per
    model (``position``/``orientation``: label → (N,) mm / rad), log scale (paper 1 Fig. 11:
    the verification poses after calibration)."""
    panels = [(position, "position error (µm)", 1000.0)]
    if orientation:
        panels.append((orientation, "orientation error (arcsec)", ARCSEC_PER_RAD))
    markers = "os^Dv<>"
    with style():
        fig = _new((7.2, 2.8 * len(panels) + 0.4))
        for p, (series, label, scale) in enumerate(panels):
            ax = fig.add_subplot(len(panels), 1, p + 1)
            for k, (name, e) in enumerate(series.items()):
                e = np.asarray(e, dtype=float)
                ax.semilogy(np.arange(1, e.size + 1), _log_positive(e * scale), markers[k % len(markers)] + "-",
                            lw=0.6, ms=4, mfc="none" if k else None, color=series_colour(name, k), label=name)
            ax.set_ylabel(label)
            ax.legend(fontsize=7, loc="best")
            ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
            if p == 0:
                ax.set_title(title)
            if p == len(panels) - 1:
                ax.set_xlabel(xlabel)
        fig.tight_layout()
    return fig


def path_figure(points: np.ndarray, forward: np.ndarray, calibration: np.ndarray,
                title: str = "Measurement path") -> Figure:
    """The measured points (N, 2) (mm) in their order: the path as a thin line, forward
    passes as circles, backward passes as crosses, calibration points filled and the
    verification points open (paper 3 Figs. 4 and 7)."""
    pts = np.asarray(points, dtype=float)
    fwd, cal = np.asarray(forward, dtype=bool), np.asarray(calibration, dtype=bool)
    with style():
        fig = _new((6.0, 4.6))
        ax = fig.add_subplot(1, 1, 1)
        ax.plot(pts[:, 0], pts[:, 1], "-", color="0.7", lw=0.8, zorder=1)
        for sel, marker, label in ((fwd & cal, "o", "calibration, forward"), (~fwd & cal, "x", "calibration, backward"),
                                   (fwd & ~cal, "s", "verification, forward"),
                                   (~fwd & ~cal, "+", "verification, backward")):
            if sel.any():
                ax.plot(pts[sel, 0], pts[sel, 1], marker, ms=6, mfc="none", label=f"{label} ({int(sel.sum())})",
                        color=OTHER_COLOURS[0] if "calibration" in label else OTHER_COLOURS[1], zorder=2)
        for k in (0, len(pts) - 1):
            ax.annotate("start" if k == 0 else "end", pts[k], textcoords="offset points", xytext=(5, 5), fontsize=7)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(title)
        ax.legend(fontsize=7, loc="best")
        fig.tight_layout()
    return fig


def path_errors_figure(before: np.ndarray, after: dict[str, np.ndarray], forward: np.ndarray,
                       calibration: np.ndarray | None = None, title: str = "Position error along the path") -> Figure:
    """Tool-point error (µm) at every point of a measurement path, before (nominal model) and
    after calibration by each model of ``after`` (label → (N,) mm), forward points as circles
    and backward points as crosses, as paper 3 Figs. 5 and 8 (○/× before, ◇/+ after; further
    models after: □/1, △/2, ▽/3, all in :data:`AFTER_COLOUR`); points not used for
    calibration are shaded."""
    fwd = np.asarray(forward, dtype=bool)
    idx = np.arange(1, fwd.size + 1)
    # every model after in AFTER_COLOUR, told apart by its markers (forward, backward)
    markers = [("o", "x"), ("D", "+"), ("s", "1"), ("^", "2"), ("v", "3")]
    series = [("before", np.asarray(before, dtype=float), BEFORE_COLOUR, markers[0])]
    series += [(f"after: {k}", np.asarray(v, dtype=float), AFTER_COLOUR, markers[1 + i % (len(markers) - 1)])
               for i, (k, v) in enumerate(after.items())]
    with style():
        fig = _new((7.6, 3.8))
        ax = fig.add_subplot(1, 1, 1)
        if calibration is not None:
            cal = np.asarray(calibration, dtype=bool)
            for k in np.flatnonzero(~cal):
                ax.axvspan(idx[k] - 0.5, idx[k] + 0.5, color="0.92", lw=0, zorder=0)
        for label, e, colour, (m_fwd, m_bwd) in series:
            e = _log_positive(e * 1000.0)
            ax.semilogy(idx[fwd], e[fwd], m_fwd, ms=4, mfc="none", color=colour, label=f"{label}, forward")
            ax.semilogy(idx[~fwd], e[~fwd], m_bwd, ms=5, color=colour, label=f"{label}, backward")
        ax.set_xlabel("measurement point (path order)" + ("; shaded: not used for calibration"
                                                          if calibration is not None else ""))
        ax.set_ylabel("position error (µm)")
        ax.set_title(title)
        ax.legend(fontsize=6.5, ncol=2, loc="best")
        fig.tight_layout()
    return fig


def error_slices_figure(values: np.ndarray, position: np.ndarray, orientation: np.ndarray, magnitude: float,
                        title: str = "") -> Figure:
    """Pose error along slices of each pose coordinate (paper 1 Figs. 4–9): one column per
    coordinate x … c, position error (µm) on top, orientation error (arcsec) below, one line
    per slice (:class:`~pkmcal.planning.error_maps.ErrorSlices` arrays: ``values`` (6, P),
    ``position``/``orientation`` (6, C, P), mm and rad)."""
    names = ("x", "y", "z", "a", "b", "c")
    with style():
        fig = _new((15.0, 5.2))
        for k, name in enumerate(names):
            x = values[k] if k < 3 else np.rad2deg(values[k])
            for row, (data, scale, label) in enumerate(((position, 1000.0, "position error (µm)"),
                                                        (orientation, ARCSEC_PER_RAD, "orientation error (arcsec)"))):
                ax = fig.add_subplot(2, 6, row * 6 + k + 1)
                for curve in data[k]:
                    ax.plot(x, curve * scale, lw=0.7)
                if k == 0:
                    ax.set_ylabel(label)
                if row == 1:
                    ax.set_xlabel(f"{name} ({'mm' if k < 3 else 'deg'})")
                ax.tick_params(labelsize=7)
        fig.suptitle(title or f"Pose error from ±{magnitude:g} mm parameter errors (paper 1 Figs. 4–9)", fontsize=10)
        fig.tight_layout()
    return fig


def accuracy_map_figure(amap) -> Figure:
    """The predicted accuracy over the workspace (:class:`~pkmcal.identification.iso9283.AccuracyMap`):
    the 95 % bound of the tool point's position error (µm) at the grid points of the three
    heights with the most reachable points, x against y, one colour scale; the ISO 9283
    cube's P1..P5 marked in the panel nearest their height."""
    g = amap.grid
    z = np.round(g.poses[:, 2], 9)
    levels, counts = np.unique(z, return_counts=True)
    shown = np.sort(levels[np.argsort(-counts, kind="stable")[:3]])      # the three fullest heights
    fig = _new((4.0 * len(shown) + 1.0, 3.8), constrained_layout=True)
    axes = fig.subplots(1, len(shown), sharex=True, sharey=True, squeeze=False)[0]
    vmin, vmax = 1e3 * float(np.min(g.position)), 1e3 * float(np.max(g.position))
    cube = amap.cube.poses
    near = int(np.argmin(np.abs(shown - float(np.mean(cube[:, 2])))))
    for k, (ax, level) in enumerate(zip(axes, shown)):
        m = z == level
        sc = ax.scatter(g.poses[m, 0], g.poses[m, 1], c=1e3 * g.position[m], vmin=vmin, vmax=vmax, s=60)
        if k == near:
            ax.plot(cube[:, 0], cube[:, 1], "k+", ms=8, label="ISO 9283 P1..P5")
            ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.06), fontsize=7, frameon=False)
        ax.set_title(f"z = {level:.4g} mm", loc="left")
        ax.set_xlabel("x (mm)")
        ax.set_aspect("equal")
    axes[0].set_ylabel("y (mm)")
    fig.colorbar(sc, ax=list(axes), label=f"{100 * g.level:g} % bound of the position error (µm)")
    return fig
