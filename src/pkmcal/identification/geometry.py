"""Readable geometry: what an identification changed in the machine, free of the gauge.

The automatic gauge fixes some parameters and lets the others absorb the rest of the
unidentifiable motions, so the raw estimates of joint coordinates can move by far more
than the machine did (a whole joint set shifted by a rigid motion that no measurement can
see). Issue 11 item 8: besides the gauge values, show quantities the gauge cannot change.

**Best rigid alignment.** For each point set a mechanism declares
(:attr:`~pkmcal.mechanisms.base.Mechanism.point_sets`: the hexapod's base joints b_i and
platform joints a_i), the rotation R and translation t minimising Σ_i ‖R p_i + t − p⁰_i‖²
(calibrated points p_i onto nominal p⁰_i; Kabsch, :meth:`scipy.spatial.transform.Rotation.align_vectors`
on the centred sets) are removed; what is left, d_i = R p_i + t − p⁰_i, is how the joints
moved relative to each other. To first order d = (I − P) δ, δ = p − p⁰ (3k,), with P the
orthogonal projector onto the rigid motions of the nominal set (δ_i = v + ω × p⁰_i, six
columns); its covariance is (I − P) Σ_δ (I − P)ᵀ, which is how the σ of d are computed
from the machine's parameter covariance (the one written in the machine file).

**Invariants.** Joint-to-joint distances within a set, d_ij = ‖p_i − p_j‖, with
σ² = gᵀ Σ g, g = ∂d_ij/∂(p_i, p_j) = (u, −u), u the unit vector from p_j to p_i; and, for
machines with leg lengths, the leg lengths at the nominal machine's home readings
(L_i = the calibrated machine's length at the readings that put the nominal machine at
home: readings are physical, so no gauge enters).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.mechanisms.base import Mechanism


@dataclass(frozen=True)
class AlignedSet:
    """One point set after the best rigid alignment onto nominal (mm; module docstring).

    ``labels`` (k,) the points; ``nominal``, ``aligned`` (k, 3) the nominal points and the
    calibrated ones after alignment; ``moved`` (k, 3) = aligned − nominal with its 1σ
    ``moved_std`` (k, 3) (None without a covariance); ``rotation_deg`` and
    ``translation_mm`` the size of the rigid motion removed (gauge and real rigid motion
    alike); pairwise distances in ``distances``."""

    name: str
    labels: tuple[str, ...]
    nominal: np.ndarray
    aligned: np.ndarray
    moved: np.ndarray
    moved_std: np.ndarray | None
    rotation_deg: float
    translation_mm: float
    distances: tuple["Distance", ...]

    @property
    def moved_norm(self) -> np.ndarray:
        return np.linalg.norm(self.moved, axis=1)

    def to_dict(self) -> dict:
        return {
            "set": self.name,
            "rigid_motion_removed": {"rotation_deg": self.rotation_deg, "translation_mm": self.translation_mm},
            "points": [
                {"point": lab, "moved_mm": self.moved[i].tolist(),
                 "moved_std_mm": None if self.moved_std is None else self.moved_std[i].tolist(),
                 "moved_norm_mm": float(self.moved_norm[i])}
                for i, lab in enumerate(self.labels)
            ],
            "moved_rms_mm": float(np.sqrt(np.mean(self.moved_norm ** 2))),
            "distances": [d.to_dict() for d in self.distances],
        }


@dataclass(frozen=True)
class Distance:
    """A gauge-invariant length (mm): ``nominal``, ``calibrated`` and the 1σ of the latter."""

    name: str
    nominal: float
    calibrated: float
    std: float | None

    @property
    def change(self) -> float:
        return self.calibrated - self.nominal

    def to_dict(self) -> dict:
        return {"name": self.name, "nominal_mm": self.nominal, "calibrated_mm": self.calibrated,
                "change_mm": self.change, "std_mm": self.std}


@dataclass(frozen=True)
class ReadableGeometry:
    """The gauge-free view of an identified machine (module docstring)."""

    sets: tuple[AlignedSet, ...]
    leg_lengths_at_home: tuple[Distance, ...]
    covariance: str | None

    def to_dict(self) -> dict:
        return {
            "note": "gauge-free: joint sets after the best rigid alignment onto nominal, joint-to-joint "
                    "distances, leg lengths at the nominal home readings; mm",
            "covariance": self.covariance,
            "sets": [s.to_dict() for s in self.sets],
            "leg_lengths_at_home": [d.to_dict() for d in self.leg_lengths_at_home],
        }

    def format(self) -> str:
        """The fit summary's lines (empty when the machine declares no point sets)."""
        if not self.sets and not self.leg_lengths_at_home:
            return ""
        sig = "" if self.covariance is None else f"; ±1σ of {self.covariance}"
        lines = [f"geometry without the gauge (best rigid alignment onto nominal, mm{sig}):"]
        for s in self.sets:
            worst = int(np.argmax(s.moved_norm))
            lines.append(f"  {s.name}: rigid motion removed {s.translation_mm:.4g} mm, {s.rotation_deg:.4g}°; "
                         f"joints moved rms {np.sqrt(np.mean(s.moved_norm ** 2)):.4g}, max "
                         f"{s.moved_norm[worst]:.4g} ({s.labels[worst]})")
            for i, lab in enumerate(s.labels):
                parts = []
                for k, axis in enumerate("xyz"):
                    v = f"{axis} {s.moved[i, k]:+.4f}"
                    if s.moved_std is not None:
                        v += f" ±{s.moved_std[i, k]:.4f}"
                    parts.append(v)
                lines.append(f"    {lab}  " + "  ".join(parts))
            if s.distances:
                d = max(s.distances, key=lambda d: abs(d.change))
                lines.append(f"    joint-to-joint distances: largest change {d.change:+.4f}"
                             + ("" if d.std is None else f" ±{d.std:.4f}") + f" ({d.name})")
        if self.leg_lengths_at_home:
            lines.append("  leg lengths at the nominal home readings: "
                         + ", ".join(f"{d.name} {d.calibrated:.4f} ({d.change:+.4f}"
                                     + ("" if d.std is None else f" ±{d.std:.4f}") + ")"
                                     for d in self.leg_lengths_at_home))
        return "\n".join(lines)


def rigid_motion_basis(points: np.ndarray) -> np.ndarray:
    """(3k, 6): the columns δ = v + ω × p⁰_i for unit v (3) and unit ω (3)."""
    k = len(points)
    B = np.zeros((k, 3, 6))
    B[:, :, 0:3] = np.eye(3)
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    # ω × p = −[p]× ω
    B[:, 0, 4], B[:, 0, 5] = z, -y
    B[:, 1, 3], B[:, 1, 5] = -z, x
    B[:, 2, 3], B[:, 2, 4] = y, -x
    return B.reshape(3 * k, 6)


def align_rigidly(points: np.ndarray, onto: np.ndarray) -> tuple[np.ndarray, float, float]:
    """``(aligned, rotation_deg, translation_mm)``: ``points`` (k, 3) moved by the rotation
    and translation that bring them closest to ``onto`` in the least-squares sense, and the
    size of that motion (the rotation angle; the translation of the centroid)."""
    from scipy.spatial.transform import Rotation

    c_p, c_o = points.mean(axis=0), onto.mean(axis=0)
    rot, _ = Rotation.align_vectors(onto - c_o, points - c_p)
    aligned = rot.apply(points - c_p) + c_o
    return aligned, float(np.degrees(rot.magnitude())), float(np.linalg.norm(c_o - c_p))


def readable_geometry(nominal: Mechanism, calibrated: Mechanism, covariance_kind: str | None = None) -> ReadableGeometry:
    """The gauge-free view of ``calibrated`` against ``nominal`` (module docstring); σ from
    ``calibrated.covariance`` (None: no σ), which ``covariance_kind`` names."""
    names = list(calibrated.param_names)
    rho0, rho = nominal.params, calibrated.params
    cov = calibrated.covariance
    sets = []
    for set_name, labels in calibrated.point_sets.items():
        idx = np.array([[names.index(f"{lab}.{a}") for a in "xyz"] for lab in labels])
        p0, p = rho0[idx], rho[idx]
        aligned, angle, shift = align_rigidly(p, p0)
        moved = aligned - p0
        moved_std = None
        S = None
        if cov is not None:
            S = cov[np.ix_(idx.ravel(), idx.ravel())]
            B = rigid_motion_basis(p0)
            Q, _ = np.linalg.qr(B)
            M = np.eye(len(S)) - Q @ Q.T
            moved_std = np.sqrt(np.clip(np.diag(M @ S @ M.T), 0.0, None)).reshape(-1, 3)
        dists = []
        for i in range(len(labels)):
            for j in range(i + 1, len(labels)):
                diff = p[i] - p[j]
                d = float(np.linalg.norm(diff))
                std = None
                if S is not None and d > 0:
                    g = np.zeros(3 * len(labels))
                    g[3 * i:3 * i + 3], g[3 * j:3 * j + 3] = diff / d, -diff / d
                    std = float(np.sqrt(max(g @ S @ g, 0.0)))
                dists.append(Distance(f"{labels[i]}–{labels[j]}", float(np.linalg.norm(p0[i] - p0[j])), d, std))
        sets.append(AlignedSet(set_name, tuple(labels), p0, aligned, moved, moved_std, angle, shift, tuple(dists)))
    legs: tuple[Distance, ...] = ()
    if "leg-lengths" in calibrated.abilities:
        legs = _leg_lengths_at_home(nominal, calibrated, cov)
    return ReadableGeometry(tuple(sets), legs, covariance_kind if cov is not None else None)


def _leg_lengths_at_home(nominal: Mechanism, calibrated: Mechanism, cov) -> tuple[Distance, ...]:
    """Leg lengths of both machines at the readings λ that put the nominal one at home:
    L = the machine's ``lengths_from_readings(λ)`` (the hexapod: L0 + g λ), linear in ρ, so
    its σ is √(gᵀ Σ g) with g = ``lengths_from_readings_param_jacobian(λ)``, exactly."""
    q = nominal.ik(np.asarray(nominal.home_pose, dtype=float)[None, :])
    L0 = nominal.lengths_from_readings(q)[0]
    L = calibrated.lengths_from_readings(q)[0]
    std = [None] * len(L)
    if cov is not None:
        G = calibrated.lengths_from_readings_param_jacobian(q)[0]
        std = np.sqrt(np.clip(np.einsum("ip,pq,iq->i", G, cov, G), 0.0, None)).tolist()
    return tuple(Distance(f"L{i + 1}", float(L0[i]), float(L[i]), std[i]) for i in range(len(L)))
