"""YAML reading and writing for pkmcal's files: YAML 1.2 numbers, line numbers, exact floats.

* :func:`parse_yaml` reads a document with PyYAML's safe loader, rejects duplicate keys,
  and returns the data with a map from key paths (``("legs", 3, "stroke")``) to 1-based line
  numbers, so that schema errors can say where they are.
* Plain scalars are resolved by the YAML 1.2 core schema (YAML 1.2.2 §10.3.2), not PyYAML's
  YAML 1.1 rules: ``305``, ``0o17``, ``0x1F``, ``1e3``, ``.5``, ``.inf``, ``.nan`` are
  numbers; ``true``/``false`` (any case as the spec lists) booleans; ``~``/``null`` and an
  empty value null; everything else — ``yes``, ``off``, ``2024-05-01`` — text. A plain
  scalar that YAML 1.1 readers (PyYAML, most tools) take for a *different number* than
  YAML 1.2 does is refused with its line, because the same file must mean the same thing
  to every reader: an integer with a leading zero (``0305`` is octal 197 in YAML 1.1, 305
  in YAML 1.2), a base-60 number (``5:05`` = 305 in YAML 1.1, text in 1.2), digits with
  underscores (``1_000``) and binary (``0b101``). Quote such a value to make it text.
  Non-finite numbers load as floats; the schemas refuse them where a finite value is needed.
* Floats keep their source text (:class:`TextFloat`), which :func:`deg_to_rad` uses.
* Angles are degrees in files and radians inside. ``np.deg2rad`` cannot reach every double
  (the spacing of degree doubles times π/180 exceeds one radian ulp for about 1 value in 9),
  so :func:`rad_to_deg_text` writes the shortest degree text whose ``np.deg2rad`` is the
  radian value exactly, and when none exists a 21-significant-digit text that
  :func:`deg_to_rad` converts with 50-digit decimal arithmetic (correctly rounded). Texts of
  at most 17 significant digits are converted with ``np.deg2rad`` as everywhere else in
  pkmcal, so ``45`` in a file is exactly ``np.deg2rad(45.0)``.
* :func:`dump_yaml` writes plain only what YAML 1.1 and YAML 1.2 readers both read back as
  written: a text that either would take for a number, a boolean or null is quoted.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal, localcontext
from typing import Any

import numpy as np
import yaml

_PI = Decimal("3.14159265358979323846264338327950288419716939937510582097494459")
_FLOAT_TAG = "tag:yaml.org,2002:float"


class TextFloat(float):
    """A float that remembers the text it was read from."""

    text: str

    def __new__(cls, value: float, text: str):
        obj = float.__new__(cls, value)
        obj.text = text
        return obj


class YamlSyntaxError(ValueError):
    """Malformed YAML; ``line`` is 1-based or None."""

    def __init__(self, message: str, line: int | None):
        super().__init__(message)
        self.line = line


# libyaml's C parser and emitter when available (about 20× faster on a 42×42 covariance).
_BaseLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_BaseDumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


_INT_TAG = "tag:yaml.org,2002:int"
_STR_TAG = "tag:yaml.org,2002:str"
_AMBIGUOUS_TAG = "tag:pkmcal,2026:yaml-1.1-number"

#: The YAML 1.2 core schema's plain scalars (YAML 1.2.2 §10.3.2), in resolution order.
_CORE_SCALARS = (
    ("tag:yaml.org,2002:null", re.compile(r"~|null|Null|NULL|")),
    ("tag:yaml.org,2002:bool", re.compile(r"true|True|TRUE|false|False|FALSE")),
    (_INT_TAG, re.compile(r"[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+")),
    (_FLOAT_TAG, re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?"
                            r"|[-+]?\.(inf|Inf|INF)|\.(nan|NaN|NAN)")),
)
_LEADING_ZERO_INT = re.compile(r"[-+]?0[0-9]+")
#: PyYAML's own YAML 1.1 rules, to find what a YAML 1.1 reader would make of a scalar.
_YAML11 = yaml.resolver.Resolver()


def _core_tag(value: str) -> str:
    """The YAML 1.2 core-schema tag of a plain scalar, or :data:`_AMBIGUOUS_TAG` when a
    YAML 1.1 reader would read a different number (module docstring)."""
    if _LEADING_ZERO_INT.fullmatch(value):
        return _AMBIGUOUS_TAG
    tag = next((t for t, rx in _CORE_SCALARS if rx.fullmatch(value)), _STR_TAG)
    if tag == _STR_TAG and _YAML11.resolve(yaml.ScalarNode, value, (True, False)) in (_INT_TAG, _FLOAT_TAG):
        return _AMBIGUOUS_TAG
    return tag


class _Loader(_BaseLoader):  # type: ignore[misc, valid-type]
    def resolve(self, kind, value, implicit):
        if kind is yaml.ScalarNode and implicit[0]:
            return _core_tag(value)
        return super().resolve(kind, value, implicit)


def _construct_int(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> int:
    text = str(node.value)
    if text.startswith(("0o", "0x")):
        return int(text[2:], 8 if text[1] == "o" else 16)
    return int(text, 10)


def _construct_float(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> float:
    text = str(node.value)
    body = text.lstrip("+-").lower()
    if body in (".inf", ".nan"):
        value = float(body[1:]) * (-1.0 if text.startswith("-") else 1.0)
    else:
        value = float(text)
    return TextFloat(value, text)


def _refuse_yaml11_number(loader: yaml.SafeLoader, node: yaml.ScalarNode):
    text = str(node.value)
    if _LEADING_ZERO_INT.fullmatch(text):
        digits = text.lstrip("+-").lstrip("0") or "0"
        sign = "-" if text.startswith("-") else ""
        old = yaml.SafeLoader.construct_yaml_int(loader, node) if re.fullmatch(r"[-+]?0[0-7]+", text) else None
        what = (f"YAML 1.1 readers take it for the octal number {old} and YAML 1.2 for {sign}{digits}"
                if old is not None else f"YAML 1.2 reads it as {sign}{digits}, YAML 1.1 readers as text")
        fix = f"write {sign}{digits} without the leading zero"
    else:
        tag = _YAML11.resolve(yaml.ScalarNode, text, (True, False))
        construct = yaml.SafeLoader.construct_yaml_int if tag == _INT_TAG else yaml.SafeLoader.construct_yaml_float
        old = construct(loader, node)
        kind = ("a base-60 number" if ":" in text else "a binary number" if "0b" in text.lower()
                else "a number with '_' separators" if "_" in text else "a signed hexadecimal number")
        what = f"YAML 1.1 readers take it for {kind} ({old!r}) and YAML 1.2 for text"
        fix = f"write {old!r} in plain decimal"
    raise YamlSyntaxError(f"'{text}' means different things to different YAML readers: {what}; {fix}, "
                          "or quote it if it is text", node.start_mark.line + 1)


_Loader.add_constructor(_INT_TAG, _construct_int)
_Loader.add_constructor(_FLOAT_TAG, _construct_float)
_Loader.add_constructor(_AMBIGUOUS_TAG, _refuse_yaml11_number)


_MAX_EXPANDED_NODES = 1_000_000


def _expanded_size(node: yaml.Node, memo: dict[int, int], stack: set[int]) -> int:
    """Number of nodes once aliases are expanded; :class:`YamlSyntaxError` for a recursive
    alias or an expansion beyond :data:`_MAX_EXPANDED_NODES` ("billion laughs")."""
    key = id(node)
    if key in memo:
        return memo[key]
    if key in stack:
        raise YamlSyntaxError("an alias refers to the node that contains it (recursive structure)",
                              node.start_mark.line + 1)
    stack.add(key)
    size = 1
    if isinstance(node, yaml.MappingNode):
        size += sum(_expanded_size(k, memo, stack) + _expanded_size(v, memo, stack) for k, v in node.value)
    elif isinstance(node, yaml.SequenceNode):
        size += sum(_expanded_size(v, memo, stack) for v in node.value)
    stack.discard(key)
    if size > _MAX_EXPANDED_NODES:
        raise YamlSyntaxError(f"aliases expand to more than {_MAX_EXPANDED_NODES} values; this is not a "
                              "machine description", node.start_mark.line + 1)
    memo[key] = size
    return size


def _walk(node: yaml.Node, path: tuple, lines: dict[tuple, int], line: int | None = None,
          seen: set[int] | None = None) -> None:
    """Fill ``lines`` with the line of every key path; an aliased node is walked once."""
    seen = set() if seen is None else seen
    lines[path] = node.start_mark.line + 1 if line is None else line
    if id(node) in seen:
        return
    seen.add(id(node))
    if isinstance(node, yaml.MappingNode):
        first: dict[Any, int] = {}
        for knode, vnode in node.value:
            key = knode.value if isinstance(knode, yaml.ScalarNode) else None
            if key is not None:
                if key in first:
                    raise YamlSyntaxError(
                        f"key {key!r} appears twice (lines {first[key]} and {knode.start_mark.line + 1}); "
                        "keep only one", knode.start_mark.line + 1)
                first[key] = knode.start_mark.line + 1
            _walk(vnode, path + (key,), lines, knode.start_mark.line + 1, seen)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _walk(item, path + (i,), lines, None, seen)


def parse_yaml(text: str) -> tuple[Any, dict[tuple, int]]:
    """``(data, lines)`` of one YAML document; :class:`YamlSyntaxError` with the line when
    it is not valid YAML. ``lines`` maps key paths to 1-based line numbers."""
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None, {}
        _expanded_size(node, {}, set())
        lines: dict[tuple, int] = {}
        _walk(node, (), lines)
        data = loader.construct_document(node)
    except YamlSyntaxError:
        raise
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = _one_line(" ".join(str(s) for s in (exc.context, exc.problem) if s))
        raise YamlSyntaxError(f"not valid YAML: {what}", None if mark is None else mark.line + 1) from None
    except yaml.YAMLError as exc:
        raise YamlSyntaxError(f"not valid YAML: {_one_line(exc)}", getattr(exc, "line", None)) from None
    except (ValueError, TypeError, OverflowError, RecursionError) as exc:
        # PyYAML's constructors raise these on e.g. a timestamp with an impossible date.
        raise YamlSyntaxError(f"not valid YAML: {_one_line(exc)}", None) from None
    finally:
        loader.dispose()
    return data, lines


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def plain(obj: Any) -> Any:
    """``obj`` with every :class:`TextFloat` replaced by a plain float (for free-form data)."""
    if isinstance(obj, TextFloat):
        return float(obj)
    if isinstance(obj, dict):
        return {plain(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [plain(v) for v in obj]
    return obj


# -- degrees <-> radians, exactly -------------------------------------------------------

def _significant_digits(text: str) -> int:
    mantissa = re.split(r"[eE]", text.strip().lstrip("+-").replace("_", ""))[0]
    digits = mantissa.replace(".", "").lstrip("0")
    return len(digits)


def deg_to_rad(value: float) -> float:
    """Radians of a degree value read from a file (see module docstring)."""
    text = getattr(value, "text", None)
    if text is not None and _significant_digits(text) > 17:
        with localcontext() as ctx:
            ctx.prec = 60
            return float(Decimal(text.replace("_", "")) * _PI / 180)
    return float(np.deg2rad(float(value)))


def _deg_candidates(rad: float):
    d = float(np.rad2deg(rad))
    yield d
    for k in range(1, 5):
        for direction in (math.inf, -math.inf):
            w = d
            for _ in range(k):
                w = math.nextafter(w, direction)
            yield w


def rad_to_deg_text(rad: float) -> str:
    """The shortest degree text that :func:`deg_to_rad` maps back to ``rad`` exactly."""
    rad = float(rad)
    if not math.isfinite(rad):
        raise ValueError(f"angle {rad!r} is not finite")
    best = None
    for d in _deg_candidates(rad):
        if float(np.deg2rad(d)) == rad:
            text = _yaml_float_text(d)
            if best is None or len(text) < len(best):
                best = text
    if best is not None:
        return best
    for digits in (21, 25, 30):
        with localcontext() as ctx:
            ctx.prec = 60
            exact = Decimal(rad) * 180 / _PI
            text = f"{exact:.{digits - 1}e}"
        if deg_to_rad(TextFloat(float(text), text)) == rad:
            return text
    raise ValueError(f"no exact degree text for {rad!r}")  # unreachable: 30 digits always suffice


def _yaml_float_text(value: float) -> str:
    """``repr(value)`` in a form YAML 1.1 resolves as a float (a dot before any exponent)."""
    text = repr(float(value)).lower()
    if "e" in text and "." not in text.split("e")[0]:
        text = text.replace("e", ".0e", 1)
    if "." not in text and "e" not in text and text not in ("inf", "-inf", "nan"):
        text += ".0"
    return text


# -- writing ----------------------------------------------------------------------------

class RawFloat(str):
    """A float already formatted (e.g. by :func:`rad_to_deg_text`), written verbatim."""


class FlowList(list):
    """A list written on one line (``[1.0, 2.0, 3.0]``)."""


class _Dumper(_BaseDumper):  # type: ignore[misc, valid-type]
    def ignore_aliases(self, data: Any) -> bool:  # never write &anchors for repeated values
        return True

    def resolve(self, kind, value, implicit):
        """YAML 1.1's tag, unless only YAML 1.2 (or the ambiguity rule) reads the plain text
        as something else than text: then a text gets quoted (module docstring)."""
        tag = super().resolve(kind, value, implicit)
        if kind is yaml.ScalarNode and implicit[0] and tag == _STR_TAG:
            return _core_tag(value)
        return tag


def _represent_raw(dumper: yaml.SafeDumper, data: RawFloat):
    return dumper.represent_scalar(_FLOAT_TAG, str(data))


def _represent_flow(dumper: yaml.SafeDumper, data: FlowList):
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)


def _represent_float(dumper: yaml.SafeDumper, data: float):
    if math.isfinite(data):
        return dumper.represent_scalar(_FLOAT_TAG, _yaml_float_text(data))
    return yaml.SafeDumper.represent_float(dumper, data)


def _represent_text_float(dumper: yaml.SafeDumper, data: TextFloat):
    """A float read from a file: its source text when that has more than 17 significant
    digits (a degree text only :func:`deg_to_rad` maps exactly; module docstring), else
    as any float."""
    if math.isfinite(data) and _significant_digits(data.text) > 17:
        return dumper.represent_scalar(_FLOAT_TAG, data.text)
    return _represent_float(dumper, float(data))


_Dumper.add_representer(RawFloat, _represent_raw)
_Dumper.add_representer(TextFloat, _represent_text_float)
_Dumper.add_representer(FlowList, _represent_flow)
_Dumper.add_representer(float, _represent_float)
_Dumper.add_representer(np.float64, lambda d, v: _represent_float(d, float(v)))


def dump_yaml(data: Any) -> str:
    """Block-style YAML with :class:`FlowList` rows on one line, keys in insertion order."""
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False,
                     allow_unicode=True, width=1_000_000)
