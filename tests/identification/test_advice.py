"""What to measure next (issue 13, item 5: ``identification/advice.py``,
``pkmcal identifiability --suggest``).

Checks: the elimination of an addition's own sensor parameters against the marginal
information J_kᵀJ_k − J_kᵀS_k(S_kᵀS_k)⁻¹S_kᵀJ_k written out; the scores against an SVD of
the stacked, scaled, gauge-projected Jacobian computed here; a delta under a Z probe: the
printed distances and a tracker identify the arm/radius scale, more probe points do not
(they are heights, taken on the bed: ``Sensor.measured_frames``); a hexapod with dial
indicators: a full-pose sensor raises the rank to full; the CLI prints the ranking and
its JSON key, and nothing of it without ``--suggest``.
"""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.identification.advice import _eliminated, _score, advise
from pkmcal.io.machine_file import load_machine
from pkmcal.mechanisms.frame import Frame
from pkmcal.sensors.library import builtin_setup
from pkmcal.sensors.z_probe import ZProbeSensor

SCALE = "a common scale of the arm lengths and the radius"


def _disc(n, radius, seed):
    rng = np.random.default_rng(seed)
    r = radius * np.sqrt(rng.uniform(size=n))
    t = rng.uniform(0, 2 * np.pi, n)
    return np.c_[r * np.cos(t), r * np.sin(t), np.zeros(n)]


def test_elimination_is_the_marginal_information():
    rng = np.random.default_rng(2)
    J, S = rng.standard_normal((30, 5)), rng.standard_normal((30, 3))
    E = _eliminated(J, S)
    info = J.T @ J - J.T @ S @ np.linalg.solve(S.T @ S, S.T @ J)
    np.testing.assert_allclose(E.T @ E, info, rtol=0, atol=1e-12 * np.abs(info).max())
    np.testing.assert_array_equal(_eliminated(J, S[:, :0]), J)


def test_score_is_the_svd_off_the_gauge():
    rng = np.random.default_rng(3)
    E = rng.standard_normal((20, 4)) @ np.diag([1.0, 2.0, 1e-3, 0.0])        # one direction unseen
    D = np.ones(4)
    U = np.eye(4)[:, :3]
    rank, smin, sr = _score(E, D, U)
    s = np.linalg.svd(E[:, :3], compute_uv=False)
    assert rank == 3 and smin == s[-1] and sr == s[-1]
    rank, smin, sr = _score(E, D, np.eye(4))
    assert rank == 3 and smin == 0.0 and abs(sr - s[-1]) < 1e-12


def test_a_probe_reads_where_it_triggers():
    rng = np.random.default_rng(4)
    s = ZProbeSensor(probe_offset=[3.0, -2.0, 1.5], bed=[0.4, 0.01, -0.02])
    f = Frame(p=rng.uniform(-50, 50, (8, 3)), R=np.broadcast_to(np.eye(3), (8, 3, 3)).copy())
    low = s.measured_frames(f)
    np.testing.assert_allclose(s.predict(low), 0.0, atol=1e-12)
    np.testing.assert_array_equal(low.p[:, :2], f.p[:, :2])


def test_delta_under_a_probe_is_told_to_print_the_object():
    m = load_machine("kossel-mini")
    adv = advise(m, builtin_setup("z-probe-klipper", m), _disc(37, 80, 7))
    assert adv.current.rank == adv.current.n_seen - 1 == 15          # the turn of the towers unseen by heights
    verdict = {o.kind if o.kind != "setup" else o.label.split()[1]: o for o in adv.options}
    scale = {k: next(e["status"] for e in o.named if e["meaning"] == SCALE) for k, o in verdict.items()}
    assert next(e["status"] for e in adv.current.named) == "not determined"
    assert scale["printed-distance"] == "identified" and scale["laser-tracker"] == "identified"
    assert scale["poses"] == "not determined"
    kinds = [o.kind for o in adv.options]
    assert adv.options[0].label.startswith("+ laser-tracker") and adv.options[0].rank == 16
    assert kinds.index("printed-distance") < kinds.index("poses")
    assert len(adv.gauge) == 2                                      # the sideways slide of the towers
    assert all(o.gain >= 1.0 for o in adv.options if o.rank == adv.current.rank)


def test_hexapod_with_indicators_is_told_to_add_a_full_pose_sensor():
    from pkmcal.planning.plan import plan_poses

    m = load_machine("stewart-prototype")
    s = builtin_setup("indicators-prototype", m)
    x = plan_poses(m, s, 20, algorithm="random", seed=3, n_candidates=300).poses
    adv = advise(m, s, x)
    assert adv.current.rank < adv.current.n_seen == 42
    assert adv.options[0].label.startswith("+ full-pose-paper1") and adv.options[0].rank == 42
    assert adv.options[0].sigma_min > 0 and adv.current.sigma_min == 0.0
    # a Z probe reads a bed at z = 0 the hexapod's platform cannot be lowered to: not offered
    assert not any("z-probe" in o.label for o in adv.options)
    assert any(n.startswith("z-probe-klipper: not scored (the machine cannot reach") for n in adv.notes)


def test_cli_prints_the_ranking_only_when_asked(tmp_path):
    poses = tmp_path / "P.csv"
    poses.write_text("x,y,z\n" + "\n".join(f"{float(x)!r},{float(y)!r},0.0" for x, y, _ in _disc(30, 80, 5)) + "\n")
    args = ["identifiability", "kossel-mini", "--setup", "z-probe-klipper", "--poses", str(poses)]
    plain = CliRunner().invoke(cli, args)
    res = CliRunner().invoke(cli, args + ["--suggest"])
    assert plain.exit_code == 0 and res.exit_code == 0, res.output
    assert "what to measure next" not in plain.output and res.output.startswith(plain.output)
    assert "+ printed distances" in res.output
    js = json.loads(CliRunner().invoke(cli, args + ["--suggest", "--json"]).output)
    assert js["suggestions"]["options"][0]["rank"] == js["suggestions"]["options"][0]["of"]
    assert "suggestions" not in json.loads(CliRunner().invoke(cli, args + ["--json"]).output)
