"""Identifiability: rank, named null space and gauge for known-degenerate set-ups.

Analytic arguments for the null spaces checked here (hexapod, poses (p, R), joints b_i in
{F}, a_i in {P}):

* Redefining the platform frame {P} by a small rigid motion (t, ω) (a_i → a_i + t + ω×a_i,
  poses compensating) leaves every leg length unchanged: the actuators alone never see
  it. A sensor that sees the platform's full pose through a free tool transform, or a
  free target point (position sensor), absorbs all 6; indicators touching the platform's
  lower plane (paper 2) see z-translation and tilts of {P} but not the 3 in-plane
  motions t = e_x, e_y and ω = e_z: their rank is at most 42 − 3 = 39.
* Redefining the base frame {F} (b_i → b_i + t + ω×b_i) is visible unless the sensor's
  world transform is free: with ``world.*`` free, 6 more null directions
  (δb_i = t + ω×b_i, δworld = −(t, ω) at the identity world transform).
* Free indicator zero offsets absorb a common z-shift of the base joints (the readings
  move by +δz, the zeros by −δz … i.e. δb_i.z = 1, δzero_k = 1 leaves all readings).
"""

from __future__ import annotations

import numpy as np
import pytest

from pkmcal.errors import PkmcalError
from pkmcal.identification.identifiability import analyse_jacobian, format_direction, identifiability
from pkmcal.mechanisms import builtin_machine
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.full_pose import FullPoseSensor
from pkmcal.sensors.indicators import IndicatorSensor
from pkmcal.sensors.position import PositionSensor

HALF = np.array([20.0, 20.0, 10.0, *np.deg2rad([8.0, 8.0, 8.0])])
NOISE_FULL = NoiseModel(reading_std=np.array([0.01] * 3 + [1e-4] * 3), actuator_std=np.full(6, 0.005))
NOISE_3 = NoiseModel(reading_std=np.full(3, 0.01), actuator_std=np.full(6, 0.005))
INDICATOR_XY = np.array([[40.0, 0.0], [-20.0, 34.64], [-20.0, -34.64]])


@pytest.fixture(scope="module")
def machine():
    return builtin_machine("stewart-prototype")


@pytest.fixture(scope="module")
def poses(machine):
    rng = np.random.default_rng(0)
    return machine.home_pose + rng.uniform(-1.0, 1.0, (60, 6)) * HALF


def frame_motion(points, which, names, extra=None):
    """Parameter-space vectors (one per rigid motion t = e_x, e_y, e_z, ω = e_x, e_y, e_z)
    moving the joints ``which`` ('b' or 'a') of all legs."""
    out = []
    for k in range(6):
        v = dict.fromkeys(names, 0.0)
        for i, pt in enumerate(points):
            d = np.eye(3)[k] if k < 3 else np.cross(np.eye(3)[k - 3], pt)
            for c, axis in enumerate("xyz"):
                v[f"{which}{i + 1}.{axis}"] = d[c]
        if extra:
            for name, coef in extra(k).items():
                v[name] = coef
        out.append(np.array([v[n] for n in names]))
    return np.array(out).T


def in_span(vectors, report):
    """Largest relative residual of ``vectors`` (P, k) projected onto the report's null space."""
    N = np.array([[d.get(n, 0.0) for n in report.names] for d in report.null_space]).T
    Q, _ = np.linalg.qr(N)
    res = vectors - Q @ (Q.T @ vectors)
    return np.max(np.linalg.norm(res, axis=0) / np.linalg.norm(vectors, axis=0))


def test_indicators_rank_39_platform_in_plane_gauge(machine, poses):
    setup = MeasurementSetup(IndicatorSensor(positions=INDICATOR_XY, plane_offset=10.0), NOISE_3)
    rep = identifiability(machine, setup, poses)
    assert rep.n_params == 42 and rep.rank == 39
    assert len(rep.null_space) == 3 and len(rep.fixed) == 3
    # the 3 in-plane motions of {P} (t = e_x, e_y; ω = e_z) span the null space
    motions = frame_motion(machine.platform, "a", rep.names)[:, [0, 1, 5]]
    assert in_span(motions, rep) < 1e-6
    # ... and the out-of-plane ones are seen
    seen = frame_motion(machine.platform, "a", rep.names)[:, [2, 3, 4]]
    assert in_span(seen, rep) > 0.5
    # the gauge is taken from the frame-defining joints of legs 1, 2 (paper 2 §2.2)
    assert set(rep.fixed) <= {f"{j}{i}.{c}" for j in "ab" for i in (1, 2) for c in "xyz"}
    # directions are normalised on their gauge parameter
    for g, d in zip(rep.fixed, rep.null_space):
        assert d[g] == 1.0 and all(d.get(o, 0.0) == 0.0 for o in rep.fixed if o != g)


def test_indicators_with_free_zeros_add_the_base_height(machine, poses):
    setup = MeasurementSetup(IndicatorSensor(positions=INDICATOR_XY, plane_offset=10.0,
                                             free=("zero1", "zero2", "zero3")), NOISE_3)
    rep = identifiability(machine, setup, poses)
    assert rep.n_params == 45 and rep.rank == 41
    v = np.array([1.0 if (n.startswith("b") and n.endswith(".z")) or n.startswith("zero") else 0.0 for n in rep.names])
    assert in_span(v[:, None], rep) < 1e-6


def test_full_pose_identity_transforms_full_rank(machine, poses):
    rep = identifiability(machine, MeasurementSetup(FullPoseSensor(), NOISE_FULL), poses[:15])
    assert rep.rank == 42 and rep.identifiable and rep.null_space == [] and rep.fixed == ()


def test_full_pose_unknown_world_has_6_named_gauge_directions(machine, poses):
    setup = MeasurementSetup(FullPoseSensor(), NOISE_FULL)
    world = [f"world.{c}" for c in "xyzabc"]
    rep = identifiability(machine, setup, poses[:15], free=["b*", "a*", "L0_*", *world])
    assert rep.n_params == 48 and rep.rank == 42 and len(rep.null_space) == 6

    def compensate(k):
        return {world[k]: -1.0}

    motions = frame_motion(machine.base, "b", rep.names, compensate)
    assert in_span(motions, rep) < 1e-6
    assert all(f.startswith("b") for f in rep.fixed)
    # every named direction mentions the world transform
    assert all(any(n.startswith("world.") for n in d) for d in rep.null_space)
    # with the tool transform free too: 12 (base + platform frame)
    rep12 = identifiability(machine, setup, poses[:15], free=["b*", "a*", "L0_*", "world.*", "tool.*"])
    assert rep12.n_params == 54 and rep12.rank == 42 and len(rep12.null_space) == 12
    # and the leg gains freed as well: the readings' scale is seen (the pose is measured in
    # mm), so the same 12 frame directions and nothing more
    rep18 = identifiability(machine, setup, poses[:15], free=["*"])
    assert rep18.n_params == 60 and rep18.rank == 48 and len(rep18.null_space) == 12


def test_position_sensor_target_free_platform_gauge(machine, poses):
    setup = MeasurementSetup(PositionSensor(), NOISE_3)
    rep = identifiability(machine, setup, poses)
    assert rep.n_params == 45 and rep.rank == 39

    def target(k):
        return {"target.x": float(k == 0), "target.y": float(k == 1), "target.z": float(k == 2)} if k < 3 else {}

    # moving {P} by t moves the target's coordinates in {P} by t as well; rotations rotate it,
    # which is a zero at the default target (the origin of {P})
    motions = frame_motion(machine.platform, "a", rep.names, target)
    assert in_span(motions, rep) < 1e-6


def test_too_few_poses(machine, poses):
    rep = identifiability(machine, MeasurementSetup(FullPoseSensor(), NOISE_FULL), poses[:1])
    assert rep.rank == 6 and len(rep.null_space) == 36


def test_unweighted_same_rank(machine, poses):
    setup = MeasurementSetup(IndicatorSensor(positions=INDICATOR_XY, plane_offset=10.0), NOISE_3)
    a = identifiability(machine, setup, poses, weighted=True)
    b = identifiability(machine, setup, poses, weighted=False)
    assert a.rank == b.rank == 39


def test_analyse_jacobian_known_matrix():
    """J = [c1, c2, c1 + 2 c2, 0]: rank 2, one combination, one unseen column."""
    rng = np.random.default_rng(1)
    c1, c2 = rng.normal(size=(2, 20))
    J = np.stack([c1, c2, c1 + 2 * c2, np.zeros(20)], axis=1)
    rep = analyse_jacobian(J, ("p", "q", "r", "s"), ("p", "q", "r", "s"))
    assert rep.rank == 2 and rep.unseen == ("s",)
    assert len(rep.null_space) == 2
    combo = [d for d in rep.null_space if "s" not in d][0]
    # p + 2 q − r = 0 in some scaling; check J annihilates it
    v = np.array([combo.get(n, 0.0) for n in rep.names])
    assert np.linalg.norm(J @ v) < 1e-10 * np.linalg.norm(v)
    d = rep.to_dict()
    for key in ("n_params", "rank", "singular_values", "null_space", "fixed", "weak"):
        assert key in d
    assert d["n_params"] == 4 and len(d["singular_values"]) == 4
    assert "rank 2 of 4" in rep.describe()


def test_weak_direction_reported():
    rng = np.random.default_rng(2)
    c1, c2, e = rng.normal(size=(3, 50))
    J = np.stack([c1, c2, c1 + 1e-6 * e], axis=1)
    rep = analyse_jacobian(J, ("p", "q", "r"))
    assert rep.rank == 3 and len(rep.weak) == 1
    w = rep.weak[0]
    assert w["ratio"] < 1e-4 and set(w["direction"]) == {"p", "r"}
    assert w["direction"]["p"] * w["direction"]["r"] < 0


def test_format_direction():
    assert format_direction({"b1.x": 1.0, "b2.y": -0.5, "world.x": -1.0}) == "b1.x - 0.5*b2.y - world.x"


def test_identifiability_bad_names(machine, poses):
    with pytest.raises(PkmcalError, match="no parameter matches"):
        identifiability(machine, MeasurementSetup(FullPoseSensor(), NOISE_FULL), poses, free=["q9"])
