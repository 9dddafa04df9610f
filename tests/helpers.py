"""Helpers shared by the test modules (imported as ``from helpers import ...``; pytest puts
``tests/`` on the path): the prototype's legs as machine-file text, the CLI's user-error
contract (exit code 2, one ``pkmcal: error:`` line on stderr, no traceback, nothing
written), the hypothesis strategies of the loader fuzz tests, and the one comparison of
analytic Jacobians with central finite differences that every Jacobian test uses
(:func:`assert_jacobian_matches_fd`, its tolerance derived from the step and the scale)."""

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
# absolute error of one evaluation of f. Bounds used here:
#
# * T_k ≤ 2·G_k/ℓ_k² (Cauchy's estimate for the analytic function ∂f/∂x_k: if its size stays
#   below the slope G_k within distance ℓ_k of x_k, its second derivative is ≤ 2!·G_k/ℓ_k²).
#   ℓ_k is the problem's length scale for x_k: the leg length for a coordinate in mm of a leg
#   of a hexapod (for ‖v + t e‖ exactly |d³/dt³| ≤ (2/√3)/‖v‖² ≤ 2/‖v‖², G = 1), 1 rad for an
#   angle (a lever r rotating: |d³/dt³| ≤ r·(1 + 3r/L + 1.16 r²/L²) ≈ 2r for r/L ≤ 0.3, G = r).
# * δ = FD_ROUNDINGS·ε·M: that many roundings of relative size ε on the largest value M the
#   computation handles (default: the largest |f|); iterative solvers inside f (FK) give δ
#   from their stopping tolerance instead.
# * h_k = ε^(1/3)·max(ℓ_k, |x_k|), near the minimiser (3δ/T_k)^(1/3) ≈ ε^(1/3)·ℓ_k of the
#   bound when M ≈ G·ℓ, so both terms are ~ε^(2/3)·G ≈ 4e-11·G.
#
# The tolerance is FD_SAFETY times that bound, plus the analytic Jacobian's own round-off.
# The check has teeth: the tolerance of every column that matters must be below
# ``resolution`` (default 1e-5) times the column's size, else the test itself fails; so a
# sign flip or a 1e-5 relative error of one column is always caught (test_fd_check_has_teeth).

EPS = float(np.finfo(float).eps)
#: Factor between the error bound above (constants of typical, not worst-case size) and the
#: tolerance.
FD_SAFETY = 10.0
#: Roundings of relative size ε in one evaluation of f (a few dozen flops per value).
FD_ROUNDINGS = 32


def fd_steps(x, scale) -> np.ndarray:
    """Central-difference steps h = ε^(1/3)·max(ℓ, |x|) for x (..., n), scale ℓ (n,) or scalar."""
    x = np.asarray(x, dtype=float)
    return np.cbrt(EPS) * np.maximum(np.broadcast_to(np.asarray(scale, dtype=float), x.shape[-1:]), np.abs(x))


def central_difference(f, x, k: int, h, diff=None) -> np.ndarray:
    """(f(x + h e_k) − f(x − h e_k)) / (x⁺_k − x⁻_k): column k of the central-difference Jacobian.

    ``x`` is (..., n); ``h`` a scalar or an array of the shape of ``x[..., k]`` (one step per
    pose when f maps each row of x independently). The divisor is the step actually taken
    after rounding x ± h. ``diff(a, b)`` replaces a − b (e.g. to wrap angle readings)."""
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

    Parameters (the error model is in the comment above this function)
    ----------
    scale : ℓ_k, the length scale of each variable (n,) or scalar (mm: a leg length; rad: 1).
    slope : G_k, a bound on |∂f/∂x_k| (n,) or scalar; default the largest |J[..., k]|.
    magnitude : M, the largest value the computation of f handles; default max |f(x)|.
    noise : δ, the absolute error of one evaluation of f; default FD_ROUNDINGS·ε·M.
    h : steps (overrides :func:`fd_steps`), scalar, (n,) or x.shape.
    resolution : the largest relative error of a column the check may miss (checked).
    names : column names for the message.

    Returns (finite differences, tolerance), broadcastable to J's shape.
    """
    x = np.asarray(x, dtype=float)
    J = np.asarray(J, dtype=float)
    n = x.shape[-1]
    h = fd_steps(x, scale) if h is None else np.broadcast_to(np.asarray(h, dtype=float), x.shape)
    fd = np.stack([central_difference(f, x, k, h[..., k], diff) for k in range(n)], axis=-1)
    assert fd.shape == J.shape, f"Jacobian shape {J.shape}, finite differences {fd.shape}"
    ell = np.broadcast_to(np.asarray(scale, dtype=float), (n,))
    col_size = np.max(np.abs(J).reshape(-1, n), axis=0, initial=0.0)
    G = col_size if slope is None else np.broadcast_to(np.asarray(slope, dtype=float), (n,))
    if noise is None:
        M = np.max(np.abs(f(x))) if magnitude is None else magnitude
        noise = FD_ROUNDINGS * EPS * M
    hb = np.reshape(h, x.shape[:-1] + (1,) * (J.ndim - x.ndim) + (n,))
    tol = fd_tolerance(hb, 2.0 * G / ell**2, noise, safety) + FD_ROUNDINGS * EPS * np.max(np.abs(J), initial=0.0)
    err = np.abs(J - fd)
    names = list(names) if names is not None else [f"column {k}" for k in range(n)]
    bad = ~(err <= tol)  # NaN counts as a failure
    if bad.any():
        ratio = np.where(np.isfinite(err), err / tol, np.inf)
        idx = np.unravel_index(np.argmax(np.where(bad, ratio, -1.0)), J.shape)
        raise AssertionError(
            f"{err_msg}{': ' if err_msg else ''}analytic Jacobian differs from central differences at "
            f"{bad.sum()} of {bad.size} entries; worst {names[idx[-1]]} at index {idx}: analytic "
            f"{J[idx]:.6g}, finite differences {fd[idx]:.6g}, |difference| {err[idx]:.3g} > tolerance "
            f"{np.broadcast_to(tol, J.shape)[idx]:.3g}")
    # teeth: every column that matters (f changes by ≥ 1e-6 of the largest change over a scale)
    # is resolved to `resolution` of its size
    change = col_size * ell
    matters = change >= 1e-6 * np.max(change, initial=0.0)
    col_tol = np.max(np.broadcast_to(tol, J.shape).reshape(-1, n), axis=0)
    blunt = matters & ~(col_tol <= resolution * col_size)
    assert not blunt.any(), (
        f"{err_msg}{': ' if err_msg else ''}the finite-difference check cannot resolve a relative error of "
        f"{resolution:g} in {[names[k] for k in np.flatnonzero(blunt)]} (tolerance / column size "
        f"{(col_tol / col_size)[blunt]})")
    return fd, tol


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
