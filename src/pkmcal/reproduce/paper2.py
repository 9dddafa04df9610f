"""Paper 2 (Saputra, Ong & Nee 2014) §5, Table 5 (and the Table 7 evidence), in simulation.

Table 5: nominal machine = ``stewart-prototype`` (Table 3), real machine =
``stewart-prototype-real`` (nominal + Table 4), three dial indicators, identification by
the forward-kinematics residual (§3 eq. 3; our ``fk-residual``), Gaussian noise of four
levels N_L ("variance") on the measurements. Columns, as defined in the note under the
table and as we compute them:

    E_E  = 100 (1 − SS_after / SS_before),  SS = Σ_j ‖Y_j − F_j(Q_j, η)‖²  on the
           calibration poses (η nominal before, identified after; "sum of squares of F_i")
    D_E  = 100 (1 − mean|h(x_r,after) − h(x_c)| / mean|h(x_r,before) − h(x_c)|)  on held-out
           poses: the indicators' "real" reading h(x_r) against the "nominal" one h(x_c),
           x_r = FK(IK(x_c, η_model), η_real), noise-free
    P_Eb, P_Ea = mean |α_r − α_c|, |β_r − β_c| (deg) and |z error| (mm, height of the
           platform plane above the commanded centre, :mod:`pkmcal.identification.verification`)
           on the held-out poses, before (nominal model) and after (identified model)
    P_Er = 100 (1 − P_Ea / P_Eb)

Ambiguities (stated in the notes): "variance" (σ = √N_L) vs standard deviation (σ = N_L),
so both are run; noise on the indicator readings only (legs exact); number and kind of
poses not given (we use random poses); the indicator positions and d_off are not given
(we use ``indicators-prototype``). Gauge: the paper fixes b1, b2, a1, a2 (12 parameters,
§2.2), which is over-constrained when Table 4 perturbs b2 and a2; our engine fixes the
3-parameter gauge it finds (a1.x, a1.y, a2.x). Both are run.
"""

from __future__ import annotations

import time

import numpy as np

from pkmcal.identification.engine import identify
from pkmcal.identification.residuals import default_estimated_index
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.identification.verification import pose_errors
from pkmcal.io.setup_file import builtin_setup
from pkmcal.mechanisms import builtin_machine
from pkmcal.mechanisms.library import (
    PROTOTYPE_BASE,
    PROTOTYPE_PLATFORM,
    TABLE4_DELTA_BASE,
    TABLE4_DELTA_OFFSET,
    TABLE4_DELTA_PLATFORM,
)
from pkmcal.progress import Progress
from pkmcal.reproduce.table import Reproduction, Row, mean_sd
from pkmcal.sensors.base import MeasurementSetup, NoiseModel

NOISE_LEVELS = (0.0001, 0.001, 0.01, 0.1)
#: Paper 2 Table 5: N_L → (E_E %, D_E %, P_Eb (α°, β°, z mm), P_Ea, P_Er %).
PAPER_TABLE5 = {
    0.0001: (99.99, 99.81, (0.12, 3.11, 1.27), (0.0006, 0.001, 0.002), (99.41, 99.97, 99.85)),
    0.001: (99.95, 99.57, (0.12, 2.99, 1.26), (0.002, 0.004, 0.003), (98.28, 99.87, 99.79)),
    0.01: (99.48, 97.78, (0.12, 2.78, 1.24), (0.01, 0.006, 0.023), (90.90, 99.78, 98.13)),
    0.1: (93.80, 94.61, (0.12, 3.24, 1.23), (0.014, 0.05, 0.04), (88.15, 98.59, 96.60)),
}
#: Paper 2 Table 7 ("kinematic parameters after calibration", 110 optimal poses), as printed:
#: δL0_i, b_i (x, y, z), a_i (x, y, z).
PAPER_TABLE7_OFFSET = (1.0, 2.0, 3.0, 1.0, 2.0, 3.0)
PAPER_TABLE7_BASE = ((-152.5, 0.0, 0.0), (-129.069, 76.25, 0.3), (76.15, 130.269, 0.7),
                     (131.9689, -74.45, 0.7), (76.15, 133.869, 0.7), (-0.1, 154.3, 0.7))
PAPER_TABLE7_PLATFORM = ((-60.622, 35.0, 0.0), (-0.9, 0.67, 0.53), (3.0, -72.0, 0.7),
                         (73.0, -2.0, 0.7), (63.22, 33.0, 0.7), (-32.0, 58.622, 0.7))
PAPER_GAUGE = tuple(f"{j}{i}.{c}" for j in "ba" for i in (1, 2) for c in "xyz")
BOX_HALF = np.array([20.0, 20.0, 10.0, *np.deg2rad([8.0, 8.0, 8.0])])
IGNORE = ("leg_collision",)
COLS = ("E_E", "D_E", "P_Eb_alpha", "P_Eb_beta", "P_Eb_z", "P_Ea_alpha", "P_Ea_beta", "P_Ea_z",
        "P_Er_alpha", "P_Er_beta", "P_Er_z")


def _paper_row(level: float) -> dict[str, float]:
    e, d, b, a, r = PAPER_TABLE5[level]
    return dict(zip(COLS, (e, d, *b, *a, *r)))


def table7_evidence(tol: float = 0.0015) -> tuple[tuple[str, ...], ...]:
    """Rows (parameter, Table 7, nominal + Table 4, difference, verdict) comparing paper 2's
    "identified" Table 7 with nominal (Table 3) + the simulated real deviations (Table 4)."""
    rows = []
    for i in range(6):
        rows.append((f"dL0_{i + 1}", PAPER_TABLE7_OFFSET[i], TABLE4_DELTA_OFFSET[i]))
        for j, kind, nom, dlt, t7 in (("b", "base", PROTOTYPE_BASE, TABLE4_DELTA_BASE, PAPER_TABLE7_BASE),
                                      ("a", "platform", PROTOTYPE_PLATFORM, TABLE4_DELTA_PLATFORM, PAPER_TABLE7_PLATFORM)):
            for c, ax in enumerate("xyz"):
                rows.append((f"{j}{i + 1}.{ax}", t7[i][c], nom[i, c] + dlt[i, c], dlt[i, c]))
    out = []
    for r in rows:
        name, t7, expect = r[0], r[1], r[2]
        diff = t7 - expect
        if abs(diff) <= tol:
            verdict = "= nominal + Table 4"
        elif len(r) == 4 and abs(t7 - r[3]) <= tol:
            verdict = "= Table 4 deviation alone (nominal missing)"
        elif abs(t7 + expect) <= tol:
            verdict = "= nominal + Table 4 with the sign flipped"
        elif len(r) == 4 and abs(t7 - (expect - 2 * r[3])) <= tol:
            verdict = "= nominal − Table 4 deviation (deviation sign flipped)"
        else:
            verdict = "differs"
        out.append((name, f"{t7:g}", f"{expect:.4f}", f"{diff:+.4f}", verdict))
    return tuple(out)


def _fk_readings(machine, sensor, q, cmd):
    fk = machine.fk(q, guess=cmd)
    return sensor.predict(machine.frame(fk.poses)), fk.converged


def _metrics(nominal, real, sensor, sim, fitted, verify_poses) -> dict[str, float]:
    q, y, cmd = sim.actuator_readings, sim.sensor_readings, sim.commanded[sim.kept]
    y0, ok0 = _fk_readings(nominal, sensor, q, cmd)
    y1, ok1 = _fk_readings(fitted, sensor, q, cmd)
    ok = ok0 & ok1
    ss0, ss1 = np.sum((y[ok] - y0[ok]) ** 2), np.sum((y[ok] - y1[ok]) ** 2)
    pb, pa = pose_errors(nominal, real, verify_poses, IGNORE), pose_errors(fitted, real, verify_poses, IGNORE)
    m = pb.valid & pa.valid
    hc = sensor.predict(real.frame(verify_poses[m]))
    db = np.mean(np.abs(sensor.predict(real.frame(pb.reached[m])) - hc))
    da = np.mean(np.abs(sensor.predict(real.frame(pa.reached[m])) - hc))
    out = {"E_E": 100 * (1 - ss1 / ss0), "D_E": 100 * (1 - da / db)}
    for tag, pe in (("b", pb), ("a", pa)):
        d = np.abs(pe.reached[m] - verify_poses[m])
        out[f"P_E{tag}_alpha"] = float(np.rad2deg(np.mean(d[:, 3])))
        out[f"P_E{tag}_beta"] = float(np.rad2deg(np.mean(d[:, 4])))
        out[f"P_E{tag}_z"] = float(np.mean(np.abs(pe.height[m])))
    for k in ("alpha", "beta", "z"):
        out[f"P_Er_{k}"] = 100 * (1 - out[f"P_Ea_{k}"] / out[f"P_Eb_{k}"])
    return out


def _campaign(nominal, real, setup, n_poses, n_verify, rng):
    cmd = nominal.home_pose + rng.uniform(-1.0, 1.0, (2 * n_poses, 6)) * BOX_HALF
    sim = simulate_campaign(nominal, real, setup, cmd, rng, ignore_limits=IGNORE).subset(slice(n_poses))
    verify_poses = nominal.home_pose + rng.uniform(-1.0, 1.0, (n_verify, 6)) * BOX_HALF
    return sim, verify_poses


def _fit(nominal, setup, sim, gauge):
    free = None if gauge == "auto" else tuple(n for n in nominal.param_names if n not in PAPER_GAUGE)
    return identify(nominal, setup, q=sim.actuator_readings, y=sim.sensor_readings,
                    commanded=sim.commanded[sim.kept], method="fk-residual", weighted=False, free=free)


def paper2_table5(seed: int = 0, quick: bool = False, trials: int | None = None,
                  progress: Progress | None = None) -> Reproduction:
    """Paper 2 Table 5 (module docstring); ``trials`` campaigns per noise level and reading;
    ``progress(done, total)`` after each campaign."""
    t0 = time.perf_counter()
    n_tr = trials if trials is not None else (1 if quick else 5)
    # Quick mode runs fewer campaigns, not fewer poses: with 40 poses, D_E at N_L = 0.1 fell below
    # 80 % in 12 of 60 seeded campaigns (none of 60 with 100 poses: lowest 92.6 %).
    n_poses, n_verify = 100, 50
    nominal, real = builtin_machine("stewart-prototype"), builtin_machine("stewart-prototype-real")
    base = builtin_setup("indicators-prototype")
    sensor = base.sensor
    rows: list[Row] = []
    extra_rows = []
    headline: dict[str, float] = {}
    gauges_seen: dict[str, tuple[str, ...]] = {}
    for vi, reading in enumerate(("variance", "std")):
        for li, level in enumerate(NOISE_LEVELS):
            sigma = float(np.sqrt(level)) if reading == "variance" else level
            setup = MeasurementSetup(sensor, NoiseModel(np.full(3, sigma), np.array(0.0)))
            res = {"auto": [], "paper": []}
            for ti, ss in enumerate(np.random.SeedSequence([seed, vi, li]).spawn(n_tr)):
                rng = np.random.default_rng(ss)
                sim, verify_poses = _campaign(nominal, real, setup, n_poses, n_verify, rng)
                for gauge in res:
                    fit = _fit(nominal, setup, sim, gauge)
                    gauges_seen[gauge] = fit.gauge if gauge == "auto" else PAPER_GAUGE
                    res[gauge].append(_metrics(nominal, real, sensor, sim, fit.mechanism, verify_poses))
                if progress is not None:
                    progress(((vi * len(NOISE_LEVELS)) + li) * n_tr + ti + 1, 2 * len(NOISE_LEVELS) * n_tr)
            for gauge, vals in res.items():
                mean = {c: mean_sd([v[c] for v in vals]) for c in COLS}
                if reading == "variance" and gauge == "auto":
                    paper = _paper_row(level)
                    g = f"N_L = {level:g} (variance: sigma = {sigma:.4g} mm), auto gauge"
                    for c in COLS:
                        unit = "%" if c.startswith(("E_", "D_", "P_Er")) else ("mm" if c.endswith("_z") else "deg")
                        rows.append(Row(c, paper[c], mean[c][0], unit, mean[c][1], g))
                    headline[f"paper2_D_E_{level:g}"] = mean["D_E"][0]
                    headline[f"paper2_E_E_{level:g}"] = mean["E_E"][0]
                extra_rows.append((reading, f"{level:g}", f"{sigma:.4g}", gauge,
                                   *(f"{mean[c][0]:.4g}" for c in ("E_E", "D_E", "P_Ea_alpha", "P_Ea_beta", "P_Ea_z",
                                                                    "P_Er_alpha", "P_Er_beta", "P_Er_z"))))
    # noise-free: can each gauge represent the real machine at all?
    setup0 = MeasurementSetup(sensor, NoiseModel(np.zeros(3), np.array(0.0)))
    rng = np.random.default_rng(np.random.SeedSequence([seed, 9]))
    sim, verify_poses = _campaign(nominal, real, setup0, n_poses, n_verify, rng)
    g = "noise-free data: can the gauge represent Table 4's machine?"
    for gauge in ("auto", "paper"):
        fit = _fit(nominal, setup0, sim, gauge)
        mt = _metrics(nominal, real, sensor, sim, fit.mechanism, verify_poses)
        rows.append(Row(f"rms residual after fit, {gauge} gauge", None, fit.rms_residual, "mm", "", g))
        rows.append(Row(f"D_E, {gauge} gauge", None, mt["D_E"], "%", "", g))
        idx = default_estimated_index(real)  # the paper's 42 parameters (the leg gains held at 1)
        err = np.abs(fit.estimate[idx] - real.params[idx])
        worst = np.argsort(-err)[:3]
        rows.append(Row(f"mean |θ̂ − θ_real|, {gauge} gauge", None, float(err.mean()), "mm", "", g))
        rows.append(Row(f"largest |θ̂ − θ_real|, {gauge} gauge", None, float(err[worst[0]]), "mm", "", g,
                        "; ".join(f"{nominal.param_names[idx[i]]} {err[i]:.3g}" for i in worst)))
        headline[f"paper2_noise_free_rms_{gauge}_gauge_mm"] = fit.rms_residual
        headline[f"paper2_noise_free_max_param_error_{gauge}_gauge_mm"] = float(err[worst[0]])
    setup_d = {
        "machine": "nominal stewart-prototype (Table 3); real stewart-prototype-real (Table 3 + Table 4)",
        "sensor": "indicators-prototype: 3 indicators at radius 40 mm, 0/120/240°, plane offset 10 mm "
                  "(paper 2 gives neither indicator positions nor d_off)",
        "noise": "Gaussian on the indicator readings only, sigma = sqrt(N_L) ('variance', the rows) and sigma = N_L "
                 "(the 'std' lines of the extra table); leg readings exact",
        "poses": f"{n_poses} random calibration poses in home ± (20, 20, 10 mm, 8°, 8°, 8°) that the real machine "
                 f"reaches and the indicators read; {n_verify} random held-out poses in the same box; the real "
                 "prototype's leg_collision check is not applied",
        "method": "fk-residual (Y − h(FK(Q, η))), unweighted as in the paper; gauge auto "
                  f"({', '.join(gauges_seen.get('auto', ()))}) and paper ({len(PAPER_GAUGE)} fixed: b1, b2, a1, a2)",
        "seeds": f"numpy SeedSequence([{seed}, reading, level]).spawn({n_tr})",
        "Monte Carlo": f"{n_tr} campaign(s) (fresh poses and noise) per noise level and reading; mean (sd, range)",
    }
    notes = (
        "Table 5's note defines N_L as a variance; with sigma = sqrt(N_L) the largest level is sigma = 0.32 mm, "
        "32 times the 0.01 mm resolution of the paper's dial gauges. Both readings are shown.",
        "Paper 2 gives neither the number of poses behind Table 5, nor their kind, nor the indicator "
        "positions and d_off; our choices are stated in the setup and change the before/after errors.",
        "The paper's gauge fixes b1, b2, a1, a2 at nominal, but Table 4 perturbs b2 (3, 0, 0.3) and a2 "
        "(−0.9, 0.67, 0.53): fixing 12 parameters where 3 suffice (our automatic gauge) removes real "
        "degrees of freedom, so even noise-free data leave a residual and a floor under the after-errors "
        "(the noise-free rows; the 'paper' gauge lines of the extra table at the smallest noise). The "
        "paper's lowest-noise row (D_E 99.81 %, P_Ea z 0.002 mm) is better than that floor in our setup. "
        "With the poses and indicator positions unknown this is evidence, not proof, that the paper's "
        "simulation did not fix b2 and a2 as §2.2 says.",
        "The practical consequence of the paper's gauge is worse than the residual floor: to fit readings "
        "to ~0.025 mm with b2 and a2 held at wrong values, the other parameters move far from the real "
        "machine — on noise-free data the largest error is tens of millimetres (noise-free rows: b3.z, L0_3; "
        "20-27 mm over five seeded campaigns), the mean several mm. Such a calibration predicts the "
        "indicator readings but its parameters are not the machine's geometry: do not export them as joint "
        "positions, and do not compare them with a survey. With the automatic gauge the noise-free error "
        "against θ_real is only the gauge offset (a2.x, which Table 4 moves and the gauge holds; the "
        "largest error 1.27 mm is that offset propagated), and zero against the truth in the fit's gauge.",
        "Our before-errors P_Eb differ from the paper's (tilt about x larger, about y smaller, height "
        "larger); Table 5 gives neither the poses nor d_off, and we found no reading of Tables 3-4 that "
        "reproduces them, so the P_Ea / P_Er columns compare only roughly. D_E and E_E, which are "
        "ratios, follow the paper's trend (falling as the noise grows).",
        "P_Eb (before) depends only on the real machine and the poses, not on noise; the paper's P_Eb "
        "changes between noise levels (β: 3.11, 2.99, 2.78, 3.24°), so each level used different poses.",
        "Table 7 ('after calibration' on the real prototype, 110 optimal poses) equals nominal + Table 4 "
        "(the simulation's assumed real machine), with misprints: see the extra table.",
    )
    extra = (
        ("All variants (E_E, D_E, P_Ea and P_Er columns; mean over campaigns)",
         ("N_L read as", "N_L", "sigma mm", "gauge", "E_E %", "D_E %", "P_Ea a deg", "P_Ea b deg", "P_Ea z mm",
          "P_Er a %", "P_Er b %", "P_Er z %"), tuple(extra_rows)),
        ("Paper 2 Table 7 ('identified' parameters) against nominal (Table 3) + Table 4",
         ("parameter", "Table 7", "nominal+Table 4", "difference", "verdict"), table7_evidence()),
    )
    return Reproduction(name="paper2-table5", title="Saputra, Ong & Nee, Table 5 (and Table 7 evidence)",
                        rows=tuple(rows), setup=setup_d, notes=notes, headline=headline, extra=extra,
                        seconds=time.perf_counter() - t0)
