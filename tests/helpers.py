"""Helpers shared by the test modules (imported as ``from helpers import ...``; pytest puts
``tests/`` on the path): the prototype's legs as machine-file text, the CLI's user-error
contract (exit code 2, one ``pkmcal: error:`` line on stderr, no traceback, nothing
written), and the hypothesis strategies of the loader fuzz tests."""

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
