"""The JSON record of a (calibrated) machine, ``pkmcal export --format json`` and
:func:`pkmcal.api.export`: the identified parameters ρ in file units (mm, deg) with their
standard deviations σ_i = √Σ_ii and correlations ρ_ij = Σ_ij / (σ_i σ_j) from the machine
file's covariance Σ (:func:`pkmcal.io.machine_file.identified_uncertainty`), units,
conventions and calibration metadata. Deterministic: the same machine gives the same bytes.
"""

from __future__ import annotations

import json

import numpy as np

from pkmcal import __version__
from pkmcal.errors import PkmcalError
from pkmcal.io.tables import to_file_units
from pkmcal.mechanisms.base import Mechanism

#: Version of the JSON layout written by :func:`calibration_json`.
JSON_FORMAT_VERSION = 1

CONVENTIONS = {
    "pose": "x y z (mm) a b c (deg): the platform frame {P} in the base frame {F}; R = Rz(c) Ry(b) Rx(a) "
            "(roll a, pitch b, yaw c about the fixed base axes; scipy extrinsic 'xyz'; = LinuxCNC genhexkins)",
    "hexapod_parameters": "per leg i = 1..6: bi.x, bi.y, bi.z = base joint b_i in {F}; ai.x, ai.y, ai.z = platform "
                          "joint a_i in {P}; L0_i = leg offset: leg length L_i = |p + R a_i - b_i| = L0_i + lambda_i, "
                          "lambda_i the actuator reading",
    "uncertainty": "std = square root of the diagonal of the parameter covariance of the machine file; correlation = "
                   "covariance_ij / (std_i std_j); parameters without std were held fixed (e.g. the gauge)",
}


def _finite(v: float) -> float:
    v = float(v)
    if not np.isfinite(v):
        raise PkmcalError(f"cannot export a non-finite value ({v}) to JSON")
    return v + 0.0  # -0.0 → 0.0


def calibration_json(machine: Mechanism, source: str | None = None) -> dict:
    """The JSON-ready record of a (calibrated) machine: parameters in file units (mm, deg)
    with σ (None where the covariance has a zero row: not identified), the correlation
    matrix over the identified parameters, units, conventions and calibration metadata."""
    names = list(machine.param_names)
    angle = np.array(machine.param_is_angle, dtype=bool)
    scale = np.where(angle, np.rad2deg(1.0), 1.0)
    values = np.asarray(machine.params, dtype=float) * scale
    cov = machine.covariance
    std = np.full(len(names), np.nan)
    corr_block = None
    if cov is not None:
        from pkmcal.io.machine_file import identified_uncertainty

        used, _, sd, corr = identified_uncertainty(np.asarray(cov, dtype=float) * np.outer(scale, scale))
        std[used] = sd
        corr_block = {"parameters": [names[i] for i in used],
                      "matrix": [[_finite(v) for v in row] for row in np.clip(corr, -1.0, 1.0)]}
    params = [{"name": n, "value": _finite(v), "unit": "deg" if a else u,
               "std": None if np.isnan(s) else _finite(s)}
              for n, v, a, u, s in zip(names, values, angle, machine.param_units, std)]
    reading_units = tuple(machine.actuator_units)
    home = to_file_units(machine.home_pose, machine.pose_is_angle)
    meta = dict(machine.metadata or {})
    out = {
        "format": "pkmcal-calibration",
        "format_version": JSON_FORMAT_VERSION,
        "pkmcal": __version__,
        "source": source,
        # "kind": the model's class (kept for the scripts that read it); "mechanism_kind": the
        # kind `pkmcal machines` and `pkmcal info` name (6-UPS, linear-delta, planar-3dof-4act, ...)
        "machine": {"name": machine.name, "kind": type(machine).__name__, "mechanism_kind": machine.kind,
                    "description": machine.description or ""},
        "units": {"length": "mm", "angle": "deg", "covariance": "mm^2 (deg^2, mm*deg for angle parameters)",
                  # the unit of each numeric key (docs/conventions.md, "Units in JSON")
                  "format_version": "1", "n_identified": "1", "correlation": "1",
                  "home_pose": "mm for x, y, z; deg for the angles (a, b, c; phi)",
                  "actuator_stroke": ("mm (deg for rotary actuators): [min, max] reading"
                                      if set(reading_units) <= {"mm", "deg"} else
                                      "the reading unit of actuator_units: [min, max] reading"),
                  "n_poses": "1", "n_free": "1", "reduced_chi2": "1",
                  "rms_residual": "the unit of the fit's residual rows (mm; 1 when whitened or mixed)",
                  "sensor": "mm; deg for the sensor's angle parameters",
                  "before_registration": "mm; deg for the sensor's angle parameters",
                  "setup": "the identified setup in setup-file units: mm; deg for angles (a, b, c, "
                           "orientation_deg, angle parameters and their std)"},
        "conventions": CONVENTIONS,
        "parameters": params,
        "n_identified": int(np.count_nonzero(~np.isnan(std))),
        "correlation": corr_block,
        "home_pose": {n: _finite(v) for n, v in zip(machine.pose_names, home)},
        "calibration": meta.pop("calibration", None),
        "setup": meta.pop("setup", None),
        "metadata": meta or None,
    }
    out["actuator_units"] = dict(zip(machine.actuator_names, reading_units))
    if "stroke" in machine.abilities:
        out["actuator_stroke"] = {a: [_finite(v) for v in row]
                                  for a, row in zip(machine.actuator_names, np.asarray(machine.reading_range(),
                                                                                       dtype=float))}
    return out


def format_calibration_json(machine: Mechanism, source: str | None = None) -> str:
    """:func:`calibration_json` as text: 2-space indent, shortest exact floats, ``\\n`` ending;
    a non-finite number in the file's free-form metadata (e.g. an undefined χ²/ν) is null."""
    from pkmcal.io.json_out import finite_or_null

    return json.dumps(finite_or_null(calibration_json(machine, source)), indent=2, ensure_ascii=False,
                      allow_nan=False, default=str) + "\n"


__all__ = ["CONVENTIONS", "JSON_FORMAT_VERSION", "calibration_json", "format_calibration_json"]
