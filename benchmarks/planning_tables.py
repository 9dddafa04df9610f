"""Paper 2 Tables 1–2 with our numbers: observability indices of random and optimally
selected pose sets of 14, 28, …, 112 poses (paper 2's prototype, 3 dial indicators).

Two Jacobians per pose set:

* **ours** — the planning Jacobian (:mod:`pkmcal.planning.blocks`): fk-residual rows
  whitened by the setup's noise (indicators 0.01 mm, legs 0.005 mm), columns scaled to
  unit RMS norm per pose, restricted to the 39 identifiable parameters;
* **paper-like** — paper 2's convention as far as it is stated: the raw fk-residual
  Jacobian ∂(readings)/∂η in mm/mm, unweighted, unscaled, on the 30 parameters left after
  fixing b1, b2, a1, a2 (paper 2 §2.2).

"random" = mean over 10 random sets from 2,000 checked candidates; "optimal" = our default
algorithm maximising O4 (D-optimal exchange polished on O4), on the same candidates.
Last line: one JSON object.

    python benchmarks/planning_tables.py [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from pkmcal.identification.residuals import Model, make_method
from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.planning.blocks import planning_model
from pkmcal.planning.candidates import generate_candidates
from pkmcal.planning.indices import indices_from_singular_values, observability_indices
from pkmcal.planning.selection import select_default, select_random

SIZES = (14, 28, 42, 56, 70, 84, 98, 112)
#: Paper 2 Table 1 (random) and Table 2 (optimal): O1..O4 in the units of the table heads.
PAPER_T1 = {14: (1.3406e-3, 9.4700e-11, 9.6938e-10, 9.1800e-20), 28: (2.5333e-3, 2.9976e-9, 4.3717e-8, 1.3105e-16),
            42: (2.8748e-3, 3.2963e-9, 5.8492e-8, 1.9281e-16), 56: (3.0601e-3, 4.1138e-9, 8.4191e-8, 3.4635e-16),
            70: (3.0448e-3, 4.2465e-9, 9.7290e-8, 4.1314e-16), 84: (3.1455e-3, 3.9187e-9, 9.8669e-8, 3.8666e-16),
            98: (3.3224e-3, 4.6919e-9, 1.2734e-7, 5.9744e-16), 112: (3.1732e-3, 4.1835e-9, 1.2146e-7, 5.0813e-16)}
PAPER_T2 = {14: (4.0339e-3, 4.0330e-9, 4.7545e-8, 1.9175e-16), 28: (1.1640e-2, 2.6540e-8, 4.5375e-7, 1.2042e-14),
            42: (1.2875e-2, 3.0920e-8, 6.7746e-7, 2.0947e-14), 56: (1.2592e-2, 2.9189e-8, 7.0810e-7, 2.0668e-14),
            70: (1.3544e-2, 3.0325e-8, 8.5110e-7, 2.5810e-14), 84: (1.3087e-2, 2.9874e-8, 9.1111e-7, 2.7219e-14),
            98: (1.3730e-2, 3.2634e-8, 1.0731e-6, 3.5018e-14), 112: (1.2899e-2, 3.0770e-8, 1.0641e-6, 3.2741e-14)}


def paper_like_indices(machine, setup, poses) -> dict[str, float]:
    """O1..O4 of the raw (unweighted, unscaled) fk-residual Jacobian on paper 2's 30 parameters."""
    model = Model(machine, setup.sensor, setup.noise, machine.ik(poses), setup.sensor.predict(poses), commanded=poses)
    J = make_method("fk-residual", model, weighted=False).evaluate(model.theta0, jac=True, cov=False).J
    fixed = {f"{j}{i}.{c}" for j in "ba" for i in (1, 2) for c in "xyz"}
    cols = [k for k, nm in enumerate(machine.param_names) if nm not in fixed]
    rows = J[:, :, cols].reshape(-1, len(cols))
    return indices_from_singular_values(np.linalg.svd(rows, compute_uv=False), rows.shape[0])


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--random-sets", type=int, default=10)
    args = ap.parse_args(argv)
    machine = stewart_prototype()
    setup = load_setup("indicators-prototype")
    model = planning_model(machine, setup)
    rng = np.random.default_rng(args.seed)
    cand = generate_candidates(machine, setup, n=2000, rng=rng)
    G, _ = model.blocks(cand.poses)
    out = {}
    for n in SIZES:
        rsets = [select_random(len(G), n, rng) for _ in range(args.random_sets)]
        ours_r = {k: float(np.mean([observability_indices(G, s)[k] for s in rsets])) for k in ("O1", "O2", "O3", "O4", "O5")}
        like_r = {k: float(np.mean([paper_like_indices(machine, setup, cand.poses[s])[k] for s in rsets]))
                  for k in ("O1", "O2", "O3", "O4")}
        opt = select_default(G, n, index="O4")
        like_o = paper_like_indices(machine, setup, cand.poses[opt.chosen])
        out[n] = {"ours_random": ours_r, "ours_optimal": opt.indices, "paper_like_random": like_r,
                  "paper_like_optimal": like_o, "paper_random": PAPER_T1[n], "paper_optimal": PAPER_T2[n]}
        print(f"n = {n:3d}  O4 ours random {ours_r['O4']:.3e} optimal {opt.indices['O4']:.3e} | "
              f"paper-like random {like_r['O4']:.3e} optimal {like_o['O4']:.3e} | "
              f"paper random {PAPER_T1[n][3]:.3e} optimal {PAPER_T2[n][3]:.3e}", flush=True)
    print("\n| n | index | paper random | paper optimal | paper-like random | paper-like optimal | ours random | ours optimal |")
    print("|---|---|---|---|---|---|---|---|")
    for n in SIZES:
        r = out[n]
        for i, k in enumerate(("O1", "O2", "O3", "O4")):
            print(f"| {n} | {k} | {r['paper_random'][i]:.3e} | {r['paper_optimal'][i]:.3e} | "
                  f"{r['paper_like_random'][k]:.3e} | {r['paper_like_optimal'][k]:.3e} | "
                  f"{r['ours_random'][k]:.3e} | {r['ours_optimal'][k]:.3e} |")
    print(json.dumps({str(n): v for n, v in out.items()}))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
