"""``pkmcal reproduce --list`` names every table and figure of the three papers (issue 15):
each reproduced by registered reproductions, or an input, a method, or listed with the
reason it cannot be reproduced.

The papers' items are transcribed here (paper 1: Figs. 1-11, Table I; paper 2: Figs. 1-6,
Tables 1-7; paper 3: Figs. 1-8, Tables 1-2) and, when the papers' texts are at hand
(``../shared/papers``), checked against the captions found in them.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.reproduce import CATALOGUE, REPRODUCTIONS
from pkmcal.reproduce.catalogue import STATUSES

ITEMS = {
    1: [f"Fig. {k}" for k in range(1, 12)] + ["Table I"],
    2: [f"Fig. {k}" for k in range(1, 7)] + [f"Table {k}" for k in range(1, 8)],
    3: [f"Fig. {k}" for k in range(1, 9)] + ["Table 1", "Table 2"],
}
PAPER_FILES = {1: "hexapod-identification-ik-residual.md", 2: "stewart-calibration-digital-indicators.md",
               3: "redundant-pkm-projection-calibration.md"}


def test_every_table_and_figure_is_listed_once():
    for paper, items in ITEMS.items():
        listed = [it.item for it in CATALOGUE if it.paper == paper and not it.item.startswith("§")]
        assert sorted(listed) == sorted(items), paper


def test_statuses_and_reproductions_are_real():
    for it in CATALOGUE:
        assert it.status in STATUSES, it
        assert it.where.strip(), it
        for name in it.reproductions:
            assert name in REPRODUCTIONS, (it, name)
    covered = {n for it in CATALOGUE for n in it.reproductions}
    assert covered <= set(REPRODUCTIONS)
    # every reproduction covers some paper item, except the study beyond the papers
    assert set(REPRODUCTIONS) - covered == {"paper3-compliance"}


def test_list_prints_every_item_with_its_status():
    res = CliRunner().invoke(cli, ["reproduce", "--list"])
    assert res.exit_code == 0, res.output
    for name in REPRODUCTIONS:
        assert name in res.output
    for it in CATALOGUE:
        assert f"{it.item:<8} {it.what}" in res.output
        assert f"{it.status}: {it.where}" in res.output
    assert res.output.count("not reproducible:") == sum(it.status == "not reproducible" for it in CATALOGUE)


def _papers_dir() -> Path | None:
    for base in (Path(__file__).resolve().parents[2], *Path(__file__).resolve().parents):
        d = base / ".." / "shared" / "papers"
        if d.is_dir():
            return d
    return None


@pytest.mark.skipif(_papers_dir() is None, reason="the papers' texts are not at ../shared/papers")
def test_items_match_the_captions_in_the_papers():
    d = _papers_dir()
    for paper, fname in PAPER_FILES.items():
        text = (d / fname).read_text(encoding="utf-8")
        figs = {int(m) for m in re.findall(r"^\s*Fig\.\s*(\d+)[\s.]", text, flags=re.M)}
        assert figs == set(range(1, max(figs) + 1)), (paper, figs)
        assert [f"Fig. {k}" for k in sorted(figs)] == [i for i in ITEMS[paper] if i.startswith("Fig")], paper
        roman = {"I": "1"}                       # paper 1 prints "TABLE 1" and cites "Table I"
        tables = {roman.get(t.upper(), t) for t in re.findall(r"^\s*(?:\*\*)?\s*Table\s+(I|\d+)\b", text,
                                                               flags=re.M | re.I)}
        listed = {roman.get(i.split()[1], i.split()[1]) for i in ITEMS[paper] if i.startswith("Table")}
        assert tables == listed, (paper, tables)
