"""Paper 2 Table 6 and Fig. 6 reproductions, built on pkmcal.study: the published numbers
as printed in the paper, and the claims they are checked against (quick modes)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from pkmcal.reproduce import run_reproduction
from pkmcal.reproduce.paper2_study import PAPER_TABLE6

#: The paper's text: shared/ beside the repository (CI, /work/main) or beside its worktree folder.
PAPER = next((d / "shared" / "papers" / "stewart-calibration-digital-indicators.md"
              for d in Path(__file__).resolve().parents[2:5]
              if (d / "shared" / "papers" / "stewart-calibration-digital-indicators.md").exists()), Path("missing"))


@pytest.fixture(scope="module")
def table6():
    return run_reproduction("paper2-table6", seed=0, quick=True)


@pytest.fixture(scope="module")
def fig6():
    return run_reproduction("paper2-fig6", seed=0, quick=True)


def test_table6_numbers_are_the_papers():
    if not PAPER.exists():
        pytest.skip("paper text not available")
    text = PAPER.read_text(encoding="utf-8")
    for plan, label in (("random", "Random poses"), ("optimal", "Optimum poses")):
        m = re.search(label + r"\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)", text)
        assert m, label
        assert tuple(float(x) for x in m.groups()) == PAPER_TABLE6[plan]


def test_table6_rows(table6):
    for plan in ("random", "optimal"):
        g = f"{plan} poses (110), indicators sigma 0.01 mm"
        row = table6.row("D_E", g)
        assert row.paper == PAPER_TABLE6[plan][0]
        assert 90.0 < row.ours <= 100.0          # simulation: only Table 4's errors and the noise
        for col in ("P_Er_alpha", "P_Er_beta", "P_Er_z"):
            assert 50.0 < table6.row(col, g).ours <= 100.0
    # more noise, smaller reduction of the indicator error
    assert (table6.row("D_E", "random poses (110), indicators sigma 0.03 mm").ours
            < table6.row("D_E", "random poses (110), indicators sigma 0.01 mm").ours)


def test_fig6_claims(fig6):
    auto_small = fig6.row("mean |θ̂ − θ*| (truth in the fit's gauge), auto gauge", "14 random poses").ours
    auto_large = fig6.row("mean |θ̂ − θ*| (truth in the fit's gauge), auto gauge", "112 random poses").ours
    assert auto_large < 0.5 * auto_small                          # more poses, smaller error
    for gauge in ("auto gauge", "paper gauge"):
        small = fig6.row(f"mean |θ̂ − θ_real|, {gauge}", "14 random poses").ours
        large = fig6.row(f"mean |θ̂ − θ_real|, {gauge}", "112 random poses").ours
        assert large < small
    floor = fig6.row("rms residual of the noise-free fit, paper gauge (model floor)").ours
    assert floor > 1e-3                                            # the paper's gauge cannot represent Table 4
    assert np.isfinite([r.ours for r in fig6.rows]).all()
