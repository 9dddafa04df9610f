"""One simulate, one perturb, one verify for every built-in machine kind (issue 12 item 3).

For each kind (6-UPS, 6-RSS, 6-PUS, linear delta, rotary delta, both planar redundant
machines) the same three functions run: :func:`perturb_machine` draws a real machine,
:func:`simulate_campaign` measures it noise-free (FK of the commands, or, for the machines
that declare more actuators than pose coordinates, the static equilibrium of their
actuator springs), and :func:`verify` commands held-out poses through a model. Checked
against independent facts: the readings are the real machine's own IK and sensor model at
the poses it reached (and, at equilibrium, the force balance Γᵀ K (q(x) − c) = 0 holds
there); commanded through the true parameters the real machine lands where it is commanded
(errors at the FK/equilibrium tolerance), through the nominal ones it does not.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pkmcal.identification.simulation import perturb_machine, settles_at_equilibrium, simulate_campaign
from pkmcal.identification.verification import VerificationReport, verify
from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import builtin_machine
from pkmcal.mechanisms.statics import StaticsModel, force_balance
from pkmcal.planning.candidates import generate_candidates

#: built-in machine → setup of its sensor (one of each mechanism kind)
MACHINES = {
    "stewart-prototype": "full-pose-paper1",    # 6-UPS
    "servo-stewart": "full-pose-paper1",        # 6-RSS
    "hexaslide": "full-pose-paper1",            # 6-PUS
    "kossel-mini": "laser-tracker",             # linear delta
    "delta-picker": "laser-tracker",            # rotary delta
    "planar-2dof-3act": "planar-tracker",       # redundant, rotary actuators
    "planar-3dof-4act": "planar-tracker",       # redundant, linear actuators
}
ERROR_MM = 0.3


def _noise_free(setup):
    """The setup without noise and, for a machine at equilibrium, without load (a load
    deflects the machine whatever its parameters: no zero error to check against)."""
    noise = dataclasses.replace(setup.noise, reading_std=np.zeros_like(np.asarray(setup.noise.reading_std, float)),
                                actuator_std=np.zeros_like(np.asarray(setup.noise.actuator_std, float)))
    sim = setup.simulation
    return dataclasses.replace(setup, noise=noise,
                               simulation=None if sim is None else StaticsModel(sim.stiffness, None))


@pytest.fixture(scope="module", params=list(MACHINES))
def campaign(request):
    nominal = builtin_machine(request.param)
    setup = _noise_free(load_setup(MACHINES[request.param], nominal))
    real = perturb_machine(nominal, ERROR_MM, np.random.default_rng(3), name="real")
    poses = generate_candidates(nominal, setup, kind="random", n=40, rng=np.random.default_rng(1)).poses
    return nominal, real, setup, poses


def test_perturb_moves_every_length_and_angle_parameter_within_its_bound(campaign):
    nominal, real, _, _ = campaign
    d = real.params - nominal.params
    drawn = np.isin(nominal.param_units, ("mm", "deg"))
    bound = np.where(np.array(nominal.param_is_angle, dtype=bool), ERROR_MM / 1000.0, ERROR_MM)
    assert np.all(np.abs(d[drawn]) <= bound[drawn]) and np.all(d[drawn] != 0.0)
    assert np.all(d[~drawn] == 0.0)


def test_simulated_readings_are_the_real_machines_at_the_poses_it_reached(campaign):
    nominal, real, setup, poses = campaign
    sim = simulate_campaign(nominal, real, setup, poses, rng=0, ignore_limits=_ignored(real))
    assert len(sim.kept) >= 30, sim.dropped
    assert np.array_equal(sim.actuator_readings, sim.actuator_true)          # noise free
    np.testing.assert_allclose(real.ik(sim.real_poses), sim.actuator_true, atol=1e-7)
    np.testing.assert_array_equal(sim.sensor_readings, setup.sensor.predict(real.frame(sim.real_poses)))
    commands = nominal.ik(sim.commanded[sim.kept])
    if settles_at_equilibrium(nominal):
        # the real machine does not reach its commands (the actuators conflict) ...
        assert np.max(np.abs(sim.actuator_true - commands)) > 1e-4
        # ... but its springs balance where it settled (zero load): the Gauss-Newton step
        # dx = (ΓᵀKΓ)⁻¹ g that the force residual g = Γᵀ K (q(x) − c) still asks for is
        # below the equilibrium solver's stopping bound 1e-8·max(|x|, 1)
        K = setup.simulation.stiffness_for(real)
        x = sim.real_poses
        g = force_balance(real, commands, K, x)
        G = real.actuator_pose_jacobian(x)
        dx = np.linalg.solve(np.einsum("nli,l,nlj->nij", G, K, G), g[..., None])[..., 0]
        assert np.all(np.max(np.abs(dx), axis=1) <= 1e-8 * np.maximum(np.abs(x).max(axis=1), 1.0))
    else:
        np.testing.assert_array_equal(sim.actuator_true, commands)             # FK of the commands


def test_verify_is_zero_with_the_true_parameters_and_not_with_the_nominal(campaign):
    nominal, real, setup, poses = campaign
    held = poses[:12]
    report = verify(real, real, held, nominal=nominal, ignore_limits=_ignored(real), setup=setup)
    assert isinstance(report, VerificationReport)
    d = report.to_dict()
    key = "tool_max_mm" if settles_at_equilibrium(nominal) else "position_max_mm"
    assert d["after"][key] < 1e-6, d["after"]
    assert d["before"][key] > 1e-3, d["before"]
    assert report.format_table()


def _ignored(machine) -> tuple[str, ...]:
    """The perturbed prototype's legs may touch (simulate_campaign's docstring); the
    perturbed planar machines may leave the nominal workspace box by their errors."""
    limits = set(machine.check_limits(machine.home_pose[None, :]).violations)
    return tuple(n for n in ("leg_collision", "workspace") if n in limits)
