"""A reproduction: the paper's published numbers beside ours, with the setup and notes.

Every reproduction (:mod:`pkmcal.reproduce`) returns a :class:`Reproduction`: rows of
``(quantity, paper, ours, spread, unit)``, the setup it ran (machine, noise, poses, seeds,
Monte Carlo count) and notes explaining every difference. ``paper`` is the number as
published (``None`` where the paper gives none); ``ours`` a measured number.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Row:
    """One line of a table: ``quantity`` in ``unit``; ``paper`` as published (float, or a
    string such as ``"< 0.03"`` for a bound, or None); ``ours`` measured; ``spread`` a
    short text (e.g. ``"sd 0.21"``, ``"[0.3, 1.2]"``); ``group`` a section heading."""

    quantity: str
    paper: float | str | None
    ours: float
    unit: str = ""
    spread: str = ""
    group: str = ""
    note: str = ""

    def to_dict(self) -> dict:
        return {"group": self.group, "quantity": self.quantity, "unit": self.unit, "paper": self.paper,
                "ours": None if not math.isfinite(self.ours) else self.ours, "spread": self.spread,
                "note": self.note}


def _num(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, str):
        return v
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    a = abs(v)
    if a >= 1000 or a < 1e-3:
        return f"{v:.3g}"
    return f"{v:.4g}"


@dataclass(frozen=True)
class FigureSpec:
    """A figure of a reproduction: file stem ``name``, ``caption`` and ``build()`` returning a
    matplotlib Figure (called only when the figures are written, so that a reproduction
    run for its numbers never imports matplotlib)."""

    name: str
    caption: str
    build: Callable[[], object] = field(repr=False, compare=False)


@dataclass(frozen=True)
class Reproduction:
    """A reproduced table. ``setup`` maps setting → value (str); ``headline`` a few numbers
    for the benchmark's JSON line; ``extra`` further tables as (title, header, rows of str);
    ``figures`` the paper's figures as we redraw them (:class:`FigureSpec`)."""

    name: str
    title: str
    rows: tuple[Row, ...]
    setup: dict[str, str]
    notes: tuple[str, ...] = ()
    headline: dict[str, float] = field(default_factory=dict)
    extra: tuple[tuple[str, tuple[str, ...], tuple[tuple[str, ...], ...]], ...] = ()
    seconds: float = float("nan")
    figures: tuple[FigureSpec, ...] = ()

    def row(self, quantity: str, group: str | None = None) -> Row:
        """The row named ``quantity`` (in ``group`` when given)."""
        for r in self.rows:
            if r.quantity == quantity and (group is None or r.group == group):
                return r
        raise KeyError(f"{self.name}: no row '{quantity}'" + (f" in group '{group}'" if group else ""))

    def format(self) -> str:
        """The table for the terminal (ours beside the paper's), then setup and notes."""
        out = [f"{self.name}: {self.title}", ""]
        w = max([len(r.quantity) + (len(r.unit) + 3 if r.unit else 0) for r in self.rows] + [20])
        head = f"{'quantity':<{w}}  {'paper':>12}  {'ours':>12}  spread"
        group = None
        for r in self.rows:
            if r.group != group:
                group = r.group
                out += ([""] if len(out) > 2 else []) + ([f"[{group}]"] if group else []) + [head, "-" * len(head)]
            label = r.quantity + (f" ({r.unit})" if r.unit else "")
            line = f"{label:<{w}}  {_num(r.paper):>12}  {_num(r.ours):>12}  {r.spread}"
            out.append(line + (f"   {r.note}" if r.note else ""))
        for title, header, rows in self.extra:
            out += ["", title]
            widths = [max(len(h), *(len(rw[i]) for rw in rows)) if rows else len(h) for i, h in enumerate(header)]
            out.append("  ".join(h.rjust(wd) for h, wd in zip(header, widths)))
            out += ["  ".join(c.rjust(wd) for c, wd in zip(rw, widths)) for rw in rows]
        out += ["", "setup:"] + [f"  {k}: {v}" for k, v in self.setup.items()]
        if self.notes:
            out += ["", "notes:"] + [f"  - {n}" for n in self.notes]
        if math.isfinite(self.seconds):
            out.append(f"\n({self.seconds:.1f} s)")
        return "\n".join(out)

    def to_dict(self) -> dict:
        return {"name": self.name, "title": self.title, "rows": [r.to_dict() for r in self.rows],
                "setup": dict(self.setup), "notes": list(self.notes), "headline": _headline_json(self.headline),
                "extra": [{"title": t, "header": list(h), "rows": [list(r) for r in rows]} for t, h, rows in self.extra],
                "figures": [{"name": f.name, "caption": f.caption} for f in self.figures],
                "seconds": self.seconds,
                "units": {"seconds": "s",
                          "headline": "per key: its suffix (_mm, _pct, _deg; _rad = the paper's unit, with its "
                                      "_deg twin); paper2_D_E_*, paper2_E_E_*: % (rows D_E, E_E); *_O4_*: 1 "
                                      "(observability index O4)"}}

    def write_figures(self, out_dir, png: bool = True) -> list:
        """Draw :attr:`figures` and write ``<name>.svg`` (and ``.png``) into ``out_dir``
        (created if needed), atomically and byte-identically for the same numbers; returns
        the paths written."""
        from pathlib import Path

        from pkmcal.errors import PkmcalError
        from pkmcal.io.atomic import atomic_write_bytes, make_folder
        from pkmcal.report.figures import render

        out = Path(out_dir)
        if out.exists() and not out.is_dir():
            raise PkmcalError(f"figure folder '{out}' exists and is not a folder; choose another --figures path")
        make_folder(out, "--figures")
        written = []
        for spec in self.figures:
            fig = render(spec.build(), spec.name, spec.caption, png)
            for ext, data in (("svg", fig.svg), ("png", fig.png)):
                if data is not None:
                    path = out / f"{spec.name}.{ext}"
                    atomic_write_bytes(path, data)
                    written.append(path)
        return written


def _headline_json(headline: dict[str, float]) -> dict[str, float]:
    """The headline for JSON: every ``*_rad`` value (the paper's unit) followed by its
    ``*_deg`` twin, since pkmcal's JSON gives angles in degrees (docs/conventions.md)."""
    out: dict[str, float] = {}
    for k, v in headline.items():
        out[k] = v
        if k.endswith("_rad") and isinstance(v, (int, float)) and math.isfinite(v):
            out[k[:-4] + "_deg"] = math.degrees(v)
    return out


def mean_sd(values) -> tuple[float, str]:
    """(mean, "sd X, [min, max]") of a sequence of numbers, ignoring NaN."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), "no finite value"
    if v.size == 1:
        return float(v[0]), "1 run"
    return float(v.mean()), f"sd {_num(float(v.std(ddof=1)))}, range [{_num(float(v.min()))}, {_num(float(v.max()))}], n={v.size}"
