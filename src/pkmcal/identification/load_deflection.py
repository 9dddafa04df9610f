"""What a redundant machine's following errors say about its deflection under load (paper 3 §2).

At equilibrium Γᵀ K e = J_fᵀ F (:mod:`pkmcal.mechanisms.statics`), e = q̂ − c the following
errors. The part of e along Γ, (ΓᵀΓ)⁻¹ Γᵀ e, is the pose deflection, and

    d_j = J_f (ΓᵀΓ)⁻¹ Γᵀ e_j

the tool deflection (:func:`load_deflection_estimate`); :func:`compliance_warning` is the
identify report's warning when it exceeds twice the tracker noise.
"""

from __future__ import annotations

import numpy as np

from pkmcal.mechanisms.base import Mechanism


def load_deflection_estimate(mechanism: Mechanism, sensor, poses: np.ndarray, following_errors: np.ndarray) -> np.ndarray:
    """Tool deflection (N, 2) (mm) implied by the measured following errors e_j = q̂_j − c_j at
    the rest poses ``poses`` (N, n): d_j = J_f (ΓᵀΓ)⁻¹ Γᵀ e_j.

    At equilibrium Γᵀ K e = J_fᵀ F (:mod:`pkmcal.mechanisms.statics`). With equal actuator
    stiffness K = k I the part of e along Γ is then exactly the linear load deflection
    dx = (ΓᵀKΓ)⁻¹ J_fᵀ F, whatever the actuators' conflict (which lies in the null space of
    Γᵀ); with unequal stiffness it is an estimate whose error is the conflict's leak into the
    range of Γ. No stiffness is needed: the data say how far the machine gave way."""
    x = mechanism.as_pose_array(poses)
    G = mechanism.actuator_pose_jacobian(x)
    e = np.asarray(following_errors, dtype=float)
    dx = np.linalg.solve(np.swapaxes(G, 1, 2) @ G, np.einsum("nli,nl->ni", G, e)[..., None])[..., 0]
    Jf = mechanism.pose_jacobian_from_twist(sensor.tool_frame_jacobian(mechanism.frame(x)), x)
    return np.einsum("nki,ni->nk", Jf, dx)


def compliance_warning(nominal: Mechanism, calibrated: Mechanism, sensor, commanded: np.ndarray, rest_poses: np.ndarray,
                       tracker_std: float) -> str | None:
    """A warning when a redundant machine visibly deflected under its load during calibration
    (:func:`load_deflection_estimate` at the rest poses of a projection fit, following
    errors IK(x*, ρ̂) − IK(x_c, ρ_nom)); None when the largest deflection is below twice the
    tracker noise."""
    with np.errstate(invalid="ignore"):
        e = calibrated.ik(rest_poses) - nominal.ik(commanded)
    d = np.linalg.norm(load_deflection_estimate(calibrated, sensor, rest_poses, e), axis=1)
    if not np.any(np.isfinite(d)) or np.nanmax(d) <= 2.0 * tracker_std:
        return None
    return (f"the machine deflected under its load by up to {np.nanmax(d):.3g} mm (mean {np.nanmean(d):.3g} mm) "
            "during calibration, as its following errors show (their part along the pose Jacobian, exact for "
            "equal actuator stiffness); no kinematic calibration removes that deflection: the projection model "
            "keeps it at this load, a fit that ignores the redundancy absorbs it into the parameters and looks "
            "better at this load only (docs/redundant-machines.md, load and compliance)")
