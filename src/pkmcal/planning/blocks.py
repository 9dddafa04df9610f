"""Per-pose identification Jacobian blocks G_j for planning, from the identification engine.

For a machine + measurement setup, candidate pose x_j is simulated as measured at the
nominal machine (q_j = IK(x_j, ρ₀), y_j = h(x_j, s₀)) and the engine's method
(:mod:`pkmcal.identification.residuals`: ``ik-residual`` for a full-pose sensor, paper 1;
``fk-residual`` otherwise, paper 2; ``projection`` for redundantly actuated machines, paper 3) gives its residual Jacobian J_j = ∂r_j/∂θ and the
covariance Σ_j that the noise induces on r_j. The block is

    G_j = W_j J_j[:, free] D,    W_j = L_j⁻¹ (L_j L_jᵀ = Σ_j),    D = diag(d_i)

* **free** — the candidate parameters (:func:`~pkmcal.identification.engine.candidate_parameters`:
  machine parameters + the sensor's default free ones) less the gauge that
  :func:`~pkmcal.identification.identifiability.analyse_jacobian` suggests on a
  *reference* pose set, i.e. the identifiable parameters;
* **D** — column scaling d_i = 1 / RMS_j ‖W_j J_j[:, i]‖ over the reference poses (unit
  RMS column norm per pose), so indices do not depend on the parameters' units.

The reference set (256 random reachable, measurable poses of the workspace box, seed 0)
depends only on the machine and setup, so ``plan`` and ``observability`` use the same
parameters and scaling and agree on the indices of a pose set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.identifiability import IdentifiabilityReport, analyse_jacobian
from pkmcal.identification.residuals import (  # noqa: F401  (default_method: re-exported, the one rule)
    Model,
    candidate_parameters,
    default_method,
    make_method,
    whitening,
)
from pkmcal.mechanisms.base import Mechanism
from pkmcal.planning.indices import blas_single_threaded
from pkmcal.sensors.base import MeasurementSetup

N_REFERENCE = 256


def raw_blocks(mechanism: Mechanism, setup: MeasurementSetup, poses: np.ndarray, method: str,
               weighted: bool = True, columns: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Whitened residual Jacobians W_j J_j (N, k, P) of all parameters at the nominal machine
    (J_j itself when not ``weighted``), a converged flag (N,) and the parameter names.

    ``columns``: only these columns of θ = [ρ; s] (N, k, len(columns)), the same numbers as
    those columns of all P (whitening mixes rows, not columns); the sensor parameters'
    columns are not computed when none of them is asked for, as the engine skips them when
    none is free."""
    poses = mechanism.as_pose_array(poses)
    model = Model(mechanism, setup.sensor, setup.noise, mechanism.ik(poses),
                  setup.sensor.predict(mechanism.frame(poses)), commanded=poses)
    evaluator = make_method(method, model, weighted=weighted)
    if columns is not None:
        evaluator.sensor_columns = bool(np.any(np.asarray(columns) >= model.n_mech))
    ev = evaluator.evaluate(model.theta0, jac=True, cov=weighted)
    W = whitening(ev.cov, f"{method} residual") if weighted and method != "projection" else None
    J = ev.J if W is None else W @ ev.J    # NaN sensor columns stay in their own columns
    return (J if columns is None else J[:, :, columns]), ev.converged, model.names


@dataclass(frozen=True)
class PlanningModel:
    """What :meth:`blocks` needs: machine, setup, method, the identifiable parameters
    ``names`` (their indices ``free_index`` in θ = [ρ; s]), column scales ``scale``, the
    identifiability ``report`` of the reference set (module docstring) and the residual
    rows per pose k of a block."""

    mechanism: Mechanism
    setup: MeasurementSetup
    method: str
    names: tuple[str, ...]
    free_index: np.ndarray
    scale: np.ndarray
    report: IdentifiabilityReport
    rows_per_pose: int

    @property
    def n_params(self) -> int:
        return len(self.names)

    @blas_single_threaded
    def blocks(self, poses: np.ndarray, out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """G (N, k, n) of ``poses`` (module docstring) and a flag (N,) of poses whose
        nuisance pose was solved (FK converged); G written into ``out`` when given."""
        J, ok, _ = raw_blocks(self.mechanism, self.setup, poses, self.method, columns=self.free_index)
        return np.multiply(J, self.scale, out=out), ok


@blas_single_threaded
def planning_model(mechanism: Mechanism, setup: MeasurementSetup, *, method: str | None = None,
                   reference: np.ndarray | None = None, free=None) -> PlanningModel:
    """The identifiable parameters and their scaling for planning (module docstring).

    ``reference`` poses default to :data:`N_REFERENCE` random checked poses of the
    workspace box (seed 0) of the machine within what its geometry reaches
    (:meth:`~pkmcal.mechanisms.base.Mechanism.within_geometry`, as the plan's candidates);
    ``free`` restricts the candidate parameters (names/patterns).
    """
    from pkmcal.planning.candidates import generate_candidates

    method = method or default_method(setup, mechanism)
    if reference is None:
        reference = generate_candidates(mechanism.within_geometry()[0], setup, kind="random", n=N_REFERENCE,
                                        rng=np.random.default_rng(0)).poses
    J, ok, names = raw_blocks(mechanism, setup, reference, method)
    J = J[ok]
    model = Model(mechanism, setup.sensor, setup.noise, mechanism.ik(reference[:1]),
                  setup.sensor.predict(mechanism.frame(reference[:1])))
    cand, _ = candidate_parameters(model, free, None)
    rows = J.reshape(-1, J.shape[-1])[:, cand]
    report = analyse_jacobian(rows, tuple(names[i] for i in cand), tuple(mechanism.param_names))
    keep = [i for i in cand if names[i] not in report.fixed and names[i] not in report.unseen]
    if not keep:
        raise PkmcalError("no identifiable parameter: the sensor sees none of the machine's parameters")
    col = np.sqrt(np.sum(J[:, :, keep] ** 2, axis=(0, 1)) / len(J))
    scale = 1.0 / np.where(col > 0, col, 1.0)
    return PlanningModel(mechanism, setup, method, tuple(names[i] for i in keep), np.array(keep), scale, report,
                         J.shape[1])
