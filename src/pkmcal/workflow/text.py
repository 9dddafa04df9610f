"""What ``pkmcal identify`` prints about a fit: the parameter table, the fit summary (method,
poses, solver, residuals, chi², identifiability, covariance, outliers, priors, sessions).

The table shows parameter, nominal, identified and ±σ (mm; degrees for angle parameters);
chi² = Σ |W r|² with the noise whitening W at the solution, chi²/dof its reduced value.
"""

from __future__ import annotations

import numpy as np

from pkmcal.identification.identifiability import describe_named, format_direction  # noqa: F401  (printing)


def _fmt(v: float, angle: bool) -> str:
    return f"{np.rad2deg(v):.6f}°" if angle else f"{v:.6f}"


def _angle_names(result) -> set[str]:
    """Names of the angle parameters (shown in degrees), from the sensor's ``param_is_angle``
    and the machine's (a machine without the flags, the hexapod, has only lengths), and the
    result's own flags where it has them (the sessions' offsets of rotary actuators)."""
    sensor, mech = result.sensor, result.mechanism
    angles = {n for n, a in zip(sensor.param_names, sensor.param_is_angle) if a}
    angles.update(n for n, a in zip(mech.param_names, mech.param_is_angle) if a)
    angles.update(n for n, a in zip(getattr(result, "names", ()), getattr(result, "param_is_angle", ())) if a)
    return angles


def result_table(result) -> str:
    """Parameter, nominal, identified, ±σ (mm; degrees for angles), one line per parameter."""
    angles = _angle_names(result)
    free = set(result.free)
    std = dict(zip(result.free, result.std))
    rows = [("parameter", "nominal", "identified", "±std", "")]
    for i, n in enumerate(result.names):
        if n not in free and n not in result.gauge and i >= len(result.mechanism.param_names):
            continue  # sensor parameters held at their values: not part of the fit
        a = n in angles
        note = "gauge (fixed)" if n in result.gauge else ("fixed" if n not in free else "")
        rows.append((n, _fmt(result.initial[i], a), _fmt(result.estimate[i], a),
                     _fmt(std[n], a) if n in std else "-", note))
    w = [max(len(r[k]) for r in rows) for k in range(5)]
    return "\n".join(f"{r[0]:<{w[0]}}  {r[1]:>{w[1]}}  {r[2]:>{w[2]}}  {r[3]:>{w[3]}}  {r[4]}".rstrip() for r in rows)


def free_statement(result, free_opt: list[str] | None, setup) -> str:
    """Which parameters were estimated and where each list came from (one line)."""
    p = len(result.mechanism.param_names)
    names = result.names
    mech_free = [n for n in result.free if names.index(n) < p]
    sensor_free = [n for n in result.free if names.index(n) >= p]
    setup_free = set(setup.sensor.default_free)
    several = result.sessions is not None and result.sessions.several
    if several:   # NAME@LABEL of the setup's free: names, and the sessions' actuator offsets
        setup_free = set(result.sensor.default_free)
        offsets = {n for n in names[p + len(result.sensor.param_names):]}
    from pkmcal.identification.residuals import default_fixed_parameters, sensor_held_parameters

    held_by_machine = [n for n in default_fixed_parameters(result.mechanism) if n not in result.free]
    held_by_sensor = [] if free_opt is not None else \
        [n for n in sensor_held_parameters(result.mechanism, result.sensor)
         if n not in result.free and n not in held_by_machine]
    if free_opt is not None:
        src = "--free"
    elif held_by_machine or held_by_sensor:
        parts = ([f"{', '.join(held_by_machine)}, which the machine holds unless freed by name"]
                 if held_by_machine else []) + \
            ([f"{', '.join(held_by_sensor)}, which this sensor cannot determine (it reads heights only, or only on "
              "the bed; held at the machine file's values unless freed by name or given a prior, e.g. the measured "
              "rods)"] if held_by_sensor else [])
        src = f"all but {'; and '.join(parts)}; no --free given"
    else:
        src = "all, no --free given"
    text = f"free parameters: {len(mech_free)} of {p} machine parameters ({src})"
    if sensor_free:
        parts = [f"{n} ({'setup free:' if n in setup_free else 'session offsets' if several and n in offsets else '--free'})"
                 for n in sensor_free]
        text += "; sensor: " + ", ".join(parts)
    else:
        text += "; no sensor parameter"
    held = [n for n in (result.sensor.default_free if several else setup.sensor.default_free)
            if n not in result.free]
    if held:
        text += f"; setup-free sensor parameters held: {', '.join(held)} (--fix or gauge)"
    return text + ". Rule: --free adds to the setup's free: list, it does not replace it"


def _residual_line(result) -> str:
    groups: dict[str, list[str]] = {}
    for name, unit in zip(result.residual_names, result.residual_units or ("1",) * len(result.residual_names)):
        groups.setdefault({"rad": "deg"}.get(unit, unit), []).append(name)
    rms = result.rms_by_unit()
    parts = [f"rms {rms[u]:.6g}{'' if u == '1' else ' ' + u} over {', '.join(ns)}" + (" (whitened or mixed units)"
                                                                                   if u == "1" else "")
             for u, ns in groups.items()]
    return "residuals at the solution (measured - predicted, raw): " + "; ".join(parts)


def fit_summary(result, free_line: str | None = None) -> str:
    u = result.uncertainty
    rep = result.identifiability
    dropped = (f", {len(result.dropped)} dropped (rows {', '.join(str(int(k) + 1) for k in result.dropped[:20])}"
               f"{' ...' if len(result.dropped) > 20 else ''} of the file, 1-based)") if len(result.dropped) else ""
    whitened = ("whitened (noise model): chi2 = sum |W r|^2 = "
                f"{u.chi2:.6g} with the weights at the solution, chi2/dof = {u.chi2:.6g}/{u.dof} = "
                f"{u.reduced_chi2:.4g}, rms whitened residual sqrt(chi2/M) = {result.rms_whitened:.4g}")
    extra = "".join([f", {result.loss} loss" if result.loss != "linear" else "",
                     " + 1/2 sum of the squared prior rows" if len(result.priors) else ""])
    cost = (f"solver cost 1/2 sum |W0 r|^2 = {result.cost:.6g} (weights from the start, held fixed while solving"
            f"{extra})"
            if result.weighted else
            f"solver cost 1/2 sum r^2 = {result.cost:.6g} (plain least squares on the raw residuals)")
    lines = [
        f"method {result.method} ({'noise-weighted' if result.weighted else 'unweighted'}), "
        f"{len(result.used_poses)} poses used{dropped}, {len(result.free)} free parameters",
        *([free_line] if free_line else []),
        f"solver: {'converged' if result.success else 'NOT converged'} after {result.nfev} evaluations: {result.message}",
        _residual_line(result),
        whitened if (result.weighted or np.isfinite(u.chi2)) else "no noise model to whiten with: chi2 undefined",
        cost,
        f"identifiability ({rep.basis or 'at the start'}): rank {rep.rank} of {rep.n_params}, "
        f"condition number {rep.condition_number:.3g}",
        f"std: {u.description} — this covariance is written to the machine file",
    ]
    for d in rep.null_space:
        lines.append(f"  unobservable: {format_direction(d)}")
    lines.extend(robust_lines(result))
    lines.extend(session_lines(result))
    for w in result.warnings:
        lines.append(w if w.startswith("warning: ") else f"note: {w}")
    return "\n".join(lines)


def session_lines(result) -> list[str]:
    """The fit summary's lines on the sessions: poses per session and each session's
    identified sensor (setup-file keys, mm and degrees; ``dq`` the re-homing offsets)."""
    values = result.session_values()
    if not values:
        return []
    ses = result.sessions
    counts = dict(zip(ses.labels, ses.counts()))
    out = [f"sessions: {len(values)} ({', '.join(f'{lab}: {int(counts[lab])} poses' for lab in ses.labels)}), "
           "each with its own sensor parameters NAME@LABEL"
           + ("; actuator zero offsets dq_i@LABEL after the first" if ses.offsets else "")]
    for lab, groups in values.items():
        parts = []
        for key, v in groups.items():
            text = (", ".join(f"{k} {x:.6g}" for k, x in v.items()) if isinstance(v, dict)
                    else ", ".join(f"{x:.6g}" for x in v))
            parts.append(f"{key}: {text}")
        out.append(f"  session {lab} (mm, deg): " + "; ".join(parts))
    return out


def robust_lines(result) -> list[str]:
    """The fit summary's lines on the normalised residuals, the loss and the priors."""
    out = []
    sc = result.screening
    if sc is not None and sc.sigma.size:
        j = int(np.argmax(sc.sigma))
        out.append(f"normalised residuals sqrt(|W r|^2/k) per pose (noise sigmas): median {np.median(sc.sigma):.3g}, "
                   f"max {sc.sigma[j]:.3g} (pose {int(sc.pose_numbers[j])}); {len(sc.flagged)} beyond "
                   f"{sc.threshold:g} sigma" + (f"; rejection at {sc.reject:g} sigma: {len(sc.rejected)} pose(s) "
                                                f"dropped in {sc.rounds} fit(s)" if sc.reject is not None else ""))
    if result.loss != "linear":
        out.append(f"loss: {result.loss} on the whitened rows, f_scale {sc.f_scale:g} sigma (scipy least_squares); "
                   "chi2 and the covariance over the poses within the threshold")
    pr = result.priors
    if len(pr):
        std = dict(zip(result.free, result.std))
        out.append(f"priors (maximum a posteriori; the covariance is the posterior one), {len(pr)} parameter(s):")
        for e in pr.to_dict(result.estimate, std):
            post = "-" if e["posterior_std"] is None else f"{e['posterior_std']:.4g}"
            out.append(f"  {e['parameter']}: prior {e['mean']:.6g} ± {e['std']:.4g} {e['unit']} -> {e['estimate']:.6g} "
                       f"± {post} (pull {e['pull']:+.2f}; {e['source']})")
    return out
