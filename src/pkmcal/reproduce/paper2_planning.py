"""Paper 2 (Saputra, Ong & Nee 2014) §4, Tables 1–2: observability indices of random and
optimally selected pose sets of 14, 28, …, 112 poses (prototype, 3 dial indicators).

With σ_1 ≥ … ≥ σ_n the singular values of the stacked identification Jacobian J (m rows)
of a pose set, the indices are (:mod:`pkmcal.planning.indices`, paper 2 §4)

    O1 = (σ_1 ⋯ σ_n)^(1/n) / √m,   O2 = σ_n / σ_1,   O3 = σ_n,   O4 = σ_n² / σ_1.

Two Jacobians per pose set:

* **paper-like** (the rows beside the paper's numbers) — paper 2's convention as far as it is stated: the raw
  fk-residual Jacobian J_P = ∂(readings)/∂η (eq. 7) in mm/mm, unweighted and unscaled, on the
  30 parameters left after fixing b1, b2, a1, a2 (§2.2);
* **planning** (the rows "…, planning J", O1..O5) — :mod:`pkmcal.planning.blocks`: rows whitened by the setup's
  noise (indicators 0.01 mm, legs 0.005 mm), columns scaled to unit RMS norm per pose, on the
  39 identifiable parameters.

"random" = mean over ``random_sets`` random sets drawn from the checked candidates (the paper
shows one set); "optimal" = :func:`~pkmcal.planning.selection.select_default` with
``index="O4"`` on the planning Jacobian (D-optimal exchange polished on O4; the paper used
cuckoo search on O4), on the same candidates. ``benchmarks/planning_tables.py`` prints this
reproduction; docs/planning.md discusses the differences.
"""

from __future__ import annotations

import time

import numpy as np

from pkmcal.io.lookup import load_setup
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.planning.blocks import planning_model, raw_blocks
from pkmcal.planning.candidates import generate_candidates
from pkmcal.planning.indices import INDEX_NAMES, observability_indices
from pkmcal.planning.selection import select_default, select_random
from pkmcal.reproduce.paper2 import PAPER_GAUGE
from pkmcal.progress import Progress
from pkmcal.reproduce.table import Reproduction, Row, mean_sd

SIZES = (14, 28, 42, 56, 70, 84, 98, 112)
PAPER_INDICES = ("O1", "O2", "O3", "O4")
#: Paper 2 Table 1 (random poses): n → (O1, O2, O3, O4), the printed mantissas times the
#: column heads' powers (10⁻³, 10⁻⁹, 10⁻⁷, 10⁻¹⁶), digits as printed.
PAPER_TABLE1 = {
    14: (1.3406e-3, 9.4700e-11, 9.6938e-10, 9.1800e-20),
    28: (2.5333e-3, 2.9976e-9, 4.3717e-8, 1.3105e-16),
    42: (2.8748e-3, 3.2963e-9, 5.8492e-8, 1.9281e-16),
    56: (3.0601e-3, 4.1138e-9, 8.4191e-8, 3.4635e-16),
    70: (3.0448e-3, 4.2465e-9, 9.7290e-8, 4.1314e-16),
    84: (3.1455e-3, 3.9187e-9, 9.8669e-8, 3.8666e-16),
    98: (3.3224e-3, 4.6919e-9, 1.2734e-7, 5.9744e-16),
    112: (3.1732e-3, 4.1835e-9, 1.2146e-7, 5.0813e-16),
}
#: Paper 2 Table 2 (optimally selected poses), column heads 10⁻², 10⁻⁸, 10⁻⁶, 10⁻¹⁴.
PAPER_TABLE2 = {
    14: (4.0339e-3, 4.0330e-9, 4.7545e-8, 1.9175e-16),
    28: (1.1640e-2, 2.6540e-8, 4.5375e-7, 1.2042e-14),
    42: (1.2875e-2, 3.0920e-8, 6.7746e-7, 2.0947e-14),
    56: (1.2592e-2, 2.9189e-8, 7.0810e-7, 2.0668e-14),
    70: (1.3544e-2, 3.0325e-8, 8.5110e-7, 2.5810e-14),
    84: (1.3087e-2, 2.9874e-8, 9.1111e-7, 2.7219e-14),
    98: (1.3730e-2, 3.2634e-8, 1.0731e-6, 3.5018e-14),
    112: (1.2899e-2, 3.0770e-8, 1.0641e-6, 3.2741e-14),
}


def paper_like_blocks(machine, setup, poses: np.ndarray) -> np.ndarray:
    """Per-pose blocks (N, 3, 30) of the raw fk-residual Jacobian ∂Y/∂η (paper 2 eq. 7):
    unweighted, unscaled, columns = the parameters left after fixing b1, b2, a1, a2 (§2.2).
    Each pose's rows depend on that pose only, so a set's J is a stack of these blocks."""
    J, _, _ = raw_blocks(machine, setup, poses, "fk-residual", weighted=False)
    cols = [k for k, nm in enumerate(machine.param_names) if nm not in PAPER_GAUGE]
    return J[:, :, cols]


def paper2_tables1_2(seed: int = 0, quick: bool = False, random_sets: int | None = None,
                     n_candidates: int | None = None, progress: Progress | None = None) -> Reproduction:
    """Paper 2 Tables 1–2 (module docstring): ``random_sets`` random sets per size (10; 3
    quick) from ``n_candidates`` checked random candidates (2,000; 400 quick);
    ``progress(done, total)`` after each set size."""
    t0 = time.perf_counter()
    n_sets = random_sets if random_sets is not None else (3 if quick else 10)
    n_cand = n_candidates if n_candidates is not None else (400 if quick else 2000)
    machine = stewart_prototype()
    setup = load_setup("indicators-prototype")
    model = planning_model(machine, setup)
    rng = np.random.default_rng(seed)
    cand = generate_candidates(machine, setup, n=n_cand, rng=rng)
    G, _ = model.blocks(cand.poses)
    P = paper_like_blocks(machine, setup, cand.poses)
    rows: list[Row] = []
    headline: dict[str, float] = {}
    for si, n in enumerate(SIZES):
        rsets = [select_random(len(G), n, rng) for _ in range(n_sets)]
        opt = select_default(G, n, index="O4").chosen
        like_r = [observability_indices(P, s) for s in rsets]
        like_o = observability_indices(P, opt)
        ours_r = [observability_indices(G, s) for s in rsets]
        ours_o = observability_indices(G, opt)
        g = f"{n} poses"
        for i, k in enumerate(PAPER_INDICES):
            m, s = mean_sd([v[k] for v in like_r])
            rows.append(Row(f"{k} random", PAPER_TABLE1[n][i], m, "", s, g))
            rows.append(Row(f"{k} optimal", PAPER_TABLE2[n][i], like_o[k], "", "", g))
        for k in INDEX_NAMES:
            m, s = mean_sd([v[k] for v in ours_r])
            rows.append(Row(f"{k} random, planning J", None, m, "", s, g))
            rows.append(Row(f"{k} optimal, planning J", None, ours_o[k], "", "", g))
        if n in (SIZES[0], SIZES[-1]):
            headline[f"paper2_tables12_paper_like_O4_random_{n}"] = float(np.mean([v["O4"] for v in like_r]))
            headline[f"paper2_tables12_paper_like_O4_optimal_{n}"] = like_o["O4"]
            headline[f"paper2_tables12_planning_O4_random_{n}"] = float(np.mean([v["O4"] for v in ours_r]))
            headline[f"paper2_tables12_planning_O4_optimal_{n}"] = ours_o["O4"]
        if progress is not None:
            progress(si + 1, len(SIZES))
    setup_d = {
        "machine": "stewart-prototype (paper 2 Table 3)",
        "sensor": "indicators-prototype: 3 indicators at radius 40 mm, 0/120/240° (paper 2 gives no positions)",
        "candidates": f"{len(cand.poses)} checked random poses of the workspace box ({cand.describe()})",
        "Jacobian": "rows 'O_k random/optimal' (beside the paper's): paper-like, the raw fk-residual dY/d(eta), "
                    f"mm/mm, unweighted, unscaled, {P.shape[2]} parameters (b1, b2, a1, a2 fixed); rows '..., "
                    f"planning J': whitened, column-scaled, {model.n_params} identifiable parameters",
        "random": f"mean over {n_sets} random sets per size (mean, sd, range)",
        "optimal": "select_default(index='O4') on the planning Jacobian (paper 2: cuckoo search on O4)",
        "seeds": f"numpy default_rng({seed}): candidates, then the random sets size by size",
        "Monte Carlo": f"{n_sets} random set(s) per size; the optimal set is deterministic",
    }
    notes = (
        "The magnitudes differ by many orders (paper O4 ~1e-16, ours ~1e-6): the paper's O2 = "
        "sigma_min/sigma_max ~1e-10..1e-8 is scale-free, while our analytic paper-like Jacobian on the "
        "same 30 parameters has O2 ~1e-4..1e-3. A ratio near 1e-9 is what a rank-deficient Jacobian "
        "computed by finite differences through an iterative FK shows; the paper's J_P is numerical (§4), "
        "its FD step, FK tolerance and indicator positions are not given (docs/planning.md).",
        "What is reproduced are the trends: O2, O3 and O4 grow with the number of poses, O1 (normalised "
        "by sqrt(m)) grows then levels off, and the optimal sets beat random sets of the same size on "
        "every index, most for small sets.",
        "The paper shows one random set per size (its Table 1 is not monotone in n); we average several.",
    )
    return Reproduction(name="paper2-tables1-2",
                        title="Saputra, Ong & Nee, Tables 1-2 (observability indices, random vs optimal poses)",
                        rows=tuple(rows), setup=setup_d, notes=notes, headline=headline,
                        seconds=time.perf_counter() - t0)
