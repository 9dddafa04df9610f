"""Every FK-based result drops or flags a pose whose FK converged on another assembly mode
(``FKResult.same_branch`` False): simulation, verification and the fk-residual fit.

The real machine here is the prototype whose FK marks the poses with x > 5 mm as landed on
another assembly mode (a subclass overriding ``fk``), so the plumbing is checked exactly;
the flag itself is checked against determinants in ``test_fk_branch.py``. Old behaviour:
those poses were kept as measured / verified / fitted, because only ``converged`` was read."""

from __future__ import annotations

import dataclasses

import numpy as np

from pkmcal.identification.engine import identify
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.identification.verification import verify
from pkmcal.mechanisms.hexapod import Hexapod
from pkmcal.mechanisms.library import stewart_prototype, stewart_prototype_real
from pkmcal.sensors.library import builtin_setup


@dataclasses.dataclass(frozen=True, eq=False)
class MirrorBeyondX(Hexapod):
    """A hexapod whose FK reports the poses with x > 5 mm as on another assembly mode."""

    def fk(self, readings, guess=None, **kw):
        res = super().fk(readings, guess, **kw)
        return dataclasses.replace(res, same_branch=res.same_branch & ~(res.poses[:, 0] > 5.0))


def _mirror(machine) -> MirrorBeyondX:
    return MirrorBeyondX(**{f.name: getattr(machine, f.name) for f in dataclasses.fields(Hexapod)})


def _poses(n=30, seed=0):
    rng = np.random.default_rng(seed)
    home = stewart_prototype().home_pose
    return home + rng.uniform(-1, 1, (n, 6)) * np.array([15.0, 15.0, 8.0, 0.05, 0.05, 0.05])


def test_simulation_drops_other_assembly_modes_with_the_reason():
    nominal, real = stewart_prototype(), _mirror(stewart_prototype_real())
    poses = _poses()
    sim = simulate_campaign(nominal, real, builtin_setup("full-pose-paper1"), poses, rng=0,
                            ignore_limits=("leg_collision",))
    flagged = {k for k, why in sim.dropped.items() if why == "fk-other-assembly-mode"}
    assert flagged and not (flagged & set(sim.kept.tolist()))
    assert np.all(sim.real_poses[:, 0] <= 5.0)
    assert "dropped (fk-other-assembly-mode)" in sim.summary()


def test_verification_drops_other_assembly_modes_with_the_reason():
    nominal, real = stewart_prototype(), _mirror(stewart_prototype_real())
    poses = _poses(40, seed=1)
    rep = verify(stewart_prototype_real(), real, poses, nominal=nominal, ignore_limits=("leg_collision",))
    flagged = [k for k, why in rep.dropped.items() if "fk-other-assembly-mode" in why]
    assert flagged
    assert not rep.common[flagged].any()
    assert rep.to_dict()["used"] == int(rep.common.sum()) < len(poses)


def test_fk_residual_fit_drops_poses_whose_fk_changes_mode_at_the_start():
    """The fk-residual fit solves FK at the nominal machine: the flagged poses are dropped
    (named in the warnings), not fitted."""
    nominal, real = stewart_prototype(), stewart_prototype_real()
    setup = builtin_setup("indicators-prototype")
    poses = _poses(40, seed=2)
    poses[:, 0] = np.where(np.arange(40) < 3, 8.0, np.clip(poses[:, 0], -15, 4.0))  # 3 poses at x = 8 mm
    sim = simulate_campaign(nominal, real, setup, poses, rng=0, ignore_limits=("leg_collision",))
    meas = sim.measurements
    fit = identify(_mirror(nominal), setup, meas, method="fk-residual")
    dropped = set(fit.dropped.tolist())
    x_fk = nominal.fk(meas.actuators, guess=meas.commanded).poses[:, 0]
    assert dropped == set(np.flatnonzero(x_fk > 5.0).tolist()) and dropped
    assert any("could not be solved" in w for w in fit.warnings)
