"""Paper 1 (Agheli & Nategh) §VI, Table I and the verification claims, in simulation.

Paper 1's experiment: real machine = nominal + U(−5, 5) mm on all 42 parameters; uniform
noise (legs ±0.01 mm, position ±0.025 mm, orientation ±0.001 rad); 15 random corners of the
64 corners of a workspace box ("boundary") vs 15 random poses inside it ("interior");
Levenberg–Marquardt on the inverse-kinematics residual (§V eq. 3; our ``ik-residual``);
parameter error = mean |ρ̂ − ρ_real| over the 42 parameters (Table I); verification on 10
of the 49 remaining corners (position error ~15 mm → ~500× smaller, orientation
0.05 rad → ~15000× smaller; < 0.03 mm and < 0.000003 rad after, §VI–VII).

The paper does not give its machine, workspace or Monte Carlo count; we run it on

* ``stewart-prototype`` (paper 2's machine) with the box ±15 mm, ±15 mm, ±8 mm, ±6°
  about home (the box of ``benchmarks/identification.py``);
* a machine-tool-sized symmetric hexapod (``MACHINE_TOOL``: joint radii 600 / 300 mm,
  legs 900 mm + 500 mm stroke, joint tilt limits 45°) with the box ±100 mm, ±10°, chosen
  a priori as a typical hexapod machine tool (paper 1's subject; its "before" errors of
  ~15 mm / 0.05 rad need a platform much larger than the prototype's 70 mm radius).

Over ``machines`` random real machines (seeded), each fitted six ways (boundary /
interior × unweighted as in the paper / noise-weighted GLS, plus the paper's squared
residual of eq. 3 unweighted). The best any linear unbiased
estimator can do from the same poses is the Gauss–Markov bound C = (JᵀΣ⁻¹J)⁻¹ at the real
parameters (the Cramér–Rao bound for Gaussian noise of the same variance); propagated to
the verification poses through G = ∂(reached pose)/∂(model parameters) (analytic
derivative of x_r = FK(IK(x_c, ρ_model), ρ_real), :func:`pose_sensitivity`), it bounds the
achievable pose accuracy:
rms orientation error ≥ sqrt(mean_j tr(G_j,ori C G_j,oriᵀ)).
"""

from __future__ import annotations

import time

import numpy as np

from pkmcal.identification.engine import identify
from pkmcal.identification.simulation import perturb_machine, simulate_campaign
from pkmcal.identification.verification import pose_errors
from pkmcal.io.setup_file import builtin_setup
from pkmcal.mechanisms import builtin_machine
from pkmcal.mechanisms.library import symmetric_hexapod
from pkmcal.planning.candidates import corner_poses
from pkmcal.progress import Progress
from pkmcal.reproduce.table import Reproduction, Row, mean_sd

#: Paper 1 Table I: mean parameter error (mm) before, after (15 interior), after (15 boundary).
PAPER_TABLE1 = {"before": 2.6652, "interior": 0.7236, "boundary": 0.3752}
#: Paper 1 §VI–VII verification claims.
PAPER_VERIFY = {"position_before_mm": 15.0, "orientation_before_rad": 0.05, "position_reduction": 500.0,
                "orientation_reduction": 15000.0, "position_after_mm": "< 0.03", "orientation_after_rad": "< 0.000003"}
ERROR_MM = 5.0
N_CALIB = 15
N_VERIFY = 10


def machine_tool_hexapod():
    """The machine-tool-sized hexapod of this reproduction (module docstring)."""
    return symmetric_hexapod(base_radius=600.0, platform_radius=300.0, offset=900.0, stroke=500.0,
                             u_joint_tilt=45.0, s_joint_tilt=45.0, name="machine-tool-hexapod")


#: name → (factory, box half-widths (mm, rad), limits of the real machine not checked)
MACHINES = {
    "stewart-prototype": (lambda: builtin_machine("stewart-prototype"),
                          np.array([15.0, 15.0, 8.0, *np.deg2rad([6.0, 6.0, 6.0])]), ("leg_collision",)),
    "machine-tool-hexapod": (machine_tool_hexapod, np.array([100.0, 100.0, 100.0, *np.deg2rad([10.0, 10.0, 10.0])]), ()),
}


def box_corners(machine, half: np.ndarray) -> np.ndarray:
    """The 2⁶ = 64 corners of the box home ± half (paper 1 §IV)."""
    home = machine.home_pose
    return corner_poses(np.stack([home - half, home + half], axis=1))


def pose_sensitivity(real, poses: np.ndarray) -> np.ndarray:
    """G (N, 6, p): ∂[position error, rotation-vector error]/∂(model parameters) at model = real.

    x_r = FK(IK(x_c, ρ_model), ρ_real) solves IK(x_r, ρ_real) = IK(x_c, ρ_model); at
    ρ_model = ρ_real, x_r = x_c and the small (δp, δω) (base frame, = the rotation vector of
    R_r R_cᵀ to first order) obeys J_twist (δp, δω) = ∂λ/∂ρ δρ, so G = J_twist⁻¹ ∂λ/∂ρ."""
    poses = real.as_pose_array(poses)
    return np.linalg.solve(real.twist_jacobian(poses), real.actuator_param_jacobian(poses))


def _trial(nominal, half, ignore, setup, rng):
    """One random real machine: four fits, verification, the bound. None if too few corners."""
    real = perturb_machine(nominal, ERROR_MM, rng, name="paper1-real")
    corners = box_corners(nominal, half)
    corners = corners[nominal.check_limits(corners).ok]
    probe = simulate_campaign(nominal, real, setup, corners, rng, ignore_limits=ignore)
    if len(probe.kept) < N_CALIB + N_VERIFY:
        return None
    order = rng.permutation(len(probe.kept))
    verify_poses = corners[probe.kept[order[N_CALIB:N_CALIB + N_VERIFY]]]
    inner = nominal.home_pose + rng.uniform(-1.0, 1.0, (4 * N_CALIB, 6)) * half
    s_in = simulate_campaign(nominal, real, setup, inner, rng, ignore_limits=ignore)
    sims = {"boundary": probe.subset(order[:N_CALIB]), "interior": s_in.subset(slice(N_CALIB))}
    out = {"before": float(np.mean(np.abs(nominal.params - real.params)))}
    before = pose_errors(nominal, real, verify_poses, ignore)
    for kind, sim in sims.items():
        for w, form in ((False, "plain"), (True, "plain"), (False, "squared")):
            r = identify(nominal, setup, q=sim.actuator_readings, y=sim.sensor_readings, method="ik-residual",
                         weighted=w, form=form, solver="lm")
            key = f"{kind}_{'weighted' if w else 'unweighted'}" + ("_squared" if form == "squared" else "")
            out[key] = float(np.mean(np.abs(r.estimate[:len(real.params)] - real.params)))
            if kind == "boundary" and form == "plain":
                after = pose_errors(r.mechanism, real, verify_poses, ignore)
                m = before.valid & after.valid
                out[key + "_pos_before"] = float(np.mean(before.position[m]))
                out[key + "_pos_after"] = float(np.mean(after.position[m]))
                out[key + "_ori_before"] = float(np.mean(before.orientation[m]))
                out[key + "_ori_after"] = float(np.mean(after.orientation[m]))
        # Gauss–Markov bound at the real machine, noise-free readings of the same poses
        exact = identify(real, setup, q=sim.actuator_true, y=sim.sensor_true, method="ik-residual")
        C = exact.uncertainty.covariance_prior
        out[f"{kind}_bound_param"] = float(np.sqrt(2 / np.pi) * np.mean(np.sqrt(np.diag(C))))
        if kind == "boundary":
            G = pose_sensitivity(real, verify_poses)
            S = np.einsum("nik,kl,njl->nij", G, C, G)
            out["bound_pos_rms"] = float(np.sqrt(np.mean(np.trace(S[:, :3, :3], axis1=1, axis2=2))))
            out["bound_ori_rms"] = float(np.sqrt(np.mean(np.trace(S[:, 3:, 3:], axis1=1, axis2=2))))
    # what the paper's own after-error (mean 0.3752 mm) does to the pose, if it were random
    implied = perturb_machine(real, 2 * PAPER_TABLE1["boundary"], rng)
    pe = pose_errors(implied, real, verify_poses, ignore)
    out["implied_pos"] = float(np.nanmean(pe.position))
    out["implied_ori"] = float(np.nanmean(pe.orientation))
    return out


def paper1_table1(seed: int = 0, quick: bool = False, machines: int | None = None,
                  progress: Progress | None = None) -> Reproduction:
    """Paper 1 Table I and §VI–VII verification claims (module docstring); ``progress(done,
    total)`` after each Monte Carlo machine."""
    t0 = time.perf_counter()
    n_mc = machines if machines is not None else (3 if quick else 40)
    setup = builtin_setup("full-pose-paper1")
    rows: list[Row] = []
    headline: dict[str, float] = {}
    skipped = {}
    for mi, (mname, (factory, half, ignore)) in enumerate(MACHINES.items()):
        nominal = factory()
        seeds = np.random.SeedSequence([seed, mi]).spawn(n_mc)
        trials = []
        skipped[mname] = 0
        for k, ss in enumerate(seeds):
            t = _trial(nominal, half, ignore, setup, np.random.default_rng(ss))
            if t is None:
                skipped[mname] += 1
            else:
                trials.append(t)
            if progress is not None:
                progress(mi * n_mc + k + 1, len(MACHINES) * n_mc)
        col = {k: [t[k] for t in trials] for k in trials[0]}
        g = f"{mname}, {len(trials)} random real machines"

        def add(q, paper, key, unit, note="", fn=None):
            if fn is None:
                m, s = mean_sd(col[key])
            else:   # a median over the machines of per-machine ratios
                m, s = float(np.median(fn)), f"median of {len(fn)} per-machine ratios, range [{min(fn):.3g}, {max(fn):.3g}]"
            rows.append(Row(q, paper, m, unit, s, g, note))
            return m

        add("mean parameter error before", PAPER_TABLE1["before"], "before", "mm")
        for w in ("unweighted", "weighted", "unweighted_squared"):
            wt = w.replace("_squared", ", squared residual (eq. 3)")
            add(f"after, 15 interior, {wt}", PAPER_TABLE1["interior"], f"interior_{w}", "mm")
            add(f"after, 15 boundary, {wt}", PAPER_TABLE1["boundary"], f"boundary_{w}", "mm")
        for w in ("unweighted", "weighted"):
            ratio = np.array(col[f"boundary_{w}"]) / np.array(col[f"interior_{w}"])
            add(f"boundary / interior, {w} (median)", round(PAPER_TABLE1["boundary"] / PAPER_TABLE1["interior"], 4),
                "", "", fn=list(ratio))
        add("bound on mean |error|, 15 interior", None, "interior_bound_param", "mm", "Gauss-Markov, sqrt(2/pi)*mean sd")
        add("bound on mean |error|, 15 boundary", None, "boundary_bound_param", "mm", "Gauss-Markov, sqrt(2/pi)*mean sd")
        add("verification position error before", PAPER_VERIFY["position_before_mm"], "boundary_weighted_pos_before", "mm")
        add("verification orientation error before", PAPER_VERIFY["orientation_before_rad"],
            "boundary_weighted_ori_before", "rad")
        for w in ("unweighted", "weighted"):
            add(f"position error after (boundary fit, {w})", PAPER_VERIFY["position_after_mm"],
                f"boundary_{w}_pos_after", "mm")
            add(f"orientation error after (boundary fit, {w})", PAPER_VERIFY["orientation_after_rad"],
                f"boundary_{w}_ori_after", "rad")
            pr = np.array(col[f"boundary_{w}_pos_before"]) / np.array(col[f"boundary_{w}_pos_after"])
            orr = np.array(col[f"boundary_{w}_ori_before"]) / np.array(col[f"boundary_{w}_ori_after"])
            add(f"position reduction factor ({w}, median)", PAPER_VERIFY["position_reduction"], "", "x",
                fn=list(pr))
            add(f"orientation reduction factor ({w}, median)", PAPER_VERIFY["orientation_reduction"], "", "x",
                fn=list(orr))
        add("bound: rms position error after, any unbiased fit", PAPER_VERIFY["position_after_mm"], "bound_pos_rms", "mm")
        b_ori = add("bound: rms orientation error after, any unbiased fit", PAPER_VERIFY["orientation_after_rad"],
                    "bound_ori_rms", "rad")
        add("orientation error of random 0.3752 mm-mean parameter errors", PAPER_VERIFY["orientation_after_rad"],
            "implied_ori", "rad")
        short = "prototype" if mname == "stewart-prototype" else "machine_tool"
        headline.update({
            f"paper1_{short}_before_mm": float(np.mean(col["before"])),
            f"paper1_{short}_interior_weighted_mm": float(np.mean(col["interior_weighted"])),
            f"paper1_{short}_boundary_weighted_mm": float(np.mean(col["boundary_weighted"])),
            f"paper1_{short}_boundary_unweighted_mm": float(np.mean(col["boundary_unweighted"])),
            f"paper1_{short}_orientation_after_weighted_rad": float(np.mean(col["boundary_weighted_ori_after"])),
            f"paper1_{short}_orientation_bound_rad": b_ori,
        })
    setup_d = {
        "machines": "stewart-prototype, box ±15, ±15, ±8 mm, ±6° about home, real machine's leg_collision "
                    "limit NOT checked; machine-tool-hexapod (symmetric, radii 600/300 mm, legs 900 + 500 mm "
                    "stroke, tilt limits 45°), box ±100 mm, ±10°, all limits checked",
        "real machines": f"nominal + U(−{ERROR_MM:g}, {ERROR_MM:g}) mm on all 42 parameters; {n_mc} per machine "
                         f"(skipped, too few reachable corners: {skipped})",
        "noise": "uniform: legs ±0.01 mm, position ±0.025 mm, orientation ±0.001 rad (setup full-pose-paper1)",
        "poses": "boundary: 15 random of the box corners the real machine reaches; interior: 15 uniform random "
                 "in the box (reachable); verification: 10 other reachable corners",
        "method": "ik-residual (q − IK(x̂, ρ)), Levenberg–Marquardt, all 42 parameters free; unweighted "
                  "(paper) and noise-weighted; also unweighted on the paper's own squared residual "
                  "L_q² − ‖l(x̂, ρ)‖² (eq. 3, form='squared'); verification uses the plain fits",
        "seeds": f"numpy SeedSequence([{seed}, machine index]).spawn({n_mc})",
        "Monte Carlo": f"{n_mc} real machines per hexapod (mean, sd, range over them)",
    }
    notes = (
        "Paper 1 does not state its machine, workspace, seeds or how many runs Table I averages; "
        "its numbers look like one run. 'before' is the mean |U(−5, 5)| over 42 draws: expectation 2.5 mm, "
        "sd 0.22 mm, so 2.6652 is one ordinary draw.",
        "The prototype's legs nearly touch at home (0.13 mm margin); with ±5 mm errors every pose of the "
        "real machine violates the leg-collision check, so that check is switched off for the real "
        "prototype (simulate_campaign ignore_limits=('leg_collision',)). Other limits are kept.",
        "Parameter errors after calibration are dominated by the few weakly observable parameter "
        "combinations (e.g. joint positions along the nearly constant leg directions against the leg "
        "offsets); they barely move the pose, which is why the pose errors fall 100× or more while "
        "the mean parameter error stays near the 'bound on mean |error|' rows: what any unbiased fit "
        "can reach from 15 poses with this noise. Our weighted fit sits near them; the paper's 0.3752 mm "
        "is below the bound on both our machines, but the bound depends on the unknown machine and "
        "workspace, so Table I alone is not proven inconsistent.",
        "The paper's orientation claim (< 0.000003 rad after, 15000× reduction) is two orders of "
        "magnitude below the row 'bound: rms orientation error after, any unbiased fit' on both "
        "machines: with ±0.001 rad orientation noise and 15 poses no unbiased estimator reaches it "
        "(the bound scales with the noise, not with the machine's size, for the orientation). The "
        "'< 0.03 mm' position claim is also below the position bound, by a smaller factor.",
        "The last row (pose error of random parameter errors with the paper's after-mean 0.3752 mm) "
        "is a weaker check: identified errors are not random, they lie mostly along weakly observable "
        "directions that move the pose little (our own fits have larger parameter errors and smaller "
        "pose errors). It only shows that 0.37 mm-size parameter errors are not harmless by themselves.",
        "Boundary beats interior in the mean and the median on both machines and both weightings, as "
        "the paper claims, but not for every random machine (see the ratio ranges). The unweighted fit "
        "(the paper's) is far worse than the weighted one, most on the interior poses, where the "
        "orientation noise (times the platform radius) dominates the leg residual.",
        "Before-calibration pose errors: the machine-tool hexapod gives the paper's ~15 mm position "
        "error but half its 0.05 rad orientation error; the prototype (70 mm platform radius) gives "
        "a similar position error and 2-3 times the orientation error. Neither was tuned to match.",
    )
    return Reproduction(name="paper1-table1", title="Agheli & Nategh, Table I and verification claims (§VI–VII)",
                        rows=tuple(rows), setup=setup_d, notes=notes, headline=headline,
                        seconds=time.perf_counter() - t0)
