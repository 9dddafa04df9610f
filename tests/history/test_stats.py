"""The statistics of pkmcal.history.stats against their distributions: the false-alarm
rates of the per-parameter z (Bonferroni), the joint χ² and the fleet's leave-one-out t,
measured by Monte Carlo on draws of the null hypothesis, and the joint χ² against a plain
inverse. Tolerances: 5 binomial standard deviations of the measured rate (a correct test
fails one in ~3.5 million runs)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as st

from pkmcal.history.stats import compare, fleet, joint_chi2, leave_one_out_t, z_limit
from pkmcal.history.store import CalibrationRecord


def _record(values, cov, serial="U1", id_=1, names=None, gauge=()):
    p = len(values)
    names = names or tuple(f"p{i}" for i in range(p))
    return CalibrationRecord(serial=serial, model="m", machine="m-cal", kind="test", date=f"2026-01-{id_:02d}T00:00:00Z",
                             pkmcal_version="t", names=tuple(names), units=("mm",) * p,
                             values=np.asarray(values, dtype=float), covariance=np.asarray(cov, dtype=float), id=id_,
                             record={"gauge": list(gauge)})


def _spd(rng, p):
    a = rng.normal(size=(p, p))
    return a @ a.T / p + 0.1 * np.eye(p)


def _rate_band(alpha, n):
    return 5 * np.sqrt(alpha * (1 - alpha) / n)


def test_joint_chi2_is_the_plain_quadratic_form_on_a_full_rank_covariance():
    rng = np.random.default_rng(1)
    c = _spd(rng, 5) * np.array([1, 1e-4, 1e2, 1, 1])[:, None] * np.array([1, 1e-4, 1e2, 1, 1])[None, :]
    d = rng.normal(size=5)
    chi2, dof = joint_chi2(d, c)
    assert dof == 5
    assert chi2 == pytest.approx(d @ np.linalg.solve(c, d), rel=1e-9)


def test_joint_chi2_over_the_identifiable_subspace_of_a_singular_covariance():
    rng = np.random.default_rng(2)
    b = rng.normal(size=(4, 2))
    c = b @ b.T                                   # rank 2
    d = b @ rng.normal(size=2)                    # in its range
    chi2, dof = joint_chi2(d, c)
    assert dof == 2
    assert chi2 == pytest.approx(d @ np.linalg.pinv(c) @ d, rel=1e-8)


def test_per_parameter_false_alarm_rate_is_alpha_family_wise():
    """Independent parameters: P(any |z| > limit) = 1 − (1 − α/m)^m ≤ α (Bonferroni)."""
    rng = np.random.default_rng(3)
    m, n, alpha = 6, 40000, 0.05
    s1, s2 = rng.uniform(0.5, 2, m), rng.uniform(0.5, 2, m)
    z = (rng.normal(size=(n, m)) * s2 - rng.normal(size=(n, m)) * s1) / np.hypot(s1, s2)
    rate = np.mean(np.any(np.abs(z) > z_limit(alpha, m), axis=1))
    expected = 1 - (1 - alpha / m) ** m
    assert abs(rate - expected) < _rate_band(expected, n)


def test_joint_false_alarm_rate_is_alpha_with_correlated_parameters():
    rng = np.random.default_rng(4)
    m, n, alpha = 5, 40000, 0.05
    ca, cb = _spd(rng, m), _spd(rng, m)
    la, lb = np.linalg.cholesky(ca), np.linalg.cholesky(cb)
    d = rng.normal(size=(n, m)) @ lb.T - rng.normal(size=(n, m)) @ la.T
    chi2, dof = joint_chi2(d, ca + cb)
    rate = np.mean(chi2 > st.chi2.isf(alpha, dof))
    assert abs(rate - alpha) < _rate_band(alpha, n)


def test_compare_flags_the_changed_parameter_with_its_sigma_and_never_a_held_one():
    c = np.diag([0.01, 0.04, 0.0, 0.09])          # p2 held (zero row)
    a = _record([1.0, 2.0, 3.0, 4.0], c, id_=1)
    b = _record([1.0, 2.0 + 8 * np.sqrt(0.08), 3.0, 4.0], c, id_=2)
    res = compare(a, b, alpha=1e-3)
    assert res.comparable and res.held == ("p2",)
    assert [r.name for r in res.flagged] == ["p1"]
    row = res.flagged[0]
    assert row.sigma == pytest.approx(np.sqrt(0.08)) and row.z == pytest.approx(8.0)
    assert res.jointly_flagged and res.dof == 3


def test_compare_refuses_different_gauges_and_names_the_gauge_to_fix():
    a = _record([1.0, 2.0, 3.0], np.diag([0.0, 1.0, 1.0]), id_=1, gauge=["p0"])
    b = _record([1.0, 2.0, 3.0], np.diag([1.0, 0.0, 1.0]), id_=2, gauge=["p1"])
    res = compare(a, b)
    assert not res.comparable and not res.differ
    assert "different gauges" in res.reason and "--fix p0" in res.reason
    c = _record([1.5, 2.0, 3.0], np.diag([0.0, 1.0, 1.0]), id_=3, gauge=["p0"])
    res = compare(a, c)
    assert not res.comparable and "p0" in res.reason and "different values" in res.reason


def test_fleet_statistic_is_student_t():
    """Units drawn from one normal distribution: each unit's leave-one-out t follows t_{n−2}
    (rate of |t| beyond its 10 % quantile, 100000 fleets: 5 binomial σ = 0.005; without the
    prediction factor √(1 + 1/(n−1)) the rate would be 0.123)."""
    rng = np.random.default_rng(6)
    n_units, trials, a1 = 6, 100000, 0.1
    t = leave_one_out_t(rng.normal(size=(trials, n_units, 1)))[:, 0, 0]
    rate = np.mean(np.abs(t) > st.t.isf(a1 / 2, n_units - 2))
    assert abs(rate - a1) < _rate_band(a1, trials)
    x = rng.normal(size=(n_units, 2))                # against the textbook formula, unit by unit
    for u in range(n_units):
        o = np.delete(x, u, axis=0)
        want = (x[u] - o.mean(0)) / (o.std(0, ddof=1) * np.sqrt(1 + 1 / (n_units - 1)))
        assert np.allclose(leave_one_out_t(x)[u], want, rtol=1e-12)


def test_the_fleet_false_alarm_rate_is_at_most_alpha():
    """P(any alarm in a fleet without an outlier) ≤ α (Bonferroni over units and parameters),
    through fleet() itself (σ of the calibrations below the fleet's spread, as in a real fleet)."""
    rng = np.random.default_rng(8)
    n_units, m, trials, alpha = 6, 2, 600, 0.2
    cov = np.diag([0.01, 0.01])
    alarms = 0
    for _ in range(trials):
        vals = rng.normal(0.0, 1.0, size=(n_units, m)) + rng.normal(0.0, 0.1, size=(n_units, m))
        alarms += bool(fleet([_record(v, cov, serial=f"U{k}", id_=k + 1) for k, v in enumerate(vals)], alpha).flagged)
    assert alarms / trials < alpha + _rate_band(alpha, trials)


def test_fleet_flags_the_outlying_unit_and_not_the_others():
    rng = np.random.default_rng(7)
    cov = np.diag([1e-4, 1e-4, 0.0])
    vals = rng.normal(0.0, 0.1, size=(10, 3))
    vals[:, 2] = 7.0                                # held: equal everywhere
    vals[4, 1] += 2.0                               # 20 fleet sigmas
    recs = [_record(v, cov, serial=f"U{k}", id_=k + 1) for k, v in enumerate(vals)]
    rep = fleet(recs, alpha=1e-3)
    assert [(r.serial, r.name) for r in rep.flagged] == [("U4", "p1")]
    assert rep.held == ("p2",) and rep.dof == 8


def test_fleet_needs_three_comparable_units():
    cov = np.eye(2)
    rep = fleet([_record([0, 0], cov, serial="A"), _record([5, 5], cov, serial="B", id_=2)])
    assert not rep.flagged and "at least 3" in rep.note
