"""ISO 230-4 circular-test figures from a ballbar's readings, with their GUM uncertainty.

The circle test (``pkmcal plan --algorithm circle``, :meth:`~pkmcal.sensors.distance.DistanceSensor.circle_frames`)
commands the ball around pivot 1 on a circle of nominal radius R in a base-frame plane,
at angles φ_j; the ballbar reads r_j = d_j − ℓ, the radial deviation of the ball from the
nominal circle centred at the pivot (ℓ the bar's calibrated length; with ℓ = 0 the
distance less R). The figures (ISO 230-4:2005, §3, as we read it; one direction of travel):

    F_max = max_j r_j,   F_min = min_j r_j                          radial deviation
    G = max_j ρ_j − min_j ρ_j,   ρ = r − (r₀ + a cos φ + b sin φ)       circular deviation

with (r₀, a, b) the least-squares circle: to first order in the centre's offset (a, b)/R,
the radial distance from a centre moved by (a, b) is r − a cos φ − b sin φ, so the
least-squares circle is the linear least-squares fit of (1, cos φ, sin φ) and ρ = (I − P) r,
P its projector; G is the radial separation of the two circles about the fitted centre that
enclose the path. Circular hysteresis H needs the path in both directions, which the
circle plan does not run.

**Uncertainty** (GUM first order, k = 2). The readings' noise σ (the setup's
``noise.reading``), independent per reading; at the extreme readings j⁺, j⁻ (held where
they are: a noise much smaller than the path's shape does not move them)

    ∂F_max/∂r = e_{j⁺},   ∂G/∂r = (I − P)(e_{j⁺} − e_{j⁻}),   U = 2 σ ‖g‖.

An extreme of noisy readings is biased upwards where several readings are near it; the
figures are flagged ``noise-limited`` when the second-largest ρ (or r) is within 2σ of the
largest (first order does not hold there).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.iso9283 import COVERAGE_FACTOR, Figure
from pkmcal.mechanisms.base import Mechanism


def circle_angles(mechanism: Mechanism, sensor, commanded: np.ndarray, *, rtol: float = 1e-6) -> np.ndarray | str:
    """The angles φ_j (N,) of the ball about pivot 1 when the ``commanded`` poses are a circle
    test of ``sensor`` (a ballbar with one pivot: every ball position at the bar's nominal
    radius in a base-frame plane through the pivot, at least 8 poses); otherwise why not."""
    if "circle-test" not in sensor.abilities:
        return f"the '{sensor.kind}' instrument runs no circle test"
    names = list(sensor.param_names)
    theta = np.asarray(sensor.params, dtype=float)
    t = theta[[names.index(f"ball.{c}") for c in "xyz"]]
    c = theta[[names.index(f"pivot1.{k}") for k in "xyz"]]
    f = mechanism.frame(np.asarray(commanded, dtype=float))
    v = f.p + np.einsum("nij,j->ni", f.R, t) - c
    if len(v) < 8:
        return f"{len(v)} poses: a circle test has at least 8"
    for plane, (i, j) in sensor.CIRCLE_PLANES.items():
        k = 3 - i - j
        r = np.hypot(v[:, i], v[:, j])
        if np.ptp(v[:, k]) <= rtol * r.max() and np.ptp(r) <= rtol * r.max():
            return np.arctan2(v[:, j], v[:, i])
    return "the ball positions are not on one circle about pivot 1 in a base-frame plane"


@dataclass(frozen=True)
class CircleReport:
    """The ISO 230-4 figures (:class:`~pkmcal.identification.iso9283.Figure`, pose "circle")."""

    figures: tuple[Figure, ...]
    n_points: int
    uncertainty: str
    #: the key of ``verify --json`` that holds it
    json_key = "iso230_4"

    def get(self, name: str) -> Figure:
        return next(f for f in self.figures if f.name == name)

    def to_dict(self) -> dict:
        return {"standard": "ISO 230-4 circular test (one direction): radial deviation F, circular deviation G",
                "points": self.n_points, "coverage_factor": COVERAGE_FACTOR, "uncertainty": self.uncertainty,
                "figures": [f.to_dict() for f in self.figures]}

    def format_table(self) -> str:
        lines = [f"ISO 230-4 circular test ({self.n_points} points, one direction): value +- U (k = 2)"]
        for f in self.figures:
            lines.append(f"  {f.name:6s} {1e3 * f.value:9.2f} +- {1e3 * f.U:.2f} µm" + (f" ({f.note})" if f.note else ""))
        lines.append(f"  uncertainty: {self.uncertainty}")
        return "\n".join(lines)


def circle_figures(angles: np.ndarray, readings: np.ndarray, sigma: float, uncertainty: str = "") -> CircleReport:
    """F_max, F_min and G (module docstring) of the radial deviations ``readings`` (N,) (mm)
    at ball ``angles`` (N,) (rad), with U from the readings' σ (mm)."""
    phi = np.asarray(angles, dtype=float)
    r = np.asarray(readings, dtype=float)
    if r.shape != phi.shape or r.ndim != 1:
        raise PkmcalError("a circle test's readings and angles are one value per point")
    X = np.stack([np.ones_like(phi), np.cos(phi), np.sin(phi)], axis=1)
    Q, _ = np.linalg.qr(X)
    resid = np.eye(len(r)) - Q @ Q.T                                   # I − P
    rho = resid @ r
    figs = []
    for name, values, sign, proj in (("F_max", r, 1.0, None), ("F_min", r, -1.0, None), ("G", rho, None, resid)):
        if sign is not None:
            j = int(np.argmax(sign * values))
            g = np.zeros(len(r))
            g[j] = 1.0
            value = float(values[j])
            second = np.sort(sign * values)[-2]
            close = sign * value - second < 2 * sigma
        else:
            jp, jm = int(np.argmax(values)), int(np.argmin(values))
            g = proj @ (np.eye(len(r))[jp] - np.eye(len(r))[jm])
            value = float(values[jp] - values[jm])
            srt = np.sort(values)
            close = (srt[-1] - srt[-2] < 2 * sigma) or (srt[1] - srt[0] < 2 * sigma)
        U = COVERAGE_FACTOR * sigma * float(np.linalg.norm(g))
        figs.append(Figure(name, "circle", value, U, "mm", "noise-limited" if close else ""))
    return CircleReport(tuple(figs), len(r), uncertainty)


def heldout_circle(mechanism: Mechanism, setup, measurements) -> CircleReport | None:
    """The ISO 230-4 figures of held-out ballbar readings whose commanded poses (``cmd_*``
    columns) are a circle test of the setup's bar: the first reading of every row (pivot 1)
    less the bar's nominal radius when its length is 0. None when they are not one."""
    if measurements.commanded is None or "circle-test" not in setup.sensor.abilities:
        return None
    phi = circle_angles(mechanism, setup.sensor, measurements.commanded)
    if isinstance(phi, str):
        return None
    names = list(setup.sensor.param_names)
    length = float(setup.sensor.params[names.index("length1")])
    r = np.asarray(measurements.readings, dtype=float)[:, 0]
    if length == 0.0:                     # absolute distances: the nominal radius is the commanded one
        t = setup.sensor.params[[names.index(f"ball.{c}") for c in "xyz"]]
        c = setup.sensor.params[[names.index(f"pivot1.{k}") for k in "xyz"]]
        f = mechanism.frame(measurements.commanded)
        r = r - np.linalg.norm(f.p + np.einsum("nij,j->ni", f.R, t) - c, axis=1)
    sigma = float(np.atleast_1d(np.asarray(setup.noise.reading_std, dtype=float))[0])
    return circle_figures(phi, r, sigma, f"GUM first order, k = 2, from the bar's noise (the setup's noise.reading "
                                         f"sigma {sigma:.3g} mm); G about the least-squares centre")


