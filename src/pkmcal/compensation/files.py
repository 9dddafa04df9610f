"""Correction files: pkmcal's own (YAML, read back by ``pkmcal correct``) and Klipper's bed
mesh profile in the SAVE_CONFIG block.

**pkmcal's correction file** (docs/compensation.md)::

    kind: bed-mesh                    # or pose-field
    machine: NAME                     # the calibrated machine it was fitted for
    components: [bed_z]               # a pose field: the pose coordinates it displaces
    basis: {type: mesh, x_count: 4, y_count: 4, min_x: -90, max_x: 90, min_y: -90, max_y: 90,
            algo: bicubic, tension: 0.2, mesh_pps: 2}
           # or {type: polynomial, degree: 2, variables: [x, y, z, a, b, c],
           #     box: [[min, max], ...]}   (mm; deg for angle coordinates)
    coefficients: [[...], ...]        # a mesh: heights (mm), one row per y, as Klipper's points;
                                      # a pose field: one row per monomial, one column per
                                      # component (mm; deg for angle components)
    report: {...}                     # the cross-validation and held-out gate

**Klipper's profile** (klippy/extras/bed_mesh.py ``ProfileManager.save_profile``, read back by
``ProfileManager.__init__`` and ``load_profile``): section ``[bed_mesh NAME]`` with
``version`` (``PROFILE_VERSION`` = 1), ``points`` (one line per y row, ``%.6f`` heights
separated by ", "), then ``PROFILE_OPTIONS``: x_count, y_count, mesh_x_pps, mesh_y_pps,
algo, tension, min_x, max_x, min_y, max_y. SAVE_CONFIG writes it below the ``#*#`` header
(klippy/configfile.py ``PrinterConfig.cmd_SAVE_CONFIG``), each line prefixed ``#*# ``,
multi-line values continued with a tab, as :func:`pkmcal.io.klipper_config.save_config_text`
writes a printer.cfg. Klipper loads the profile only with a ``[bed_mesh]`` section in the
config, and applies it after ``BED_MESH_PROFILE LOAD=NAME`` (``default`` is loaded at start).
"""

from __future__ import annotations

import os

import numpy as np

from pkmcal.compensation.basis import ALGORITHMS, MeshBasis, PolynomialBasis
from pkmcal.compensation.fit import KINDS, Field
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism

#: klippy/extras/bed_mesh.py ``PROFILE_VERSION``.
KLIPPER_PROFILE_VERSION = 1


def _angles(machine: Mechanism, names) -> np.ndarray:
    return np.array([machine.pose_is_angle[machine.pose_names.index(n)] if n in machine.pose_names else False
                     for n in names], dtype=bool)


def correction_document(fld: Field, machine: Mechanism, report: dict | None = None) -> dict:
    """The correction file's mapping (module docstring), file units."""
    from pkmcal.io._yaml import FlowList

    doc: dict = {"kind": fld.kind, "machine": machine.name, "components": FlowList(fld.components)}
    b = fld.basis
    if isinstance(b, MeshBasis):
        (x0, x1), (y0, y1) = b.bounds
        doc["basis"] = {"type": "mesh", "x_count": b.x_count, "y_count": b.y_count, "min_x": x0, "max_x": x1,
                        "min_y": y0, "max_y": y1, "algo": b.algo, "tension": b.tension, "mesh_pps": b.pps}
        coef = fld.coefficients[:, 0].reshape(b.y_count, b.x_count)
    else:
        names = machine.pose_names[:b.dims]
        box = np.asarray(b.box, dtype=float)
        box = np.where(_angles(machine, names)[:, None], np.rad2deg(box), box)
        doc["basis"] = {"type": "polynomial", "degree": b.degree, "variables": FlowList(names),
                        "box": [FlowList(float(v) for v in row) for row in box]}
        coef = np.where(_angles(machine, fld.components)[None, :], np.rad2deg(fld.coefficients), fld.coefficients)
    doc["coefficients"] = [FlowList(float(v) for v in row) for row in coef]
    if report is not None:
        doc["report"] = report
    return doc


def save_correction(path: str | os.PathLike, fld: Field, machine: Mechanism, report: dict | None = None) -> str:
    """The correction file's text (written atomically to ``path`` unless it is None or '-')."""
    from pkmcal.io._yaml import dump_yaml
    from pkmcal.io.atomic import atomic_write_text
    from pkmcal.io.json_out import finite_or_null

    text = ("# pkmcal correction: read by 'pkmcal correct --correction FILE' (docs/compensation.md)\n"
            + dump_yaml(finite_or_null(correction_document(fld, machine, report))))
    if path is not None and os.fspath(path) != "-":
        atomic_write_text(path, text)
    return text


def load_correction(path: str | os.PathLike, machine: Mechanism) -> Field:
    """The :class:`Field` of a correction file, for ``machine``; a bad file is an error
    naming the file, the line and the key."""
    from pkmcal.io._yaml import YamlSyntaxError, parse_yaml

    src = os.fspath(path)
    try:
        with open(src, encoding="utf-8") as fh:
            text = fh.read()
    except OSError as exc:
        raise PkmcalError(f"{src}: cannot read the correction file ({exc.strerror})") from None
    try:
        doc, lines = parse_yaml(text)
    except (YamlSyntaxError, ValueError) as exc:
        raise PkmcalError(f"{src}: not a correction file: {exc}") from None

    def bad(key: tuple, what: str):
        line = lines.get(key) or lines.get(key[:1])
        return PkmcalError(f"{src}{f':{line}' if line else ''}: {'.'.join(map(str, key))}: {what}; the file "
                           "'pkmcal compensate' writes is the reference (docs/compensation.md)")

    if not isinstance(doc, dict):
        raise PkmcalError(f"{src}: not a correction file (a mapping with kind, basis, coefficients expected)")
    fitted_for = doc.get("machine")
    if isinstance(fitted_for, str) and fitted_for != machine.name:
        import warnings

        from pkmcal.errors import PkmcalWarning

        warnings.warn(f"{src}: the correction was fitted for machine '{fitted_for}', not '{machine.name}': it "
                      "describes what that calibration left; refit it for this one (pkmcal compensate)",
                      PkmcalWarning, stacklevel=2)
    kind = doc.get("kind")
    if kind not in KINDS:
        raise bad(("kind",), f"must be one of {', '.join(KINDS)}")
    basis = doc.get("basis")
    if not isinstance(basis, dict):
        raise bad(("basis",), "missing or not a mapping")
    comps = doc.get("components")
    if not isinstance(comps, list) or not comps or not all(isinstance(c, str) for c in comps):
        raise bad(("components",), "must be a list of names")
    coef = doc.get("coefficients")
    try:
        C = np.array(coef, dtype=float)
    except (TypeError, ValueError):
        raise bad(("coefficients",), "must be rows of numbers") from None
    if C.ndim != 2 or not np.all(np.isfinite(C)):
        raise bad(("coefficients",), "must be rows of finite numbers of equal length")

    def num(key, kind_=float):
        v = basis.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (kind_ is int and v != int(v)):
            raise bad(("basis", key), f"must be {'an integer' if kind_ is int else 'a number'}")
        return kind_(v)

    try:
        if basis.get("type") == "mesh":
            if kind != "bed-mesh":
                raise bad(("basis", "type"), "a mesh is the basis of a bed-mesh correction")
            algo = basis.get("algo")
            if algo not in ALGORITHMS:
                raise bad(("basis", "algo"), f"must be one of {', '.join(ALGORITHMS)}")
            b = MeshBasis(num("x_count", int), num("y_count", int),
                          ((num("min_x"), num("max_x")), (num("min_y"), num("max_y"))), algo, num("tension"),
                          num("mesh_pps", int))
            if C.shape != (b.y_count, b.x_count):
                raise bad(("coefficients",), f"a {b.x_count} x {b.y_count} mesh needs {b.y_count} rows of "
                          f"{b.x_count} heights; got {C.shape[0]} x {C.shape[1]}")
            if "z" not in machine.pose_names:
                raise PkmcalError(f"{src}: a bed mesh corrects a machine with a z coordinate; '{machine.name}' "
                                  f"has {', '.join(machine.pose_names)}")
            return Field(kind, b, ("bed_z",), C.reshape(-1, 1))
        if basis.get("type") == "polynomial":
            names = basis.get("variables")
            if names != list(machine.pose_names[:len(names or [])]) or not names:
                raise bad(("basis", "variables"), f"must be the first pose coordinates of machine "
                          f"'{machine.name}' ({', '.join(machine.pose_names)})")
            unknown = [c for c in comps if c not in machine.pose_names]
            if unknown:
                raise bad(("components",), f"'{', '.join(unknown)}' is not a pose coordinate of machine "
                          f"'{machine.name}'")
            box = np.array(basis.get("box"), dtype=float)
            if box.shape != (len(names), 2):
                raise bad(("basis", "box"), f"must be {len(names)} [min, max] pairs")
            box = np.where(_angles(machine, names)[:, None], np.deg2rad(box), box)
            b = PolynomialBasis(num("degree", int), tuple(map(tuple, box)))
            if C.shape != (b.size, len(comps)):
                raise bad(("coefficients",), f"a degree-{b.degree} polynomial of {len(names)} variables for "
                          f"{len(comps)} components needs {b.size} rows of {len(comps)}")
            C = np.where(_angles(machine, comps)[None, :], np.deg2rad(C), C)
            return Field(kind, b, tuple(comps), C)
    except (TypeError, ValueError):
        raise bad(("basis",), "malformed") from None
    raise bad(("basis", "type"), "must be mesh or polynomial")


def klipper_profile(fld: Field, name: str = "default") -> dict[str, dict[str, str]]:
    """``{"bed_mesh NAME": {option: text}}``: the profile as ``ProfileManager.save_profile``
    sets it (module docstring), for :func:`pkmcal.io.klipper_config.save_config_text`."""
    b = fld.basis
    if fld.kind != "bed-mesh" or not isinstance(b, MeshBasis):
        raise PkmcalError("Klipper takes a bed mesh (a correction of kind bed-mesh); a pose field is applied by "
                          "'pkmcal correct' to the program instead")
    if not name.strip() or any(c.isspace() for c in name):
        raise PkmcalError(f"Klipper profile name '{name}': give one word (e.g. default)")
    Z = fld.coefficients[:, 0].reshape(b.y_count, b.x_count)
    points = "".join("\n  " + ", ".join("%.6f" % v for v in row) for row in Z)
    (x0, x1), (y0, y1) = b.bounds
    opts = {"version": str(KLIPPER_PROFILE_VERSION), "points": points, "x_count": str(b.x_count),
            "y_count": str(b.y_count), "mesh_x_pps": str(b.pps), "mesh_y_pps": str(b.pps), "algo": b.algo,
            "tension": repr(float(b.tension)), "min_x": repr(float(x0)), "max_x": repr(float(x1)),
            "min_y": repr(float(y0)), "max_y": repr(float(y1))}
    return {f"bed_mesh {name}": opts}


def klipper_block(fld: Field, name: str = "default") -> str:
    """The SAVE_CONFIG block holding only the profile (the header and ``#*#`` lines), to end a
    printer.cfg that has no block yet; a printer.cfg with a block is updated by
    :func:`pkmcal.io.klipper_config.save_config_text`."""
    import configparser

    from pkmcal.io.klipper_config import AUTOSAVE_HEADER, autosave_lines

    parser = configparser.RawConfigParser()
    for section, opts in klipper_profile(fld, name).items():
        parser.add_section(section)
        for k, v in opts.items():
            parser.set(section, k, v)
    return AUTOSAVE_HEADER.lstrip("\n") + "\n".join(autosave_lines(parser)) + "\n"


__all__ = ["KLIPPER_PROFILE_VERSION", "correction_document", "klipper_block", "klipper_profile", "load_correction",
           "save_correction"]
