"""Gauge of a recorded calibration: the directions its measurements cannot see, and a
calibration re-expressed in another calibration's gauge.

A fit whose Jacobian J has a null space N (p × k: the parameter combinations no reading
changes along, e.g. a delta printer's towers turned together under a Z probe) holds a gauge
set g of k parameters at the machine file's values (:func:`pkmcal.identification.
identifiability.choose_gauge`), and estimates the others relative to them. The automatic
gauge can differ from one campaign to the next. Two fits of the same machine in gauges g_A
and g_B differ, to first order, by a move along N: θ_B + N t is B's estimate in A's gauge
when (θ_B + N t)[g_A] = θ_A[g_A], i.e.

    t = N[g_A]⁻¹ (θ_A[g_A] − θ_B[g_A]),   θ_B' = θ_B + N t,
    Π = I − N N[g_A]⁻¹ E_{g_A},           Σ_B' = Π Σ_B Πᵀ     (Σ_B'[g_A] = 0)

with E_{g_A} the rows of the identity at g_A (tests/history/test_gauge.py checks this
against a refit of the same data with A's gauge held). N is computed when the calibration is
recorded (:func:`null_space_of`): the identifiability analysis of the calibrated machine and
its identified setup at random poses of its workspace (:func:`pkmcal.identification.
identifiability.identifiability`), over the engine's default candidates and the fit's own
free parameters; the null space of a kinematic model is structural (the same for any generic
pose set), so the calibration's own poses are not needed.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pkmcal.errors import PkmcalError

#: Largest condition number of N[g_A] for which a re-expression is trusted.
MAX_CONDITION = 1e8
#: Poses and candidates of the random plan the null space is computed at.
N_POSES = 40
N_CANDIDATES = 200


def _nominal_of(record: dict):
    """The nominal machine the calibration record names (a built-in, or a file that still
    exists), or None."""
    import os

    from pkmcal.io.lookup import load_machine
    from pkmcal.mechanisms.library import is_builtin_name

    src = (record.get("inputs") or {}).get("machine") or {}
    spec = src.get("builtin") or src.get("file")
    if not isinstance(spec, str) or not (("builtin" in src and is_builtin_name(spec)) or os.path.isfile(spec)):
        return None
    try:
        return load_machine(spec)
    except PkmcalError:
        return None


def null_space_of(machine, setup_specs, method: str | None, extra: list[str],
                  record: dict | None = None) -> dict | None:
    """``{"names", "directions"}``: the null space of the identification Jacobian of
    ``machine`` measured with the first loadable setup of ``setup_specs`` (the calibrated
    file's identified setup, then the setup the record names), over the engine's default
    candidates plus ``extra`` (the fit's free and gauge names); one row of coefficients per
    direction, internal units (mm, rad). None when no setup loads or the analysis is not
    possible for this machine. The poses are planned on the calibrated machine, else on the
    nominal machine of the calibration ``record`` (a tight design whose calibrated home pose
    sits at a limit does not plan)."""
    from pkmcal.identification.identifiability import identifiability
    from pkmcal.io.lookup import load_setup
    from pkmcal.planning.plan import plan_poses

    setup = None
    for spec in setup_specs:
        if spec is None:
            continue
        try:
            setup = load_setup(spec, machine)
            break
        except PkmcalError:
            continue
    if setup is None:
        return None
    poses = None
    for planned_on in (machine, _nominal_of(record or {})):    # a calibrated tight design may not plan
        if planned_on is None or planned_on.param_names != machine.param_names:
            continue
        try:
            poses = plan_poses(planned_on, setup, N_POSES, algorithm="random", seed=0,
                               n_candidates=N_CANDIDATES).poses
            break
        except PkmcalError:
            continue
    if poses is None:
        return None
    try:
        rep = identifiability(machine, setup, poses, method=method)
        missing = [n for n in extra if n not in rep.names]
        if missing:
            rep = identifiability(machine, setup, poses, method=method, free=list(rep.names) + missing)
    except PkmcalError:
        return None
    order = [n for n in rep.names if any(n in d for d in rep.null_space)]
    return {"names": order, "directions": [[float(d.get(n, 0.0)) for n in order] for d in rep.null_space]}


def regauge(b, a) -> tuple[object | None, str]:
    """(``b`` re-expressed in ``a``'s gauge, how) or (None, why not) (module docstring)."""
    ns = b.null_space or a.null_space
    if not ns or not ns.get("directions"):
        return None, "no unidentifiable directions were recorded with these calibrations"
    index = {n: i for i, n in enumerate(a.names)}
    dirs = np.asarray(ns["directions"], dtype=float)            # (k, q)
    k, p = dirs.shape[0], len(a.names)
    N = np.zeros((p, k))
    for j, n in enumerate(ns["names"]):
        if n in index:                                          # sensor parameters: not in the machine file
            N[index[n]] = dirs[:, j]
    in_d = np.any(N != 0, axis=1)
    ha, hb = a.held, b.held
    if np.any(ha[~in_d] != hb[~in_d]):
        return None, "they hold different parameters outside the unidentifiable directions"
    out = np.flatnonzero(ha & ~in_d)
    if np.any(np.abs(a.values[out] - b.values[out]) > 1e-12 * np.maximum(1.0, np.abs(a.values[out]))):
        return None, "they hold parameters outside the unidentifiable directions at different values"
    g = np.flatnonzero(ha & in_d)
    if len(g) != k or np.count_nonzero(hb & in_d) != k:
        return None, (f"a gauge holds {k} parameter(s) of the unidentifiable directions; "
                      f"{a.label} holds {len(g)}, {b.label} {np.count_nonzero(hb & in_d)} (priors or --fix of "
                      "identifiable parameters)")
    M = N[g]
    if np.linalg.cond(M) > MAX_CONDITION:
        return None, f"{', '.join(a.names[i] for i in g)} do not fix the unidentifiable directions"
    t = np.linalg.solve(M, a.values[g] - b.values[g])
    values = b.values + N @ t
    values[g] = a.values[g]
    E = np.eye(p)[g]
    Pi = np.eye(p) - N @ np.linalg.solve(M, E)
    cov = Pi @ b.covariance @ Pi.T
    cov = 0.5 * (cov + cov.T)
    cov[g, :] = 0.0
    cov[:, g] = 0.0
    names = ", ".join(a.names[i] for i in g)
    return (dataclasses.replace(b, values=values, covariance=cov),
            f"B re-expressed in A's gauge ({names} held) along the {k} unidentifiable direction(s) recorded with it")


__all__ = ["MAX_CONDITION", "null_space_of", "regauge"]
