"""Paper 2 (Saputra, Ong & Nee 2014) §5: Table 6 (random against optimally selected poses)
and Fig. 6 (parameter error against the number of poses), as studies (:mod:`pkmcal.study`).

Both run on the Table 5 simulation set-up (:mod:`.paper2`): nominal ``stewart-prototype``
(Table 3), real ``stewart-prototype-real`` (Table 3 + Table 4) in every trial, three dial
indicators (``indicators-prototype``), ``fk-residual`` (§3 eq. 3), unweighted as in the
paper, the real prototype's leg-collision check off. Each trial draws new poses (random
plans) and new noise.

**Table 6** (D_E and P_Er α, β, z; definitions of :mod:`.paper2`, computed by its
``_metrics`` on the study's held-out poses): 110 poses (Table 7's count) chosen at random
from a pool of checked candidates, against 110 chosen by cuckoo search on O4 (the paper's
CS, ``algorithm: cuckoo``; DETMAX on O4 in quick mode, for time), one selection for all
trials. Two indicator noise levels: σ = 0.01 mm (the gauges' resolution; legs 0.005 mm)
and σ = 0.03 mm (the 10–50 µm repeatability the paper observed on its prototype, averaged
over its two readings per pose).

**Fig. 6** (text: "a larger number of poses will lead to better calibration results ...
there is a limit where the errors cannot be reduced further"): random poses, n = 14 … 112
(Tables 1–2's sizes), σ = 0.01 mm, with our automatic gauge and with the paper's (b1, b2,
a1, a2 fixed, §2.2). "Error in the kinematic parameters" is read as the mean |θ̂ − θ_real|
over the free parameters (``param_error_vs_real_mean_abs_mm``, paper 1's Table I measure);
the same against the truth in the fit's gauge θ* (``param_error_mean_abs_mm``) separates
noise from model error.
"""

from __future__ import annotations

import tempfile
import time

import numpy as np

from pkmcal.io.setup_file import builtin_setup
from pkmcal.mechanisms import builtin_machine
from pkmcal.progress import Progress
from pkmcal.reproduce.paper2 import IGNORE, PAPER_GAUGE, _metrics
from pkmcal.reproduce.table import Reproduction, Row, mean_sd
from pkmcal.study import MachineSpec, MethodSpec, PlanSpec, SetupSpec, Study, run_study
from pkmcal.study.schema import scaled_noise

#: Paper 2 Table 6: D_E %, P_Er α, β, z % (random poses, optimum poses), as printed.
PAPER_TABLE6 = {"random": (81.96, 90.38, 21.48, 83.96), "optimal": (83.05, 87.23, 53.18, 87.06)}
TABLE6_COLUMNS = ("D_E", "P_Er_alpha", "P_Er_beta", "P_Er_z")
EXTRA_COLUMNS = ("E_E", "D_E", "P_Eb_alpha", "P_Eb_beta", "P_Eb_z", "P_Ea_alpha", "P_Ea_beta", "P_Ea_z",
                 "P_Er_alpha", "P_Er_beta", "P_Er_z")
FIG6_SIZES = (14, 28, 42, 56, 70, 84, 98, 112)
N_TABLE6 = 110


#: The paper's held-out errors are the platform's as commanded (the tilt and height its
#: indicators see, Table 5): the studies compare poses as commanded, whatever the gauge
#: (the notes say what the gauge does to them).
PAPER_COMPARE = "commanded"


def table5_metrics(nominal, real, setup, sim, fit, heldout) -> dict:
    """Paper 2's Table 5/6 columns of one fit (``reproduce.paper2._metrics``) as study columns."""
    return _metrics(nominal, real, setup.sensor, sim, fit.mechanism, heldout)


def _machine() -> MachineSpec:
    return MachineSpec("prototype", builtin_machine("stewart-prototype"), real=builtin_machine("stewart-prototype-real"),
                       ignore_limits=IGNORE)


def _run(study: Study, quick: bool, progress: Progress | None = None):
    with tempfile.TemporaryDirectory(prefix="pkmcal-paper2-study-") as tmp:
        return run_study(study, f"{tmp}/r", workers=1 if quick else None, figures=False,
                         progress=progress or False)


def _column(cols: dict, config: int, name: str) -> np.ndarray:
    return cols[name][cols["config"].astype(int) == config]


def paper2_table6(seed: int = 0, quick: bool = False, trials: int | None = None,
                  progress: Progress | None = None) -> Reproduction:
    """Paper 2 Table 6 (module docstring); ``progress(done, total)`` over the study's trials."""
    t0 = time.perf_counter()
    n_tr = trials if trials is not None else (2 if quick else 40)
    base = builtin_setup("indicators-prototype")
    optimal = "detmax" if quick else "cuckoo"
    n_cand = 400 if quick else 2000
    study = Study(
        name="paper2-table6", trials=n_tr, seed=seed, machines=(_machine(),),
        setups=(SetupSpec("sigma 0.01 mm", base), SetupSpec("sigma 0.03 mm", scaled_noise(base, 3.0, 1.0))),
        plans=(PlanSpec("random", "random", (N_TABLE6,), candidates=n_cand, resample="trial"),
               PlanSpec("optimal", optimal, (N_TABLE6,), candidates=n_cand, resample="once", index="O4")),
        methods=(MethodSpec("fk-residual, unweighted", "fk-residual", weighted=False),),
        heldout_poses=50, heldout_compare=PAPER_COMPARE, extra_metrics=table5_metrics, extra_columns=EXTRA_COLUMNS)
    res = _run(study, quick, progress)
    cols = res.columns
    rows: list[Row] = []
    headline: dict[str, float] = {}
    for c, setup in enumerate(("sigma 0.01 mm", "sigma 0.03 mm")):
        for p, plan in enumerate(("random", "optimal")):
            cfg = (c * 2 + p)
            g = f"{plan} poses ({N_TABLE6}), indicators {setup}"
            for k, col in enumerate(TABLE6_COLUMNS):
                m, s = mean_sd(_column(cols, cfg, col))
                rows.append(Row(col, PAPER_TABLE6[plan][k], m, "%", s, g))
                if c == 0:
                    headline[f"paper2_table6_{plan}_{col}"] = m
            for col in ("P_Ea_alpha", "P_Ea_beta", "P_Ea_z", "P_Eb_alpha", "P_Eb_beta", "P_Eb_z"):
                m, s = mean_sd(_column(cols, cfg, col))
                rows.append(Row(col, None, m, "mm" if col.endswith("_z") else "deg", s, g))
            m, s = mean_sd(_column(cols, cfg, "param_error_mean_abs_mm"))
            rows.append(Row("parameter error mean |θ̂ − θ*| (truth in the fit's gauge)", None, m, "mm", s, g))
    setup_d = {
        "machine": "nominal stewart-prototype (Table 3); real stewart-prototype-real (Table 3 + Table 4), every trial",
        "sensor": "indicators-prototype (3 indicators at radius 40 mm, 0/120/240°, plane offset 10 mm); indicator "
                  "noise sigma 0.01 mm and 0.03 mm (legs 0.005 mm), Gaussian",
        "poses": f"{N_TABLE6} per campaign from {n_cand} checked random candidates of the workspace box (drawn once "
                 f"per setup): 'random' = a new random choice per trial; 'optimal' = {optimal} on O4 "
                 "(the paper's cuckoo search; DETMAX in quick mode), one selection for all trials; 50 random "
                 "held-out poses of the workspace box",
        "method": "fk-residual, unweighted (paper 2 eq. 3), automatic gauge; columns D_E, P_Er as in paper2-table5",
        "seeds": f"study seed {seed}: numpy SeedSequence keys per trial (pkmcal.study.trial)",
        "Monte Carlo": f"{n_tr} trial(s) per configuration (fresh poses for 'random', fresh noise for both)",
    }
    notes = (
        "Table 6 was measured on the physical prototype (§5: 'the calibration process has been performed ... "
        "measurement errors due to instability ... 10-50 µm'); ours is a simulation whose only errors are the 42 "
        "parameters of Table 4 and the gauge noise. The real machine's unmodelled errors (backlash in the passive "
        "joints, which the paper names, thermal and load effects, joint errors outside the 42-parameter model) "
        "stay after any calibration, so the paper's reductions (82-83 % D_E) are far below our simulated ones; "
        "raising the noise to the observed 30 µm changes ours little, so noise alone does not explain the gap.",
        "The paper's claim that optimal poses help the orientation (P_Er β 21.48 % → 53.18 %) is about the "
        "prototype; in simulation both plans already remove most of the β error, and the optimal plan's "
        "advantage shows in the smaller spread and the parameter error rather than in the mean reductions.",
        "The paper gives neither the number of poses behind Table 6 nor the candidate set, the held-out poses or "
        "the indicator positions; we use Table 7's 110 poses and the set-up of paper2-table5. The before-errors "
        "P_Eb differ from the paper's for the reasons given there.",
        "D_E and P_Er are ratios of means over held-out poses; the mean over trials and its sd are shown.",
    )
    return Reproduction(name="paper2-table6", title="Saputra, Ong & Nee, Table 6 (random vs optimal poses), as a study",
                        rows=tuple(rows), setup=setup_d, notes=notes, headline=headline,
                        seconds=time.perf_counter() - t0)


def paper2_fig6(seed: int = 0, quick: bool = False, trials: int | None = None,
                progress: Progress | None = None) -> Reproduction:
    """Paper 2 Fig. 6 (module docstring); ``progress(done, total)`` over the study's trials."""
    t0 = time.perf_counter()
    n_tr = trials if trials is not None else (2 if quick else 20)
    sizes = (14, 56, 112) if quick else FIG6_SIZES
    paper_fix = tuple(PAPER_GAUGE)
    study = Study(
        name="paper2-fig6", trials=n_tr, seed=seed, machines=(_machine(),),
        setups=(SetupSpec("indicators", builtin_setup("indicators-prototype")),),
        plans=(PlanSpec("random", "random", sizes, candidates=400 if quick else 2000, resample="trial"),),
        methods=(MethodSpec("auto gauge", "fk-residual", weighted=False),
                 MethodSpec("paper gauge", "fk-residual", weighted=False, fix=paper_fix)),
        heldout_poses=30, heldout_compare=PAPER_COMPARE)
    res = _run(study, quick, progress)
    cols = res.columns
    rows: list[Row] = []
    headline: dict[str, float] = {}
    claim = "falls with n, then levels off"
    for k, n in enumerate(sizes):
        g = f"{n} random poses"
        for j, gauge in enumerate(("auto gauge", "paper gauge")):
            cfg = k * 2 + j
            m, s = mean_sd(_column(cols, cfg, "param_error_vs_real_mean_abs_mm"))
            rows.append(Row(f"mean |θ̂ − θ_real|, {gauge}", claim, m, "mm", s, g))
            m2, s2 = mean_sd(_column(cols, cfg, "param_error_mean_abs_mm"))
            rows.append(Row(f"mean |θ̂ − θ*| (truth in the fit's gauge), {gauge}", None, m2, "mm", s2, g))
            m3, s3 = mean_sd(_column(cols, cfg, "heldout_tilt_rms_deg"))
            rows.append(Row(f"held-out tilt error rms after, {gauge}", None, m3, "deg", s3, g))
            if n in (sizes[0], sizes[-1]):
                headline[f"paper2_fig6_{gauge.split()[0]}_{n}_vs_real_mm"] = m
                headline[f"paper2_fig6_{gauge.split()[0]}_{n}_vs_truth_mm"] = m2
    floor = float(np.nanmean(cols["truth_refit_rms"][cols["method"] == "paper gauge"]))
    rows.append(Row("rms residual of the noise-free fit, paper gauge (model floor)", None, floor, "mm", "",
                    "model error of the paper's gauge"))
    setup_d = {
        "machine": "nominal stewart-prototype; real stewart-prototype-real (Table 4), every trial",
        "sensor": "indicators-prototype, indicator noise sigma 0.01 mm, legs 0.005 mm",
        "poses": f"random, n = {', '.join(map(str, sizes))}, a new draw per trial from a pool of checked candidates; "
                 "30 random held-out poses",
        "method": "fk-residual, unweighted; auto gauge (a1.x, a1.y, a2.x fixed) and the paper's (b1, b2, a1, a2 "
                  "fixed, 12 parameters)",
        "error measure": "mean |θ̂ − θ_real| over the free parameters (the figure's 'error in the kinematic "
                         "parameters'); also against θ*, the noise-free fit of the same poses",
        "seeds": f"study seed {seed}: numpy SeedSequence keys per trial (pkmcal.study.trial)",
        "Monte Carlo": f"{n_tr} trial(s) per size (mean, sd, range)",
    }
    notes = (
        "Fig. 6 is a plot without numbers; the 'paper' column states its claim. Ours falls with n in both gauges, "
        "as the paper says.",
        "Where it levels off depends on the gauge. With our automatic gauge the error against θ* (noise "
        "only) keeps falling with n, and so does the held-out tilt error; against θ_real it stays above it by "
        "the gauge offset: Table 4 moves a2.x, which that gauge holds at nominal, so θ̂ converges to the real "
        "machine in another gauge (same readings, other parameters). With the paper's gauge, which fixes b2 and "
        "a2 that Table 4 perturbs, the model cannot represent the real machine (the noise-free fit keeps the "
        "residual of the last row): the error against θ_real and the held-out tilt error stop falling after a "
        "few dozen poses, while the error against θ* still falls. That floor is the paper's 'limit where the "
        "errors cannot be reduced further': a property of the model (its gauge), not of the number of poses.",
        "The paper gives neither its error measure, its noise level, nor its pose counts for Fig. 6; ours are "
        "stated in the setup.",
    )
    return Reproduction(name="paper2-fig6", title="Saputra, Ong & Nee, Fig. 6 (parameter error vs number of poses), "
                        "as a study", rows=tuple(rows), setup=setup_d, notes=notes, headline=headline,
                        seconds=time.perf_counter() - t0)


__all__ = ["PAPER_TABLE6", "paper2_fig6", "paper2_table6", "table5_metrics"]
