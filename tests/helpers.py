"""Helpers shared by the test modules (imported as ``from helpers import ...``; pytest puts
``tests/`` on the path): the prototype's legs as machine-file text, the CLI's user-error
contract (exit code 2, one ``pkmcal: error:`` line on stderr, no traceback, nothing
written), the hypothesis strategies of the loader fuzz tests, the one comparison of
analytic Jacobians with central finite differences that every Jacobian test uses
(:func:`assert_jacobian_matches_fd`, its tolerance derived from the step and the scale), the
bands of the Monte Carlo checks (from the sampling distributions, false failure < 1e-6 for
any seed), the environment of a pkmcal subprocess, and every command's and subcommand's
``--help`` (:func:`command_helps`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from pkmcal.io.tables import LENGTH_COLUMNS, READING_COLUMNS

#: The six legs of paper 2's prototype (Table 3) as the ``legs:`` items of a machine file (mm).
PROTOTYPE_LEGS_YAML = """\
  - {base: [-152.5, 0, 0], platform: [-60.622, 35, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [-132.068, -76.25, 0], platform: [-35, -60.622, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [76.25, -132.068, 0], platform: [0, -70, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [132.068, -76.25, 0], platform: [70, 0, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [76.25, 132.068, 0], platform: [60.622, 35, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [0, 152.5, 0], platform: [-35, 60.622, 0], offset: 305.0, stroke: [0, 50]}
"""


#: Half-widths of the random poses around home the identification tests use (mm, rad).
POSE_HALF_WIDTHS = np.array([20.0, 20.0, 10.0, *np.deg2rad([8.0, 8.0, 8.0])])


def reachable_poses(machine, n: int, seed: int) -> np.ndarray:
    """``n`` poses uniform in the machine's workspace box that pass all its limits (seeded)."""
    rng = np.random.default_rng(seed)
    box = machine.workspace_box()
    poses = box[:, 0] + rng.uniform(size=(4 * n, box.shape[0])) * (box[:, 1] - box[:, 0])
    ok = ~np.any(np.column_stack(list(machine.check_limits(poses).violations.values())), axis=1)
    assert ok.sum() >= n, f"only {ok.sum()} of {4 * n} poses in the box of '{machine.name}' pass its limits"
    return poses[ok][:n]


def random_poses(machine, n: int, seed: int = 0) -> np.ndarray:
    """``n`` poses uniform in home ± :data:`POSE_HALF_WIDTHS` (internal units)."""
    rng = np.random.default_rng(seed)
    return machine.home_pose + rng.uniform(-1.0, 1.0, (n, 6)) * POSE_HALF_WIDTHS


# -- analytic Jacobians against central finite differences ---------------------------------------
#
# Central difference of f along x_k with step h:
#
#     D_k = (f(x + h e_k) − f(x − h e_k)) / 2h = ∂f/∂x_k + h²/6 · ∂³f/∂x_k³(ξ) + (δ⁺ − δ⁻)/2h,
#
# so |D_k − ∂f/∂x_k| ≤ h²·T_k/6 + δ/h, with T_k a bound on |∂³f/∂x_k³| near x and δ the
# absolute error of one evaluation of f. The bounds used:
#
# * T_k = 2·G_k/ℓ_k²: Cauchy's estimate for the analytic function ∂f/∂x_k, whose size stays
#   below the slope G_k within distance ℓ_k of x_k (its second derivative is ≤ 2!·G_k/ℓ_k²).
#   ℓ_k is the problem's length scale for x_k: for a hexapod's leg length against a coordinate
#   in mm, ℓ = the leg length and G = 1 (exactly, |d³‖v + t e‖/dt³| ≤ (2/√3)/‖v‖²); against
#   an angle, ℓ = 1 rad and G = the lever r (|d³/dt³| ≤ r·(1 + 3r/L + 1.16 r²/L²) ≈ 2r for
#   r/L ≤ 0.3); near a singularity (gimbal lock, a plane turning vertical, the edge of
#   reach) ℓ is the distance to it.
# * δ = FD_ROUNDINGS·ε·M: that many roundings of relative size ε on the largest value M the
#   computation handles (default: the largest |f|); an iterative solver inside f (FK) gives δ
#   from its stopping tolerance instead.
# * h_k minimises the bound: h_k = (3δ/T_k)^(1/3) (≈ ε^(1/3)·ℓ_k when M ≈ G_k·ℓ_k), at most
#   ℓ_k/10; the bound is then 1.3·G_k·(δ/(G_k ℓ_k))^(2/3), ≈ 4e-11·G_k for M ≈ G_k·ℓ_k.
#
# The tolerance is FD_SAFETY times that bound, plus the analytic Jacobian's own round-off. The
# check has teeth, and checks it: the tolerance of every non-zero column must be below
# ``resolution`` (default 1e-5) of the column's size, so a sign flip or a 1e-5 relative error
# of a column is caught (test_fd_check_has_teeth) — except for columns so small that no
# difference quotient resolves them relatively: below 1e-4·M/ℓ_k (f changes by less than
# 1e-4 of its values over ℓ_k along x_k) or below 1 % of their slope bound G_k (a component of
# a gradient that nearly vanishes at x), which are resolved to ``resolution`` of that size.

EPS = float(np.finfo(float).eps)
#: Factor between the error bound above (constants of typical, not worst-case size) and the
#: tolerance.
FD_SAFETY = 10.0
#: Roundings of relative size ε in one evaluation of f (a few dozen flops per value).
FD_ROUNDINGS = 32


def fd_step(third, noise, scale):
    """The step minimising h²·T/6 + δ/h, h = (3δ/T)^(1/3), at most ℓ/10 (T = 0: ℓ/10)."""
    third, scale = np.asarray(third, dtype=float), np.asarray(scale, dtype=float)
    with np.errstate(divide="ignore", over="ignore"):
        h = np.cbrt(3.0 * noise / third)
    return np.minimum(h, 0.1 * scale)


def central_difference(f, x, k: int, h, diff=None) -> np.ndarray:
    """(f(x + h e_k) − f(x − h e_k)) / (x⁺_k − x⁻_k): column k of the central-difference Jacobian.

    ``x`` is (..., n); ``h`` a scalar or an array of the shape of ``x[..., k]``. The divisor is
    the step actually taken after rounding x ± h. ``diff(a, b)`` replaces a − b (e.g. to wrap
    angle readings)."""
    xp = np.array(x, dtype=float)
    xm = xp.copy()
    xp[..., k] += h
    xm[..., k] -= h
    fp, fm = np.asarray(f(xp), dtype=float), np.asarray(f(xm), dtype=float)
    d = fp - fm if diff is None else diff(fp, fm)
    step = xp[..., k] - xm[..., k]
    return d / np.reshape(step, np.shape(step) + (1,) * (d.ndim - np.ndim(step)))


def fd_tolerance(h, third, noise, safety: float = FD_SAFETY):
    """safety·(h²·T/6 + δ/h): the bound on |central difference − derivative| (see above)."""
    h = np.asarray(h, dtype=float)
    return safety * (h**2 * np.asarray(third, dtype=float) / 6.0 + np.asarray(noise, dtype=float) / h)


def assert_jacobian_matches_fd(f, x, J, *, scale, slope=None, magnitude=None, noise=None, h=None, diff=None,
                               safety: float = FD_SAFETY, resolution: float = 1e-5, names=None, err_msg=""):
    """Assert that ``J`` (f(x).shape + (n,)) is the Jacobian of ``f`` at ``x`` (..., n).

    f maps x to an array; when x holds one row per pose, f must map each row independently
    (the step of column k moves every row at once). The error model is described above.

    Parameters
    ----------
    scale : ℓ_k, the length scale of each variable, (n,) or scalar (mm: a leg length; rad: 1).
    slope : G_k, a bound on |∂f/∂x_k|, (n,) or scalar; default the largest |J[..., k]|.
    magnitude : M, the largest value the computation of f handles; default the largest |f(x)|.
    noise : δ, the absolute error of one evaluation of f, scalar or (n,) (when a column's
        step reaches a solver that others do not); default FD_ROUNDINGS·ε·M.
    h : steps, scalar or (n,) (default :func:`fd_step`).
    resolution : the relative error of a column that must not go unnoticed (checked), scalar
        or (n,).
    names : column names for the messages.

    Returns (finite differences, tolerance), the tolerance broadcastable to J's shape.
    """
    x = np.asarray(x, dtype=float)
    J = np.asarray(J, dtype=float)
    n = x.shape[-1]
    ell = np.broadcast_to(np.asarray(scale, dtype=float), (n,))
    col_size = np.max(np.abs(J).reshape(-1, n), axis=0, initial=0.0)
    G = col_size if slope is None else np.broadcast_to(np.asarray(slope, dtype=float), (n,))
    third = 2.0 * G / ell**2
    f0 = np.asarray(f(x), dtype=float)
    M = np.max(np.abs(f0), initial=0.0) if magnitude is None else float(magnitude)
    noise = FD_ROUNDINGS * EPS * M if noise is None else np.broadcast_to(np.asarray(noise, dtype=float), (n,))
    h = fd_step(third, noise, ell) if h is None else np.broadcast_to(np.asarray(h, dtype=float), (n,))
    fd = np.stack([central_difference(f, x, k, h[k], diff) for k in range(n)], axis=-1)
    assert fd.shape == J.shape, f"Jacobian shape {J.shape}, finite differences {fd.shape}"
    tol = fd_tolerance(h, third, noise, safety) + FD_ROUNDINGS * EPS * np.max(np.abs(J), initial=0.0)
    err = np.abs(J - fd)
    names = list(names) if names is not None else [f"column {k}" for k in range(n)]
    where = f"{err_msg}: " if err_msg else ""
    bad = ~(err <= tol)  # NaN counts as a failure
    if bad.any():
        ratio = np.where(np.isfinite(err), err / np.broadcast_to(tol, J.shape), np.inf)
        idx = np.unravel_index(np.argmax(np.where(bad, ratio, -1.0)), J.shape)
        raise AssertionError(
            f"{where}analytic Jacobian differs from central differences at {bad.sum()} of {bad.size} entries; "
            f"worst {names[idx[-1]]} at index {idx}: analytic {J[idx]:.9g}, finite differences {fd[idx]:.9g}, "
            f"|difference| {err[idx]:.3g} > tolerance {tol[idx[-1]]:.3g} (step {h[idx[-1]]:.3g})")
    reference = np.maximum(col_size, np.maximum(1e-2 * G, 1e-4 * M / ell))
    blunt = (col_size > 0.0) & ~(tol <= resolution * reference)
    assert not blunt.any(), (
        f"{where}the finite-difference check cannot resolve a relative error of {resolution:g} in "
        f"{[names[k] for k in np.flatnonzero(blunt)]} (tolerance / column size {(tol / reference)[blunt]})")
    return fd, tol


def planar_fd_model(m, x):
    """Error-model scales of a planar machine's IK at poses x (see the comment above
    :func:`assert_jacobian_matches_fd`): ``(pose, params)``, each ``dict(scale=ℓ, slope=G)``.

    IK is analytic until a chain reaches a singularity — case 1: ‖C_i − B_i‖ = l_i1 ± l_i2
    (arccos of ±1), case 2: |b_ij| = ρ_ij (√0) — at distance d (≥ 73 mm and ≥ 19 mm in the
    workspace boxes). A length moves ‖C − B‖ or b at most 1:1, an angle by at most the lever r
    (case 1: none, the encoder offsets enter linearly; case 2: ‖w‖ and L3/2): ℓ = d/2 for mm,
    d/(2r) for rad. Slopes from the gradient norms (for every mm parameter of chain i):
    case 1 ‖∂θ_i/∂(B, C)‖ = ‖g‖/|s| and ∂θ_i/∂l_i2 = l_i2/|s| with ‖g‖ = l_i2; case 2
    ‖∂s/∂C‖ = ∂s/∂ρ = ρ/√(ρ² − b²); an angle multiplies by r. They grow like 1/√distance, so
    by √2 within ℓ = d/2 of x: G = √2 × the largest at x."""
    if m.n_dof == 2:
        w, _, _, s, _ = m._chains(x)
        l1, l2, *_ = m._unpack()
        reach = np.linalg.norm(w, axis=2)
        d = np.min(np.minimum(l1 + l2 - reach, reach - np.abs(l1 - l2)))
        lever = 1.0
        slope = np.sqrt(2.0) * np.max(l2 / np.abs(s))
    else:
        _, _, _, _, a, b, root, _ = m._geometry(x)
        L3, _, _, rho, _ = m._unpack()
        d = np.min(rho - np.abs(b))
        lever = max(np.max(np.hypot(a, b)), 0.5 * L3)
        slope = np.sqrt(2.0) * np.max(rho / root)
    assert d > 0.0

    def model(is_angle):
        ang = np.asarray(is_angle, dtype=bool)
        return dict(scale=np.where(ang, 0.5 * d / lever, 0.5 * d), slope=np.where(ang, lever * slope, slope))

    return model(m.pose_is_angle), model(m.param_is_angle)


# -- Monte Carlo bands ----------------------------------------------------------------------------

#: Family-wise probability that a Monte Carlo check of the suite fails although the code is
#: right (any seed): each check splits it over the quantities it tests (Bonferroni).
FALSE_FAILURE = 1e-6


def mc_std_ratio_band(n_trials: int, n_quantities: int) -> tuple[float, float]:
    """[lo, hi] holding s/σ for every one of ``n_quantities`` sample standard deviations of
    ``n_trials`` Gaussian draws but with probability FALSE_FAILURE: (s/σ)² ~ χ²_ν/ν, ν = n − 1."""
    from scipy.stats import chi2

    a = FALSE_FAILURE / (2 * n_quantities)
    nu = n_trials - 1
    lo, hi = np.sqrt(chi2.ppf([a, 1.0 - a], nu) / nu)
    return float(lo), float(hi)


def assert_covariance_matches_monte_carlo(estimates, truth, cov) -> float:
    """The reported covariance ``cov`` (P, P) of Gaussian estimates against ``estimates``
    (n, P) of independent trials around ``truth``, jointly: the squared Mahalanobis distances
    d² = (θ̂ − θ)ᵀ C⁻¹ (θ̂ − θ) are χ²_P each, so n·P·mean(d²/P) ~ χ²_{nP}; the mean stays in
    the band but with probability FALSE_FAILURE (n = 200, P = 42: within [0.926, 1.077], i.e.
    the covariance right to ~4 % in σ, correlations and bias included). Returns the mean."""
    from scipy.stats import chi2

    d = np.asarray(estimates, dtype=float) - truth
    L = np.linalg.cholesky(cov)
    z = np.linalg.solve(L, d.T)
    n, P = d.shape
    mean = float(np.sum(z**2) / (n * P))
    lo, hi = chi2.ppf([FALSE_FAILURE / 2, 1.0 - FALSE_FAILURE / 2], n * P) / (n * P)
    assert lo < mean < hi, f"mean squared Mahalanobis distance per parameter {mean:.4f} outside [{lo:.4f}, {hi:.4f}]"
    return mean


def mc_mean_bound(n_trials: int, n_quantities: int) -> float:
    """|mean − truth| / (s/√n) stays below this for all ``n_quantities`` sample means of
    ``n_trials`` Gaussian draws but with probability FALSE_FAILURE (Student t, n − 1 dof)."""
    from scipy.stats import t

    return float(t.isf(FALSE_FAILURE / (2 * n_quantities), n_trials - 1))


# -- subprocesses ---------------------------------------------------------------------------------

def pkmcal_subprocess_env() -> dict:
    """The environment for a ``python -m pkmcal...`` child that runs the pkmcal under test:
    the folder this process imported it from first on PYTHONPATH (a relative PYTHONPATH, or an
    editable install of another tree, would otherwise give the child another pkmcal)."""
    import os

    import pkmcal

    root = str(Path(pkmcal.__file__).resolve().parent.parent)
    rest = os.environ.get("PYTHONPATH", "")
    return {**os.environ, "PYTHONPATH": root + (os.pathsep + rest if rest else "")}


# -- the CLI's user-error contract ---------------------------------------------------------------

def assert_user_error(result, *fragments) -> None:
    """``result`` (click's CliRunner) is a user error: exit code 2, one stderr line starting
    ``pkmcal: error: `` that contains every one of ``fragments``, no traceback."""
    assert result.exit_code == 2, result.output
    err = result.stderr.strip()
    assert err.startswith("pkmcal: error: ") and "\n" not in err, err
    assert "Traceback" not in result.output
    for f in fragments:
        assert f in err, err


def assert_ok_or_user_error(result, out=None) -> None:
    """Exit code 0, or a user error (:func:`assert_user_error`) that wrote no ``out`` file;
    never another exception."""
    assert result.exit_code in (0, 2), result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    if result.exit_code == 2:
        assert_user_error(result)
        assert out is None or not out.exists()


# -- study files ---------------------------------------------------------------------------------

#: A kossel-mini's assembly errors as the ``errors:`` items of a study machine (mm, degrees).
DELTA_ERRORS_YAML = """\
      - {parameters: "radius_*", distribution: normal, size: 0.3}
      - {parameters: "angle_*", distribution: normal, size: 0.2}
      - {parameters: "arm_*", distribution: normal, size: 0.2}
      - {parameters: "endstop_*", distribution: normal, size: 0.3}
"""


def write_study(tmp_path, text: str, name: str = "study.yaml") -> Path:
    """The study file ``name`` in ``tmp_path`` holding ``text`` (dedented)."""
    import textwrap

    p = tmp_path / name
    p.write_text(textwrap.dedent(text), encoding="utf-8")
    return p


# -- a study trial against the commands -----------------------------------------------------------

def trial_through_commands(tmp_path, study, method_index: int, identify_args: list, verify_args: list):
    """Trial 1 of campaign 0 (its ``method_index``-th method) as the study computes it, and as
    the commands compute it from the same data through files: ``(row, identify --json,
    verify --json)``. The measurements (pose pairs for a printed-distance setup, as ``pkmcal
    import klipper-analyze`` writes them), the real machine and the held-out poses are
    written as a user would have them; ``pkmcal identify MACHINE MEAS.csv *identify_args``
    then ``pkmcal verify CAL.yaml --real REAL.yaml --nominal MACHINE --poses HELD.csv
    *verify_args``."""
    import csv
    import json

    from click.testing import CliRunner

    from pkmcal.cli.main import cli
    from pkmcal.io.machine_file import machine_to_text
    from pkmcal.io.measurements import save_measurements
    from pkmcal.io.tables import to_file_units, write_table
    from pkmcal.mechanisms.pose_pairs import read_by
    from pkmcal.study.trial import _measure, prepare, run_trial

    ctx = prepare(study)
    campaign = ctx.campaigns[0]
    nominal, setup = study.machines[0].nominal, ctx.setup(campaign)
    measured = _measure(ctx, campaign, 1)
    row = dict(zip(ctx.names, list(csv.reader(run_trial(ctx, campaign, 1)))[method_index]))
    save_measurements(tmp_path / "meas.csv", measured.sim.measurements, read_by(nominal, setup.sensor), setup)
    (tmp_path / "real.yaml").write_text(machine_to_text(measured.real), encoding="utf-8")
    held = ctx.heldout[0]
    write_table(tmp_path / "held.csv", dict(zip(nominal.pose_names, to_file_units(held, nominal.pose_is_angle).T)))
    runner = CliRunner()
    r = runner.invoke(cli, ["identify", nominal.name, str(tmp_path / "meas.csv"), *identify_args,
                            "-o", str(tmp_path / "cal.yaml"), "--json"])
    assert r.exit_code == 0, r.output
    fit = json.loads(r.stdout)
    r = runner.invoke(cli, ["verify", str(tmp_path / "cal.yaml"), "--real", str(tmp_path / "real.yaml"), "--nominal",
                            nominal.name, "--poses", str(tmp_path / "held.csv"), *verify_args, "--json"])
    assert r.exit_code == 0, r.output
    return row, fit, json.loads(r.stdout)


# -- fuzzing the loaders -------------------------------------------------------------------------

def fuzz_settings(max_examples: int) -> settings:
    """Hypothesis settings of the fuzz tests (no deadline; function-scoped fixtures allowed)."""
    return settings(max_examples=max_examples, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def fuzz_file(tmp_path_factory, name: str, content: bytes | str) -> Path:
    """A file ``name`` in a fresh temporary folder holding ``content`` (bytes as they are,
    text as UTF-8)."""
    path = tmp_path_factory.mktemp("fuzz") / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")
    return path


def dump_yaml(data) -> str:
    """YAML text of any plain structure (what a user could have written)."""
    return yaml.dump(data, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper), allow_unicode=True, sort_keys=False)


scalars = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=12),
    st.sampled_from(["nan", ".inf", "-.inf", "1e400", "b1.x", "hexapod", "", "0x10", "1_000", "~"]),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(min_value=10**300, max_value=10**310),
)
keys = st.one_of(st.sampled_from(["name", "kind", "legs", "limits", "home", "workspace", "uncertainty", "base",
                                  "platform", "offset", "stroke", "base_axis", "std", "correlation", "covariance",
                                  "parameters", "x", "a", "u_joint_tilt", "calibration", "metadata"]),
                 st.text(max_size=6), st.integers(-3, 3))
structures = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=7), st.dictionaries(keys, inner, max_size=6)), max_leaves=30)


def tree_paths(obj, prefix=()):
    """Every key path of a nested dict/list structure, the empty path first."""
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from tree_paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from tree_paths(v, prefix + (i,))


def mutate(draw, data, values, new_keys, actions=("replace", "delete", "insert")):
    """``data`` (a nested dict/list, changed in place and returned) after 1 to 3 random edits
    at key paths it had: replace the value by one of ``values``, delete it, or insert a value
    (a list item, or a mapping entry under one of ``new_keys``)."""
    paths = [p for p in tree_paths(data) if p]
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(paths))
        parent = data
        try:
            for part in path[:-1]:
                parent = parent[part]
            action = draw(st.sampled_from(actions))
            if action == "replace" or not isinstance(parent, (dict, list)):
                parent[path[-1]] = draw(values)
            elif action == "delete":
                del parent[path[-1]]
            elif isinstance(parent, list):
                parent.insert(path[-1], draw(values))
            else:
                parent[draw(new_keys)] = draw(values)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier mutation removed this path
    return data


cells = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers().map(str),
    st.sampled_from(["", " ", "nan", "inf", "-inf", "abc", '"1"', '"a,b"', "1e400", "1_0", "--1", "#", "λ1", "0x1"]),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=6),
)
names = st.one_of(st.sampled_from(list("xyzabc") + list(READING_COLUMNS) + list(LENGTH_COLUMNS)
                                  + ["X", "λ2", "L_3", "note", "", "# units: length=m"]), st.text(max_size=5))


@st.composite
def csv_texts(draw):
    """CSV-like texts: a header of column-like names, ragged rows of odd cells, maybe a units line."""
    header = draw(st.lists(names, min_size=0, max_size=10))
    n_rows = draw(st.integers(0, 5))
    lines = [",".join(header)]
    for _ in range(n_rows):
        width = len(header) if draw(st.booleans()) else draw(st.integers(0, 12))
        lines.append(",".join(draw(st.lists(cells, min_size=width, max_size=width))))
    if draw(st.booleans()):
        lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(
            ["# units: length=mm, angle=deg", "# units: length=m", "# units: angle=grad", "# c", "", "#units:"])))
    return draw(st.sampled_from(["\n", "\r\n"])).join(lines)


# -- sensors on hexapod poses ----------------------------------------------------------------------


def frames_of(poses):
    """The platform frames of hexapod poses (N, 6) or (6,) (x, y, z, a, b, c): what a sensor reads."""
    from pkmcal.mechanisms.frame import Frame

    return Frame.from_poses(poses)


def hexapod_pose_jacobian(sensor, poses, params=None):
    """∂y/∂(x, y, z, a, b, c) (N, m, 6) of a sensor on a hexapod: its twist Jacobian times the
    hexapod's T = diag(I, E(a, b, c)) (the engine's composition)."""
    from pkmcal.conventions import euler_pose_jacobian

    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    return euler_pose_jacobian(sensor.frame_jacobian(frames_of(poses), params), poses)


#: LinuxCNC's own hexapod sample, typed in from its files (LinuxCNC
#: ``configs/sim/axis/vismach/hexapod-sim/kinematics.hal`` and ``hexapod.ini``; Debian's
#: linuxcnc-uspace installs them under ``/usr/share/doc/linuxcnc/examples/sample-configs/``):
#: base and platform joints (inch) and the INI values pkmcal reads. Its joint limits are
#: ±1000 inch on struts 29.7466 inch long at home, and LinuxCNC has no joint tilt setting.
LINUXCNC_SAMPLE_BASE_IN = [(-22.950, 13.250, 0.0), (22.950, 13.250, 0.0), (22.950, 13.250, 0.0),
                           (0.000, -26.500, 0.0), (0.000, -26.500, 0.0), (-22.950, 13.250, 0.0)]
LINUXCNC_SAMPLE_PLATFORM_IN = [(-1.000, 11.500, 0.0), (1.000, 11.500, 0.0), (10.459, -4.884, 0.0),
                               (9.459, -6.616, 0.0), (-9.459, -6.616, 0.0), (-10.459, -4.884, 0.0)]
LINUXCNC_SAMPLE_HOME_IN = (0.0, 0.0, 20.0)
LINUXCNC_SAMPLE_JOINT_LIMIT_IN = 1000.0


def write_linuxcnc_hexapod_sample(folder: Path) -> tuple[Path, Path]:
    """Our own HAL and INI files with the geometry and limits of LinuxCNC's hexapod sample
    (:data:`LINUXCNC_SAMPLE_BASE_IN`; the same values, not LinuxCNC's files)."""
    hal = ["# geometry of LinuxCNC's configs/sim/axis/vismach/hexapod-sim/kinematics.hal"]
    for part, joints in (("base", LINUXCNC_SAMPLE_BASE_IN), ("platform", LINUXCNC_SAMPLE_PLATFORM_IN)):
        hal += [f"setp genhexkins.{part}.{n}.{axis} {v:.3f}" for n, joint in enumerate(joints)
                for axis, v in zip("xyz", joint)]
    hal.append("net tool-offset genhexkins.tool-offset motion.tooloffset.z")
    lim = LINUXCNC_SAMPLE_JOINT_LIMIT_IN
    home = " ".join(f"{v:g}" for v in LINUXCNC_SAMPLE_HOME_IN)
    ini = ["# limits of LinuxCNC's configs/sim/axis/vismach/hexapod-sim/hexapod.ini", "[EMC]",
           "MACHINE = hexapod (switchkins)", "[TRAJ]", f"HOME = {home} 0 0 0",
           "COORDINATES = X Y Z A B C", "LINEAR_UNITS = inch", "ANGULAR_UNITS = degree", "[KINS]",
           "KINEMATICS = genhexkins", "JOINTS = 6"]
    for n in range(6):
        ini += [f"[JOINT_{n}]", "TYPE = LINEAR", f"MIN_LIMIT = -{lim:.1f}", f"MAX_LIMIT = {lim:.1f}",
                "HOME_OFFSET= 29.7466", "HOME = 29.7466"]
    for axis in "XYZABC":
        ini += [f"[AXIS_{axis}]", f"MIN_LIMIT = -{lim:.1f}", f"MAX_LIMIT = {lim:.1f}"]
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "kinematics.hal").write_text("\n".join(hal) + "\n")
    (folder / "hexapod.ini").write_text("\n".join(ini) + "\n")
    return folder / "kinematics.hal", folder / "hexapod.ini"


# -- the real controllers (tests/controllers/) ----------------------------------------------------

def in_ci(environ=None) -> bool:
    """True when the ``CI`` environment variable is set (to anything but empty, ``0``,
    ``false``, ``no``: the rule of tests/conftest.py's Hypothesis profile)."""
    import os

    environ = os.environ if environ is None else environ
    return environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def require_controller(reason: str | None) -> None:
    """Skip the test with ``reason`` (one line: why the controller cannot run here), or fail
    it in CI, where .ci/run installs the controllers and a skip would hide that they did not
    run; nothing when ``reason`` is None."""
    import pytest

    if reason is None:
        return
    if in_ci():
        pytest.fail(f"in CI the controller tests must run: {reason}", pytrace=False)
    pytest.skip(reason)


def probe_triggers(nominal, real, sensor, xy, *, noise=0.0, rng=None, z0=5.0):
    """Klipper's probing on a simulated printer: the firmware (``nominal``) lowers the nozzle
    down its vertical line at each (x, y) until the ``real`` machine's probe point meets the
    real bed (``sensor``), or, with ``noise``, stands that far (a normal draw) above it: the
    trigger's scatter. Returns the carriage positions λ (N, 3) at the triggers and the
    firmware's positions (x, y, z) there. Secant steps in z, vectorised over the points."""
    xy = np.asarray(xy, dtype=float)
    target = np.zeros(len(xy)) if not noise else rng.standard_normal(len(xy)) * noise

    def height(z):
        lam = nominal.ik(np.c_[xy, z])
        return sensor.predict(real.frame(real.fk(lam).poses))[:, 0] - target, lam

    z, dz = np.full(len(xy), z0), 1e-3
    for _ in range(20):
        h0, _ = height(z)
        h1, _ = height(z + dz)
        z = z - h0 * dz / (h1 - h0)
    h, lam = height(z)
    assert np.max(np.abs(h)) < 1e-11
    return lam, np.c_[xy, z]


def command_helps(width: int = 200):
    """``(path, command, help text)`` of every command and subcommand of ``pkmcal`` (``path``
    the words after ``pkmcal``, e.g. ``["import", "klipper"]``), the help as ``--help`` prints
    it at terminal width ``width``."""
    import click
    from click.testing import CliRunner

    from pkmcal.cli.main import COMMANDS, cli

    def walk(path, command):
        yield path, command, CliRunner().invoke(cli, [*path, "--help"], terminal_width=width).output
        if isinstance(command, click.Group):
            for name, sub in command.commands.items():
                yield from walk([*path, name], sub)

    for name in COMMANDS:
        yield from walk([name], cli.get_command(None, name))
