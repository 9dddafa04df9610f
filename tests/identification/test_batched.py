"""identification.batched: the trial-batched weighted ik-residual fit against the engine's
MINPACK fit of the same data (parameters, χ², covariance, rank, condition), its
independence of the batch it is solved in, and the fits it leaves to the engine."""

from __future__ import annotations

import numpy as np
import pytest

from pkmcal.errors import PkmcalError
from pkmcal.identification.batched import batch_applies, identify_batch
from pkmcal.identification.engine import TOLERANCE, identify
from pkmcal.identification.residuals import Model, make_method, whitening
from pkmcal.identification.simulation import parameter_errors, simulate_campaign
from pkmcal.io.setup_file import builtin_setup
from pkmcal.mechanisms import builtin_machine
from pkmcal.planning.candidates import generate_candidates


def _campaigns(machine_name: str, size: float, n_fits: int, n_poses: int, seed: int, ignore=()):
    """``n_fits`` simulated campaigns of real machines nominal + U(−size, size) on every
    parameter the fit estimates, each at its own random poses (some of them dropped by
    the real machine's limits, so the fits differ in size)."""
    nominal = builtin_machine(machine_name)
    setup = builtin_setup("full-pose-paper1")
    rng = np.random.default_rng(seed)
    out = []
    est = np.array([i for i, n in enumerate(nominal.param_names) if not n.startswith("g")])
    for _ in range(n_fits):
        delta = np.zeros(len(nominal.params))
        delta[est] = parameter_errors(est.size, size, rng, "uniform")
        real = nominal.with_params(nominal.params + delta)
        poses = generate_candidates(nominal, None, kind="random", n=n_poses, rng=rng).poses
        out.append(simulate_campaign(nominal, real, setup, poses, rng, ignore_limits=ignore).measurements)
    return nominal, setup, out


@pytest.fixture(scope="module")
def paper1():
    return _campaigns("stewart-prototype", 0.5, 10, 15, 7, ignore=("leg_collision",))


def _distance_bound(nominal, setup, meas, ref):
    """‖J̃ (θ_a − θ_b)‖ allowed between two solutions that both met MINPACK's stopping
    tests: the cost ½‖r̃‖² is known to ftol relative (‖J̃ Δθ‖ ≤ √(2 ftol f)), a step to
    xtol relative to ‖D x‖ (‖J̃ Δθ‖ ≤ ‖J̃ D⁻¹‖ xtol ‖D x‖ ≤ √n xtol ‖D x‖, D the column
    norms): their sum, with the whitened Jacobian and weights of the engine's objective."""
    model = Model(nominal, setup.sensor, setup.noise, meas.actuators, meas.readings, meas.commanded)
    meth = make_method("ik-residual", model, True)
    W = whitening(meth.evaluate(model.theta0, jac=True, cov=True).cov)
    fi = ref.free_index
    ev = meth.evaluate(ref.estimate, jac=True, cov=False)
    rw = (W @ ev.r[..., None])[..., 0].ravel()
    J = (W @ ev.J[:, :, fi]).reshape(-1, fi.size)
    D = np.linalg.norm(J, axis=0)
    bound = np.sqrt(2 * TOLERANCE * 0.5 * rw @ rw) + np.sqrt(fi.size) * TOLERANCE * np.linalg.norm(D * ref.estimate[fi])
    return J, bound


@pytest.mark.parametrize("which", ["paper1", "machine-tool"])
def test_batched_fits_are_the_engines(paper1, which):
    if which == "paper1":
        nominal, setup, meas = paper1
    else:
        from pkmcal.reproduce.paper1 import machine_tool_hexapod

        nominal = machine_tool_hexapod()
        setup = builtin_setup("full-pose-paper1")
        rng = np.random.default_rng(11)
        meas = []
        for _ in range(6):
            real = nominal.with_params(nominal.params + np.r_[rng.uniform(-5, 5, 42), np.zeros(len(nominal.params) - 42)])
            poses = generate_candidates(nominal, None, kind="random", n=15, rng=rng).poses
            meas.append(simulate_campaign(nominal, real, setup, poses, rng).measurements)
    fits = identify_batch(nominal, setup, meas)
    assert all(f is not None for f in fits)
    for f, m in zip(fits, meas):
        ref = identify(nominal, setup, m)
        assert f.free == ref.free and f.names == ref.names and f.gauge == ref.gauge == ()
        np.testing.assert_array_equal(f.initial, ref.initial)
        J, bound = _distance_bound(nominal, setup, m, ref)
        fi = ref.free_index
        assert np.linalg.norm(J @ (f.estimate - ref.estimate)[fi]) <= bound
        np.testing.assert_array_equal(np.delete(f.estimate, fi), np.delete(ref.estimate, fi))
        # χ² and the covariance move with θ̂ at first order, by Δθ / (machine size) ≪ 1e-6
        assert abs(f.uncertainty.chi2 - ref.uncertainty.chi2) <= 1e-6 * ref.uncertainty.chi2
        assert f.uncertainty.dof == ref.uncertainty.dof
        np.testing.assert_allclose(f.covariance, ref.covariance, rtol=0, atol=1e-6 * np.abs(ref.covariance).max())
        rep = ref.identifiability
        assert f.identifiability.rank == rep.rank == rep.n_params == f.identifiability.n_params
        # singular values alone against those of the full SVD: rounding of the same matrix
        assert f.identifiability.condition_number == pytest.approx(rep.condition_number, rel=1e-12)
        np.testing.assert_array_equal(f.mechanism.params, f.estimate[:len(nominal.params)])


def test_a_fit_does_not_depend_on_its_batch(paper1):
    nominal, setup, meas = paper1
    together = identify_batch(nominal, setup, meas)
    alone = [identify_batch(nominal, setup, [m])[0] for m in meas[:4]]
    split = identify_batch(nominal, setup, meas[5:]) + identify_batch(nominal, setup, meas[3:5])
    reordered = identify_batch(nominal, setup, meas[::-1])[::-1]
    for a, b in zip(together, alone + [None]):
        if b is not None:
            np.testing.assert_array_equal(a.estimate, b.estimate)
            np.testing.assert_array_equal(a.covariance, b.covariance)
            assert a.nfev == b.nfev and a.identifiability == b.identifiability
    for a, b in zip(together[5:] + together[3:5], split):
        np.testing.assert_array_equal(a.estimate, b.estimate)
    for a, b in zip(together, reordered):
        np.testing.assert_array_equal(a.estimate, b.estimate)
        assert a.uncertainty.chi2 == b.uncertainty.chi2


def test_fits_left_to_the_engine(paper1):
    nominal, setup, meas = paper1
    assert batch_applies(setup, "ik-residual", True)
    assert not batch_applies(setup, "ik-residual", False)
    assert not batch_applies(setup, "fk-residual", True)
    assert not batch_applies(setup, "ik-residual", True, form="squared")
    import dataclasses

    from pkmcal.identification.priors import Prior

    with_prior = dataclasses.replace(setup, priors=(Prior("b1_x", 0.0, 1.0),))
    assert not batch_applies(with_prior, "ik-residual", True)
    # a free sensor parameter moves the measured poses: not the batch's fit
    assert identify_batch(nominal, setup, meas[:2], free=("b1_x", setup.sensor.param_names[0])) == [None, None]
    # too few poses for the free set (rank not proven): the engine fixes a gauge or refuses
    few = [type(meas[0])(actuators=m.actuators[:3], readings=m.readings[:3], commanded=m.commanded[:3],
                         source=None, sessions=None) for m in meas[:2]]
    assert identify_batch(nominal, setup, few) == [None, None]
    # a shared start the engine refuses (a sensor the ik-residual cannot use, a noise-free
    # residual): every fit to the engine, which reports it fit by fit
    indicators = builtin_setup("indicators-prototype")
    q, cmd = meas[0].actuators, meas[0].commanded
    y3 = indicators.sensor.predict(nominal.frame(cmd))
    assert identify_batch(nominal, indicators, [(q, y3, cmd)] * 2) == [None, None]
    with pytest.raises(PkmcalError, match="ik-residual"):
        identify(nominal, indicators, (q, y3, cmd), method="ik-residual")
    silent = dataclasses.replace(setup, noise=dataclasses.replace(setup.noise, reading_std=0.0 * np.asarray(
        setup.noise.reading_std), actuator_std=0.0 * np.asarray(setup.noise.actuator_std)))
    assert identify_batch(nominal, silent, meas[:2]) == [None, None]
    # an explicit free set is the engine's
    f = identify_batch(nominal, setup, meas[:1], free=("b*",))[0]
    ref = identify(nominal, setup, meas[0], free=("b*",))
    assert f.free == ref.free
    J, bound = _distance_bound(nominal, setup, meas[0], ref)
    assert np.linalg.norm(J @ (f.estimate - ref.estimate)[ref.free_index]) <= bound


# -- in a study -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def paper1_study():
    from pathlib import Path

    from pkmcal.study import load_study
    from pkmcal.study.trial import prepare

    study = load_study(Path(__file__).resolve().parents[2] / "examples" / "study-paper1.yaml").with_trials(8)
    return prepare(study)


def _rows(lines):
    import csv

    return list(csv.reader(lines))


def test_study_rows_do_not_depend_on_the_fit_batch(paper1_study, monkeypatch):
    from pkmcal.study import trial

    ctx = paper1_study
    c = ctx.campaigns[0]
    calls = []
    engine = trial.identify_by_method
    monkeypatch.setattr(trial, "identify_by_method", lambda *a, **k: calls.append(1) or engine(*a, **k))
    together = trial.run_trials(ctx, c, range(8))
    assert calls == []                     # every fit batched, no truth refit (all errors on free parameters)
    monkeypatch.setattr(trial, "FIT_BATCH", 3)
    _, _, _, lines, _ = trial.run_batch(ctx, 0, 0, 7)
    assert lines == together
    assert [line for t in range(8) for line in trial.run_trial(ctx, c, t)] == together


def test_study_rows_of_batched_and_engine_fits_agree(paper1_study, monkeypatch):
    """The same trials with every fit left to the engine: the same rows to the solvers'
    tolerances. Both stop within ftol = xtol = gtol = 1e-10 of the minimum, which along the
    weakest direction of a 15-pose fit leaves θ̂ free by up to ~3e-6 mm (measured over 64
    fits; the cost-metric bound of test_batched_fits_are_the_engines is the exact
    statement): the columns derived from θ̂ (parameter errors of ~0.5 mm, held-out errors of
    ~0.2 mm, χ² ~ 45) then agree to ~5e-7 relative, 1e-6 absolute (measured over 40
    trials), checked with 10× margin; counts and flags equal, ``nfev`` is each solver's own
    count."""
    import pkmcal.identification.batched as batched
    from pkmcal.study import trial

    ctx = paper1_study
    c = ctx.campaigns[0]
    head = list(ctx.names)
    fast = _rows(trial.run_trials(ctx, c, range(8)))
    monkeypatch.setattr(batched, "identify_batch", lambda machine, setup, meas, **kw: [None] * len(meas))
    slow = _rows(trial.run_trials(ctx, c, range(8)))
    exact = ("poses_measured", "n_free", "rank", "n_candidates", "gauge", "dof", "heldout_used", "failed",
             "all_within_95", "ellipsoid_within_95", "truth_refit", "message")
    for a, b in zip(fast, slow):
        for name, u, v in zip(head, a, b):
            if name in exact or not u or name == "nfev":
                assert u == v or name == "nfev", (name, u, v)
            elif name in ("condition",):
                assert float(u) == pytest.approx(float(v), rel=1e-12)
            elif name not in ("config", "trial", "n_poses", "weighted", "plan_resampled") and u[0] in "-.0123456789":
                assert float(u) == pytest.approx(float(v), rel=5e-6, abs=1e-5), name
            else:
                assert u == v, name


def test_a_fit_that_does_not_converge_is_left_to_the_engine(paper1, monkeypatch):
    import pkmcal.identification.batched as batched

    nominal, setup, meas = paper1
    monkeypatch.setattr(batched, "MAX_ITERATIONS", 2)       # far too few from ±0.5 mm errors
    assert identify_batch(nominal, setup, meas[:3]) == [None, None, None]
