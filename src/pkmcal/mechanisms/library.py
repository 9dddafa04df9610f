"""Built-in machines, usable by name wherever a machine file is accepted.

* ``stewart-prototype``: the Gough–Stewart prototype of paper 2 (Saputra, Ong, Nee 2014),
  §5 and Table 3: joints as tabulated, L0 = 305 mm, stroke 0–50 mm, U-joint tilt 45°,
  S-joint tilt 29°, leg diameter 36.1 mm. The default machine of pkmcal.
* ``stewart-prototype-real``: the same machine with paper 2's Table 4 deviations added
  (its "real model for calibration simulation").
* ``symmetric:KEY=VALUE,...``: a symmetric 6-6 (or, with ``platform_separation=0``, 3-6)
  hexapod from joint radii and pair separation angles; see :func:`symmetric_hexapod`.

* ``kossel-mini``: Johann Rocholl's Kossel Mini linear delta printer with the dimensions
  of Marlin's example configuration (MarlinFirmware/Configurations,
  ``config/examples/delta/kossel_mini/Configuration.h``): DELTA_DIAGONAL_ROD 215 mm,
  DELTA_RADIUS 105.2 mm, DELTA_HEIGHT 250 mm, DELTA_PRINTABLE_RADIUS 90 mm, towers at
  210/330/90° with no trims or endstop adjustments.
* ``delta-picker``: a rotary (Clavel) pick-and-place delta of illustrative dimensions,
  typical of the 800 mm-workspace class: effective shoulder radius (base minus effector
  joint radius) 150 mm, upper arms 350 mm, forearms 800 mm, motors −40…100°, ball joints
  within 60° of vertical; its working cylinder (every pose in it reachable): radius 300 mm
  between z = −950 and −680 mm.
* ``servo-stewart``: a rotary (6-RSS) Stewart platform of illustrative hobby dimensions
  (servo horns 25 mm, rods 180 mm, crank pivots in pairs ±10° on a 100 mm circle, platform
  joints in pairs ±50° on a 70 mm circle, servos −60…60°; not a particular product):
  :func:`pkmcal.mechanisms.rss_hexapod.symmetric_rss_hexapod`.
* ``hexaslide``: a sliding-joint (6-PUS) hexapod of illustrative dimensions: six vertical
  rails in pairs ±10° on a 150 mm circle, carriages 0…150 mm, legs 200 mm rising to platform
  joints in pairs ±50° on a 70 mm circle:
  :func:`pkmcal.mechanisms.pus_hexapod.symmetric_pus_hexapod`.

Other planar/redundant machines register themselves in :data:`BUILTIN_MACHINES`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.catalogue import BUILTIN_CATALOGUE, SYMMETRIC_PREFIX
from pkmcal.mechanisms.hexapod import Hexapod, HexapodLimits
from pkmcal.mechanisms.planar import planar_2dof_3act, planar_3dof_4act

#: Paper 2, Table 3 (mm): base joints b_i (rows = legs 1..6).
PROTOTYPE_BASE = np.array(
    [
        [-152.500, 0.000, 0.000],
        [-132.068, -76.250, 0.000],
        [76.250, -132.068, 0.000],
        [132.068, -76.250, 0.000],
        [76.250, 132.068, 0.000],
        [0.000, 152.500, 0.000],
    ]
)
#: Paper 2, Table 3 (mm): platform joints a_i in {P}.
PROTOTYPE_PLATFORM = np.array(
    [
        [-60.622, 35.000, 0.000],
        [-35.000, -60.622, 0.000],
        [0.000, -70.000, 0.000],
        [70.000, 0.000, 0.000],
        [60.622, 35.000, 0.000],
        [-35.000, 60.622, 0.000],
    ]
)
#: Paper 2, Table 4 (mm): deviations of the "real" model: δL0_i, δb_i, δa_i.
TABLE4_DELTA_OFFSET = np.array([1.0, 2.0, 3.0, 1.0, 2.0, 3.0])
TABLE4_DELTA_BASE = np.array(
    [[0, 0, 0], [3, 0, 0.3], [0.1, 1.8, 0.7], [-0.1, 1.8, 0.7], [-0.1, 1.8, 0.7], [-0.1, 1.8, 0.7]], dtype=float
)
TABLE4_DELTA_PLATFORM = np.array(
    [[0, 0, 0], [-0.9, 0.67, 0.53], [3, -2, 0.7], [3, -2, 0.7], [3, -2, 0.7], [3, -2, 0.7]], dtype=float
)
PROTOTYPE_LIMITS = HexapodLimits(
    u_joint_tilt=np.deg2rad(45.0), s_joint_tilt=np.deg2rad(29.0), leg_diameter=36.1
)


def stewart_prototype() -> Hexapod:
    """Paper 2's prototype (Table 3 and §5)."""
    return Hexapod(
        name="stewart-prototype",
        base=PROTOTYPE_BASE,
        platform=PROTOTYPE_PLATFORM,
        offset=np.full(6, 305.0),
        stroke=np.tile([0.0, 50.0], (6, 1)),
        limits=PROTOTYPE_LIMITS,
        description="Gough-Stewart prototype of Saputra, Ong & Nee (2014), Table 3",
    )


def stewart_prototype_real() -> Hexapod:
    """Paper 2's prototype with the Table 4 deviations (the simulated "real" machine)."""
    nominal = stewart_prototype()
    rho = np.concatenate(
        [nominal.base + TABLE4_DELTA_BASE, nominal.platform + TABLE4_DELTA_PLATFORM,
         (nominal.offset + TABLE4_DELTA_OFFSET)[:, None]],
        axis=1,
    ).ravel()
    rho = np.concatenate([rho, nominal.gains])  # Table 4 has no gain errors: the gains stay 1
    real = nominal.with_params(rho, name="stewart-prototype-real")
    from dataclasses import replace

    # Keep the nominal home pose: the real machine is commanded as the nominal one is.
    return replace(real, home=nominal.home, description="stewart-prototype with the Table 4 deviations of Saputra et al. (2014)")


def kossel_mini():
    """The Kossel Mini (module docstring)."""
    from pkmcal.mechanisms.linear_delta import klipper_delta

    return klipper_delta("kossel-mini", delta_radius=105.2, arm_length=215.0, position_endstop=250.0,
                         print_radius=90.0, description="Kossel Mini linear delta printer (Marlin's example "
                         "configuration: rod 215 mm, radius 105.2 mm, height 250 mm)")


def delta_picker():
    """The rotary pick-and-place delta (module docstring)."""
    from pkmcal.mechanisms.rotary_delta import symmetric_rotary_delta

    return symmetric_rotary_delta("delta-picker", radius=150.0, upper=350.0, forearm=800.0, workspace_radius=300.0,
                                  z_range=(-950.0, -680.0),
                                  description="rotary pick-and-place delta, illustrative 800 mm-workspace class "
                                  "(upper arm 350 mm, forearm 800 mm)")


def servo_stewart():
    """The rotary hobby Stewart platform (module docstring)."""
    from pkmcal.mechanisms.rss_hexapod import symmetric_rss_hexapod

    return symmetric_rss_hexapod("servo-stewart", base_radius=100.0, platform_radius=70.0, crank=25.0, rod=180.0,
                                 description="rotary (servo) Stewart platform, illustrative hobby dimensions "
                                 "(horns 25 mm, rods 180 mm)")


def hexaslide():
    """The vertical-rail sliding-joint hexapod (module docstring)."""
    from pkmcal.mechanisms.pus_hexapod import symmetric_pus_hexapod

    return symmetric_pus_hexapod("hexaslide", rail_radius=150.0, platform_radius=70.0, leg=200.0, stroke=150.0,
                                 description="sliding-joint hexapod on six vertical rails, illustrative dimensions "
                                 "(legs 200 mm, stroke 150 mm)")


def symmetric_hexapod(
    base_radius: float = 152.5,
    platform_radius: float = 70.0,
    base_separation: float = 30.0,
    platform_separation: float = 30.0,
    phase: float = 195.0,
    offset: float = 305.0,
    stroke: float = 50.0,
    u_joint_tilt: float | None = 45.0,
    s_joint_tilt: float | None = 29.0,
    leg_diameter: float | None = None,
    name: str | None = None,
) -> Hexapod:
    """A hexapod with 3-fold symmetric joint pairs (angles in degrees, lengths in mm).

    Base pair k (k = 0, 1, 2) is centred at θ_k = phase + 120k; its legs 2k+1 and 2k+2 have
    base joints at θ_k ∓ base_separation/2 and platform joints at
    θ_k ∓ (60 − platform_separation/2). ``platform_separation = 0`` gives a 3-6 hexapod
    (platform joints shared pairwise). The defaults reproduce ``stewart-prototype``.
    """
    base, plat = [], []
    for k in range(3):
        th = phase + 120.0 * k
        for sign in (-1.0, 1.0):
            tb = np.deg2rad(th + sign * base_separation / 2)
            tp = np.deg2rad(th + sign * (60.0 - platform_separation / 2))
            base.append([base_radius * np.cos(tb), base_radius * np.sin(tb), 0.0])
            plat.append([platform_radius * np.cos(tp), platform_radius * np.sin(tp), 0.0])
    deg = lambda v: None if v is None else np.deg2rad(v)  # noqa: E731
    return Hexapod(
        name=name or (f"symmetric:base_radius={base_radius:g},platform_radius={platform_radius:g},"
                      f"base_separation={base_separation:g},platform_separation={platform_separation:g}"),
        base=np.array(base),
        platform=np.array(plat),
        offset=np.full(6, float(offset)),
        stroke=np.tile([0.0, float(stroke)], (6, 1)),
        limits=HexapodLimits(u_joint_tilt=deg(u_joint_tilt), s_joint_tilt=deg(s_joint_tilt), leg_diameter=leg_diameter),
        description="symmetric hexapod generated from radii and pair separation angles",
    )


#: Built-in machines by name → (factory, one-line description).
_FACTORIES: dict[str, Callable[[], Mechanism]] = {
    "stewart-prototype": stewart_prototype,
    "stewart-prototype-real": stewart_prototype_real,
    "planar-2dof-3act": planar_2dof_3act,
    "planar-3dof-4act": planar_3dof_4act,
    "kossel-mini": kossel_mini,
    "delta-picker": delta_picker,
    "servo-stewart": lambda: servo_stewart(),
    "hexaslide": lambda: hexaslide(),
}
#: name → (factory, description); the names, kinds and descriptions are those of
#: :data:`pkmcal.mechanisms.catalogue.BUILTIN_CATALOGUE`.
BUILTIN_MACHINES: dict[str, tuple[Callable[[], Mechanism], str]] = {
    name: (_FACTORIES[name], text) for name, (_, text) in BUILTIN_CATALOGUE.items()}

DEFAULT_MACHINE = "stewart-prototype"


#: What each ``symmetric:`` key must be: (test, the rule in words).
_SYMMETRIC_RULES: dict[str, tuple[Callable[[float], bool], str]] = {
    "base_radius": (lambda v: v >= 1e-3, "a radius of at least 0.001 mm"),
    "platform_radius": (lambda v: v >= 1e-3, "a radius of at least 0.001 mm"),
    "base_separation": (lambda v: 0 <= v < 120, "an angle in [0, 120) degrees"),
    "platform_separation": (lambda v: 0 <= v < 120, "an angle in [0, 120) degrees"),
    "phase": (lambda v: True, "an angle (degrees)"),
    "offset": (lambda v: v >= 1e-3, "a leg offset of at least 0.001 mm"),
    "stroke": (lambda v: v >= 1e-3, "a stroke of at least 0.001 mm"),
    "u_joint_tilt": (lambda v: 0 < v <= 180, "a tilt limit in (0, 180] degrees, or none"),
    "s_joint_tilt": (lambda v: 0 < v <= 180, "a tilt limit in (0, 180] degrees, or none"),
    "leg_diameter": (lambda v: v >= 0, "a diameter >= 0 (mm), or none"),
}
#: Keys that may be switched off with ``none``/``off``.
_OPTIONAL = ("u_joint_tilt", "s_joint_tilt", "leg_diameter")
#: Largest accepted magnitude of a ``symmetric:`` value (mm or degrees): larger is no machine.
_MAX_VALUE = 1e6


def _parse_symmetric(spec: str) -> Hexapod:
    if not spec.isprintable():
        raise PkmcalError(f"machine {spec!r}: holds control characters; write the spec on one line")
    body = spec[len(SYMMETRIC_PREFIX):]
    kwargs: dict[str, float | None] = {}
    allowed = sorted(_SYMMETRIC_RULES)
    for item in filter(None, body.split(",")):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or key not in _SYMMETRIC_RULES:
            raise PkmcalError(f"machine '{spec}': '{item}' is not KEY=VALUE with KEY one of {', '.join(allowed)}")
        if key in kwargs:
            raise PkmcalError(f"machine '{spec}': '{key}' is given twice; give each key once")
        rule, words = _SYMMETRIC_RULES[key]
        text = value.strip()
        if text.lower() in ("none", "off"):
            if key not in _OPTIONAL:
                raise PkmcalError(f"machine '{spec}': '{key}' cannot be {text}; it must be {words}")
            kwargs[key] = None
            continue
        try:
            if "_" in text:
                raise ValueError(text)
            number = float(text)
        except ValueError:
            raise PkmcalError(f"machine '{spec}': value of '{key}' is not a number: '{value}'") from None
        if not np.isfinite(number):
            raise PkmcalError(f"machine '{spec}': {key}={text} is not a finite number; it must be {words}")
        if abs(number) > _MAX_VALUE:
            raise PkmcalError(f"machine '{spec}': {key}={text} is beyond ±{_MAX_VALUE:g}, larger than any machine; "
                              f"it must be {words}")
        if not rule(number):
            raise PkmcalError(f"machine '{spec}': {key}={text} is not {words}")
        kwargs[key] = number
    return symmetric_hexapod(**kwargs, name=spec)


def builtin_machine(name: str) -> Mechanism:
    """The built-in machine called ``name``; a clear error listing the names otherwise."""
    if name.startswith(SYMMETRIC_PREFIX):
        return _parse_symmetric(name)
    try:
        factory, _ = BUILTIN_MACHINES[name]
    except KeyError:
        raise PkmcalError(
            f"unknown machine '{name}': not a file and not a built-in machine "
            f"({', '.join(BUILTIN_MACHINES)}, or symmetric:KEY=VALUE,...); run 'pkmcal machines'"
        ) from None
    return factory()


def is_builtin_name(name: str) -> bool:
    return name in BUILTIN_MACHINES or name.startswith(SYMMETRIC_PREFIX)
