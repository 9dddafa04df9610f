"""Paper 1 (Agheli & Nategh) §IV, Figs. 4–9: where in the workspace parameter errors show,
and what that says about where to measure.

Paper 1 perturbs every parameter by U(±0.1 mm), draws the pose error along lines that vary
one coordinate with the others fixed ("curves", 20 of 100 drawn) and concludes from the
maxima at the ends that "the measurement configurations should be selected on the
boundary of the workspace", and at the highest z. We redo the slices
(:func:`pkmcal.planning.error_maps.error_slices`: stewart-prototype, its all-reachable
corner box, 20 slices per coordinate) and then ask whether the observation can carry the
conclusion:

* **Affinity.** For a fixed parameter error δρ the pose error along a line x(s) is
  e(s) = G(x(s)) δρ, with G the pose sensitivity; across a box of a few degrees G changes
  little, so e(s) is nearly affine, e(s) ≈ a + b s. The norm of an affine function is
  convex, and a convex function on an interval peaks at an end — whatever the machine's
  observability. We fit a + b s to the 6-vector e(s) (position error and rotation vector)
  of every slice and report the largest deviation relative to max ‖e‖: if small, the
  "maximum at the boundary" count holds by construction and is no evidence.
* **Information.** What a pose contributes to a calibration is its information, not the
  error of one random δρ. The D-optimal selection (:func:`~pkmcal.planning.selection.select_default`,
  full-pose set-up of paper 1) on random candidates of the whole reachable workspace shows
  where the information is: the share of chosen poses within 1 mm / 1° of a stroke or joint
  limit (the boundary of the reachable workspace), against that share among the candidates,
  and how high (z) they sit.
"""

from __future__ import annotations

import time

import numpy as np

from pkmcal.conventions import euler_to_matrix
from pkmcal.identification.simulation import perturb_machine
from pkmcal.identification.verification import pose_errors
from pkmcal.io.setup_file import builtin_setup
from pkmcal.mechanisms import builtin_machine
from pkmcal.planning.blocks import planning_model
from pkmcal.planning.candidates import corner_box, generate_candidates, workspace_box
from pkmcal.planning.error_maps import error_slices
from pkmcal.planning.selection import select_default
from pkmcal.reproduce.table import FigureSpec, Reproduction, Row

MAGNITUDE = 0.1
#: Within this of a limit counts as on the boundary of the reachable workspace (mm; degrees).
NEAR_MM, NEAR_DEG = 1.0, 1.0
COORDS = ("x", "y", "z", "a", "b", "c")


def _rotation_vectors(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (N, 3) of rotation matrices (N, 3, 3) (small angles: the axial
    vector of the skew part, exact to second order)."""
    return 0.5 * np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)


def slice_nonlinearity(nominal, real, values: np.ndarray, bases: np.ndarray) -> np.ndarray:
    """max_s ‖e(s) − (a + b s)‖ / max_s ‖e(s)‖ per slice (6, C), e = [Δp; rotation vector of
    R_r R_cᵀ] (mm, and rad times the platform radius, so both in mm), a + b s the
    least-squares line (module docstring); NaN for slices with fewer than 3 reachable points."""
    r = float(nominal.length_scale)
    out = np.full(bases.shape[:2], np.nan)
    every = tuple(real.check_limits(nominal.home_pose[None]).violations)
    for k in range(6):
        for c in range(bases.shape[1]):
            poses = np.repeat(bases[k, c][None], values.shape[1], axis=0)
            poses[:, k] = values[k]
            ok = nominal.check_limits(poses).ok
            if ok.sum() < 3:
                continue
            pe = pose_errors(nominal, real, poses[ok], ignore_limits=every)
            Rr, Rc = euler_to_matrix(pe.reached[:, 3:6]), euler_to_matrix(poses[ok, 3:6])
            e = np.concatenate([pe.reached[:, 0:3] - poses[ok, 0:3],
                                r * _rotation_vectors(Rr @ np.swapaxes(Rc, 1, 2))], axis=1)
            s = values[k][ok]
            A = np.stack([np.ones_like(s), s - s.mean()], axis=1)
            fit = A @ np.linalg.lstsq(A, e, rcond=None)[0]
            out[k, c] = np.max(np.linalg.norm(e - fit, axis=1)) / np.max(np.linalg.norm(e, axis=1))
    return out


def _at_end(curves: np.ndarray) -> tuple[int, int, int]:
    """(slices peaking at an end of their reachable stretch, at the upper end, slices)."""
    end = top = n = 0
    for c in curves:
        ok = np.flatnonzero(np.isfinite(c))
        if ok.size < 2:
            continue
        n += 1
        j = ok[np.argmax(c[ok])]
        end += j in (ok[0], ok[-1])
        top += j == ok[-1]
    return end, top, n


def paper1_figs4_9(seed: int = 0, quick: bool = False, n_candidates: int | None = None, progress=None) -> Reproduction:
    """Paper 1 Figs. 4–9 and the boundary conclusion (module docstring); ``progress(done,
    total)`` after the slices and after each selection."""
    t0 = time.perf_counter()
    n_curves, n_points = (6, 21) if quick else (20, 41)
    n_cand = n_candidates if n_candidates is not None else (400 if quick else 2000)
    m = builtin_machine("stewart-prototype")
    setup = builtin_setup("full-pose-paper1")
    box = corner_box(m, workspace_box(m, setup), setup)
    rng = np.random.default_rng([seed, 4])
    real = perturb_machine(m, MAGNITUDE, rng)
    sl = error_slices(m, box, magnitude=MAGNITUDE, n_curves=n_curves, n_points=n_points, rng=rng, real=real)
    rows: list[Row] = []
    g = f"error slices (Figs. 4-9): ±{MAGNITUDE:g} mm parameter errors, corner box, {n_curves} slices per coordinate"
    tot_p = tot_o = tot = 0
    for k, name in enumerate(COORDS):
        ep, top, n = _at_end(sl.position[k])
        eo, _, _ = _at_end(sl.orientation[k])
        tot_p, tot_o, tot = tot_p + ep, tot_o + eo, tot + n
        rows.append(Row(f"slices along {name} with the largest position error at an end", "at the boundary",
                        float(ep), "", f"of {n}", g))
        if name == "z":
            rows.append(Row("slices along z with the largest position error at the top", "at the highest z",
                            float(top), "", f"of {n}", g))
    rows.append(Row("all slices, largest position error at an end", "at the boundary", float(tot_p), "", f"of {tot}", g))
    rows.append(Row("all slices, largest orientation error at an end", "at the boundary", float(tot_o), "",
                    f"of {tot}", g))
    nl = slice_nonlinearity(m, real, sl.values, sl.bases)
    if progress is not None:
        progress(1, 4)
    v = nl[np.isfinite(nl)]
    rows.append(Row("deviation of the error vector from a straight line (median over slices)", None,
                    float(np.median(v)), "", "max ‖e − (a + b s)‖ / max ‖e‖", g))
    rows.append(Row("deviation of the error vector from a straight line (largest slice)", None, float(v.max()), "",
                    "", g))
    cand = generate_candidates(m, setup, n=n_cand, rng=np.random.default_rng([seed, 5])).poses
    G, ok = planning_model(m, setup).blocks(cand)
    cand, G = cand[ok], G[ok]
    margins = m.check_limits(cand).margins
    near = np.zeros(len(cand), dtype=bool)
    for key in ("stroke", "u_joint_tilt", "s_joint_tilt"):
        if key in margins:
            near |= margins[key] < (NEAR_MM if key == "stroke" else np.deg2rad(NEAR_DEG))
    g2 = f"where the information is: D-optimal poses among {len(cand)} random candidates of the reachable workspace"
    rows.append(Row("candidates within 1 mm / 1° of a stroke or joint limit", None, 100.0 * float(near.mean()), "%",
                    "", g2))
    z_lo, z_hi = cand[:, 2].min(), cand[:, 2].max()
    for k, n_sel in enumerate((15, 30, 60)):
        chosen = select_default(G, n_sel).chosen
        if progress is not None:
            progress(k + 2, 4)
        rows.append(Row(f"D-optimal {n_sel}: within 1 mm / 1° of a limit", "on the boundary",
                        100.0 * float(near[chosen].mean()), "%", "", g2))
        rows.append(Row(f"D-optimal {n_sel}: mean height in the candidates' z range (0 bottom, 1 top)",
                        "highest z", float(np.mean((cand[chosen, 2] - z_lo) / (z_hi - z_lo))), "", "", g2))
    setup_d = {
        "machine": "stewart-prototype; error maps: real = nominal + U(±0.1 mm) on every parameter (paper 1 §IV)",
        "slices": f"{n_curves} per coordinate, {n_points} points each, on the all-reachable corner box "
                  f"({', '.join(f'±{h:.3g}' for h in (box[:3, 1] - box[:3, 0]) / 2)} mm, "
                  f"{', '.join(f'±{np.rad2deg(h):.3g}' for h in (box[3:, 1] - box[3:, 0]) / 2)}°); points outside the "
                  "nominal limits left out",
        "selection": f"select_default (D-optimal exchange) on the full-pose-paper1 planning Jacobian, {len(cand)} "
                     "random checked candidates of the workspace box",
        "seeds": f"numpy default_rng([{seed}, 4]) (machine, slices), default_rng([{seed}, 5]) (candidates)",
        "Monte Carlo": "one random real machine (paper 1 draws one), one candidate set",
    }
    notes = (
        "Paper 1's observation is reproduced: the pose error along a line is largest at an end of the line, "
        "for (almost) every slice and coordinate. It is weak evidence for the conclusion: the error vector "
        "along a line is an affine function to the printed deviation (a few per cent at most), and the norm of "
        "an affine function is convex, so its maximum on a segment is at an end for any machine, any δρ and "
        "any line — the count could not have come out otherwise. The z slices peak at the top (for the "
        "position error, in all 20 slices, and for each of 8 random δρ we tried): the pose sensitivity grows "
        "with the platform height, as paper 1 says; but a larger pose error from one δρ is not more "
        "information, and the D-optimal poses do not crowd at the top (their mean height rows: mid-range).",
        "What does support measuring at the boundary is the information the poses carry: the D-optimal poses "
        "(the sets that minimise the parameter covariance's volume) lie mostly within 1 mm / 1° of a stroke or "
        "joint limit, far more often than random reachable poses do. That boundary is the reachable "
        "workspace's, set by the joints, not the faces or corners of a box: paper1-table1 shows that 15 "
        "D-optimal poses beat 15 box corners 4-10 times in parameter error.",
        "The figure (pkmcal reproduce paper1-figs4-9 --figures DIR) draws the slices as paper 1's Figs. 4-9, "
        "one column per coordinate.",
    )

    def build():
        from pkmcal.report.figures import error_slices_figure

        return error_slices_figure(sl.values, sl.position, sl.orientation, MAGNITUDE,
                                   "Paper 1 Figs. 4-9: pose error along slices of each coordinate (stewart-prototype)")

    return Reproduction(name="paper1-figs4-9", title="Agheli & Nategh, Figs. 4-9: pose error across the workspace and "
                        "the boundary conclusion", rows=tuple(rows), setup=setup_d, notes=notes,
                        headline={"paper1_slices_at_end": float(tot_p), "paper1_slices": float(tot),
                                  "paper1_slice_nonlinearity_max": float(v.max())},
                        figures=(FigureSpec("paper1-figs4-9", "pose error along slices of each coordinate", build),),
                        seconds=time.perf_counter() - t0)


__all__ = ["paper1_figs4_9", "slice_nonlinearity"]
