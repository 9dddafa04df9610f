"""One trial of a study: draw a real machine, measure the planned poses, identify, verify.

For trial t of campaign c (machine m × setup s × plan p × pose count n):

1. real machine: the study's fixed one, or nominal + the error model drawn from the
   generator of key (20, m, t) — the same real machine for every setup, plan and method of
   trial t (paired comparisons: differences between configurations are not blurred by
   different machines);
2. poses: the campaign's one selection (plan ``resample: once``) or a new selection from
   the campaign's candidate pool drawn from the generator of key (21, m, s, p, n, t), which
   then draws the noise (:func:`pkmcal.identification.simulation.simulate_campaign`);
3. every method identifies the parameters (:func:`pkmcal.identification.engine.identify`)
   from the same simulated campaign; the noise-weighted ik-residual fits of the trials of a
   batch together (:func:`pkmcal.identification.batched.identify_batch`: the same fit, its
   numbers independent of the batch; the fits it does not do go to ``identify``);
4. the truth θ* the estimate is compared with: θ_real = [ρ_real; s_setup] when every
   parameter that was not estimated (gauge or user-fixed) has its true value at the start;
   otherwise the noise-free fit of the same poses with the same free set (the value the
   estimator tends to as the noise vanishes: the real machine expressed in the fit's gauge,
   or the best the fixed model can do — its rms residual is ``truth_refit_rms``);
5. errors over the free parameters, e = θ̂ − θ*: mean |e|, rms, max (length parameters,
   mm; angle parameters, degrees); coverage with the *reported* covariance C of the free
   parameters (the file covariance max(1, χ²_ν)·C_prior, :mod:`pkmcal.identification.uncertainty`):
   marginal |e_i| ≤ 1.96 σ_i, and the joint ellipsoid eᵀC⁻¹e ≤ χ²_{n_free, 0.95};
6. held-out errors with the nominal and the calibrated model, over the poses both reach,
   compared as ``pkmcal verify --real --compare`` compares them (:func:`heldout_compare`,
   :func:`heldout_errors`): the poses as commanded where the instrument reads the full pose
   in known frames, else what the instrument reads (no gauge can move it); the tool errors
   for a machine that settles at static equilibrium (redundantly actuated, paper 3:
   position = tool point, orientation = plate angle). A measure the comparison or the
   machine does not have is empty (NaN): the orientation and tilt of a delta, the tilt and
   height of a planar machine, the tilt and height of what an instrument reads
   (:func:`absent_columns`).

A setup of pose pairs (a printed object's distances with probe heights) plans its probe
points as its Z probe would, measures them and the object on the machine read as pose pairs
(steps 2–5) and verifies on single poses (step 6): :mod:`pkmcal.study.printed`.

Every generator is ``numpy.random.default_rng(SeedSequence(seed, spawn_key=key))``: a
trial's numbers depend on the seed and its key only, never on which worker runs it, in
which batch, or in which order. A :class:`~pkmcal.errors.PkmcalError` in a trial (e.g. no
held-out pose reachable) makes a row with ``failed = 1`` and the message, not a crash.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.advice import where_read
from pkmcal.identification.engine import IdentificationResult
from pkmcal.identification.simulation import parameter_errors, settles_at_equilibrium, simulate_campaign
from pkmcal.identification.tool_errors import ToolErrors, tool_errors
from pkmcal.identification.verification import (
    PoseErrors,
    aligned_errors,
    pose_errors,
    pose_errors_many,
    sensor_errors,
    transported,
)
from pkmcal.mechanisms.pose_pairs import read_by
from pkmcal.planning.candidates import generate_candidates
from pkmcal.planning.plan import plan_poses
from pkmcal.planning.selection import select, select_random
from pkmcal.identification.baselines import identify_by_method
from pkmcal.sensors.base import MeasurementSetup
from pkmcal.sensors.printed_distance import single_pose_setup
from pkmcal.study import printed
from pkmcal.study.results import HELDOUT_COLUMNS, Z95, column_names, format_row
from pkmcal.study.schema import MachineSpec, Study

#: Keys of the seed sequences (module docstring).
KEY_POOL, KEY_ONCE, KEY_HELDOUT, KEY_REAL, KEY_TRIAL = 10, 11, 12, 20, 21
DEG = float(np.rad2deg(1.0))


def rng_for(seed: int, *key: int) -> np.random.Generator:
    """The generator of ``key`` under the study seed (independent streams per key)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=tuple(int(k) for k in key)))


def seed_for(seed: int, *key: int) -> int:
    """An integer seed for APIs that take one (``plan_poses``), from the same streams."""
    return int(np.random.SeedSequence(seed, spawn_key=tuple(int(k) for k in key)).generate_state(1, np.uint64)[0])


@dataclass(frozen=True)
class Campaign:
    """Machine × setup × plan × pose count, with its poses: ``poses`` the one selection of a
    ``resample: once`` plan, else None (drawn per trial from pool ``pool``); ``methods`` the
    indices of the study's methods that fit it (all, unless a method names its machines or
    setups), whose configurations are numbered from ``first_config`` on."""

    index: int
    machine: int
    setup: int
    plan: int
    n_index: int
    n_poses: int
    pool: int
    poses: np.ndarray | None
    methods: tuple[int, ...] = ()
    first_config: int = 0
    #: per method of ``methods``: what its held-out errors compare (:func:`heldout_compare`)
    compares: tuple[str, ...] = ()

    def configs(self) -> list[tuple[int, int]]:
        """(configuration number, method index) of each of its methods, in method order."""
        return [(self.first_config + j, k) for j, k in enumerate(self.methods)]


@dataclass(frozen=True)
class Context:
    """Everything a worker needs, built once (:func:`prepare`): the study, the campaigns,
    the candidate pools (poses and, for optimising planners re-run per trial, their
    planning blocks) and the held-out poses per machine."""

    study: Study
    campaigns: tuple[Campaign, ...]
    pools: tuple[np.ndarray, ...]
    pool_blocks: tuple[np.ndarray | None, ...]
    heldout: tuple[np.ndarray, ...]
    error_index: tuple[tuple[np.ndarray, ...], ...] = ()
    #: per machine, per setup: the setup bound to the machine (None: not studied with it)
    setups: tuple[tuple[MeasurementSetup | None, ...], ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return column_names(self.study.extra_columns, scale=self.study.reads_pose_pairs)

    @property
    def n_configs(self) -> int:
        """Configurations: campaign × method, over the methods each campaign is fitted with."""
        return sum(len(c.methods) for c in self.campaigns)

    def absent_metrics(self) -> dict[int, tuple[str, ...]]:
        """{config: held-out columns it does not have} (:func:`absent_columns`)."""
        out = {}
        for c in self.campaigns:
            for (config, _), compare in zip(c.configs(), c.compares):
                absent = absent_columns(self.study.machines[c.machine].nominal, compare,
                                        single_pose_setup(self.setup(c)).sensor)
                if absent:
                    out[config] = absent
        return out

    def setup(self, campaign: Campaign) -> MeasurementSetup:
        """The setup of ``campaign``, bound to its machine."""
        if self.setups:
            return self.setups[campaign.machine][campaign.setup]
        return self.study.setups[campaign.setup].setup


def prepare(study: Study, progress=None) -> Context:
    """Plan everything that does not change between trials (module docstring of
    :mod:`pkmcal.study.schema`): per machine × setup × plan one candidate pool (poses
    checked on the nominal machine by :func:`pkmcal.planning.plan.plan_poses`), per
    ``once`` plan and pose count one selection, per machine the held-out poses."""
    pools, blocks, campaigns = [], [], []
    heldout = []
    setups = tuple(tuple(study.setup_for(mi, si) for si in range(len(study.setups)))
                   for mi in range(len(study.machines)))
    compared: dict[tuple[int, int, int], str] = {}

    def compare_of(mi: int, si: int, k: int) -> str:
        if (mi, si, k) not in compared:
            compared[mi, si, k] = heldout_compare(study.heldout_compare, study.machines[mi].nominal, setups[mi][si],
                                                  study.methods[k])
        return compared[mi, si, k]

    for mi, m in enumerate(study.machines):
        if study.heldout_file is not None:
            heldout.append(m.nominal.as_pose_array(study.heldout_file))
        else:
            cand = generate_candidates(m.nominal, None, kind="random", n=study.heldout_poses,
                                       rng=rng_for(study.seed, KEY_HELDOUT, mi))
            heldout.append(cand.poses)
    for mi, m in enumerate(study.machines):
        for si, s in enumerate(study.setups):
            setup = setups[mi][si]
            if setup is None:       # not in the machine's 'setups:' list
                continue
            planned = single_pose_setup(setup)     # what a plan's poses are read with (printed: its probe)
            for pi, p in enumerate(study.plans):
                pool_kind = "corners" if p.algorithm == "corners" else "random"
                pool = plan_poses(m.nominal, planned, 1, algorithm=pool_kind, n_candidates=p.candidates,
                                  margin=p.margin, seed=seed_for(study.seed, KEY_POOL, mi, si, pi),
                                  on_bed=False)     # lowered below where the setup says so
                poses = pool.candidates.poses
                if s.on_bed:        # a printer's probe points: where its probe triggers on the bed
                    poses = where_read(m.nominal, planned.sensor, poses)
                need_blocks = p.algorithm not in ("random", "corners")
                G = pool.model.blocks(poses)[0] if need_blocks else None
                pool_index = len(pools)
                pools.append(poses)
                blocks.append(G if p.resample == "trial" else None)
                for ni, n in enumerate(p.poses):
                    if n > len(poses):
                        raise PkmcalError(f"plan '{p.label}' asks for {n} poses but machine '{m.label}' with setup "
                                          f"'{s.label}' has only {len(poses)} reachable, measurable candidates; "
                                          "ask for fewer poses or more candidates")
                    chosen = None
                    if p.resample == "once":
                        rng = rng_for(study.seed, KEY_ONCE, mi, si, pi, ni)
                        if need_blocks:
                            try:
                                sel = select(G, n, algorithm=p.algorithm, index=p.index, rng=rng, positions=poses)
                            except PkmcalError as exc:
                                raise PkmcalError(f"plan '{p.label}' for machine '{m.label}' with setup '{s.label}'"
                                                  + (" (its probe points, planned as for its Z probe alone: the "
                                                     "printed object is Klipper's)" if setup.sensor.reads_pose_pairs
                                                     else "") + f": {exc}") from None
                            chosen = poses[sel.chosen]
                        else:
                            chosen = poses[select_random(len(poses), n, rng)]
                    methods = study.methods_for(mi, si)
                    first = campaigns[-1].first_config + len(campaigns[-1].methods) if campaigns else 0
                    compares = tuple(compare_of(mi, si, k) for k in methods)
                    campaigns.append(Campaign(len(campaigns), mi, si, pi, ni, n, pool_index, chosen, methods, first,
                                              compares))
                    if progress is not None:
                        progress(len(campaigns))
    error_index = tuple(tuple(m.error_index()) for m in study.machines)
    return Context(study, tuple(campaigns), tuple(pools), tuple(blocks), tuple(heldout), error_index, setups)


def real_machine(spec: MachineSpec, seed: int, machine_index: int, trial: int,
                 error_index: tuple[np.ndarray, ...] | None = None):
    """The real machine of a trial (module docstring, step 1); ``error_index`` is
    ``spec.error_index()`` when the caller has it already (:class:`Context`)."""
    if spec.real is not None:
        return spec.real
    rng = rng_for(seed, KEY_REAL, machine_index, trial)
    delta = np.zeros(len(spec.nominal.params))
    for g, idx in zip(spec.errors, spec.error_index() if error_index is None else error_index):
        delta[idx] = parameter_errors(idx.size, g.size, rng, "gaussian" if g.distribution == "normal" else "uniform")
    return spec.nominal.with_params(spec.nominal.params + delta, name=f"{spec.nominal.name}-real-{trial}")


@lru_cache(maxsize=4096)
def chi2_95(dof: int) -> float:
    """χ²_{dof}(0.95), the 95 % quantile of the chi-squared distribution."""
    from scipy.special import chdtri

    return float(chdtri(dof, 0.05))


def _stats(e: np.ndarray, scale: float = 1.0) -> tuple[float, float, float]:
    if e.size == 0:
        return float("nan"), float("nan"), float("nan")
    a = np.abs(e) * scale
    return float(a.mean()), float(np.sqrt(np.mean(a * a))), float(a.max())


def pseudo_truth(fit: IdentificationResult, truth_full: np.ndarray, nominal, setup, sim, method: str, weighted: bool):
    """θ* (module docstring, step 4), whether it is a refit, and the refit's rms residual."""
    fixed = np.ones(len(fit.names), dtype=bool)
    fixed[fit.free_index] = False
    if np.array_equal(truth_full[fixed], fit.initial[fixed]):
        return truth_full, False, 0.0
    noise_free = dataclasses.replace(sim.measurements, actuators=sim.actuator_true, readings=sim.sensor_true)
    ref = fit_campaign(nominal, setup, noise_free, method, weighted, free=fit.free)
    return ref.estimate, True, ref.rms_residual


def fit_campaign(nominal, setup, measurements, method: str, weighted: bool, free=None, fix=None) -> IdentificationResult:
    """Step 3 for one trial: :func:`~pkmcal.identification.engine.identify` by ``method``, or a
    paper 3 baseline for a redundantly actuated machine (``ignore-redundancy``,
    ``actuator-subset``: the engine's ``projection`` fit on the inputs the baseline changes,
    :mod:`pkmcal.identification.baselines`), as ``pkmcal identify --method`` fits it."""
    return identify_by_method(nominal, setup, measurements, method, weighted=weighted, free=free, fix=fix)


def _abs_stats(values: np.ndarray | None, scale: float = 1.0, mask: np.ndarray | None = None) -> tuple[float, float]:
    """(rms, max) of |values[mask]| times ``scale``: the numbers (and operations) of
    :meth:`PoseErrors.summary`'s ``*_rms_*`` and ``*_max_*`` keys, without its other ten;
    NaN for a measure the machine does not have (None)."""
    if values is None:
        return float("nan"), float("nan")
    v = np.abs(values if mask is None else values[mask])
    return float(np.sqrt(np.mean(v**2))) * scale, float(np.max(v)) * scale


def heldout_compare(asked: str, nominal, setup: MeasurementSetup, method) -> str:
    """What the held-out errors of a configuration (machine ``nominal``, its bound ``setup``,
    a :class:`~pkmcal.study.schema.MethodSpec`) compare, as ``pkmcal verify --real --compare``:

    * ``tool`` for a machine that settles at static equilibrium (paper 3): the tool on the
      tracker, the only comparison that machine has;
    * otherwise the study's ``heldout: {compare:}`` (``asked``), where ``auto`` is
      ``commanded`` when the instrument reads the platform pose in known frames (a full-pose
      sensor none of whose parameters the method estimates, paper 1): a gauge then cannot
      move the pose, and the poses as commanded are what the instrument sees; and ``sensor``
      otherwise (dial indicators, a Z probe, a tracker, a full-pose sensor with a free
      frame): the calibration's frames are then a gauge choice, poses as commanded would
      compare frames the gauge made arbitrary (a good calibration would look like a poor
      one), and what the instrument reads is the comparison no gauge can change. Which
      sensor parameters the method estimates is its candidate set on the planning model
      (:func:`~pkmcal.planning.blocks.planning_model`), so the choice depends on the
      configuration only, never on a trial;
    * ``aligned`` for ``auto`` with a sensor of pose pairs (a printed object's distances
      with probe heights, :mod:`pkmcal.study.printed`): no instrument reads the single
      held-out poses but its Z probe, which reads heights only; the nozzle positions after
      the best rigid alignment are the printed geometry whatever its place on the bed, the
      in-plane scale the object is printed for included (``sensor`` on request: the
      probe's heights)."""
    if settles_at_equilibrium(nominal):
        return "tool"          # a Study refuses any other 'compare' for such a machine
    if asked != "auto":
        return asked
    if setup.sensor.reads_pose_pairs:
        return "aligned"
    if setup.sensor.kind != "full-pose":
        return "sensor"
    from pkmcal.planning.blocks import planning_model

    model = planning_model(nominal, setup, method=method.resolved(setup, nominal), free=method.free)
    candidates = set(model.names) | set(model.report.fixed)
    return "sensor" if candidates & set(setup.sensor.param_names) else "commanded"


def heldout_errors(nominal, setup, fits: list, real, heldout: np.ndarray, ignore_limits: tuple[str, ...],
                   compare: str = "commanded") -> list[tuple]:
    """Held-out errors (module docstring, step 6): per fit, (after, before) of the real
    machine commanded through the fit's calibrated model and through the nominal one, as
    ``pkmcal verify --real --compare`` gives them
    (:func:`pkmcal.identification.verification.verify`), ``compare`` from
    :func:`heldout_compare`:

    * ``commanded`` the platform frames as commanded (:func:`pose_errors_many`, one FK for all);
    * ``sensor`` what the setup's instrument reads at the reached pose against what each model
      predicts its own instrument reads ("before" the setup's, "after" the one identified in
      the fit; :func:`~pkmcal.identification.verification.sensor_errors`);
    * ``aligned`` the platform frames after the best rigid alignment of each model's base and
      platform frames, fitted on the poses both models reach
      (:func:`~pkmcal.identification.verification.aligned_errors`);
    * ``tool`` the tool errors of a machine that settles at static equilibrium (redundantly
      actuated, paper 3) with the same instruments as ``sensor``
      (:func:`~pkmcal.identification.tool_errors.tool_errors`).

    With ``sensor`` and ``aligned`` the held-out poses (the nominal machine's frames) are
    carried into each fit's frames first, so that every model commands the same physical
    poses whatever its gauge."""
    if compare == "commanded":
        before, *afters = pose_errors_many((nominal,) + tuple(f.mechanism for f in fits), real, heldout, ignore_limits)
        return [(after, before) for after in afters]
    if compare == "tool":
        before = tool_errors(nominal, setup.sensor, real, setup, heldout, "before", ignore_limits)
        return [(tool_errors(f.mechanism, f.sensor, real, setup, heldout, "after", ignore_limits), before) for f in fits]
    if compare == "sensor":
        before = sensor_errors(nominal, setup.sensor, real, setup.sensor, heldout, ignore_limits)
        return [(sensor_errors(f.mechanism, f.sensor, real, setup.sensor, heldout, ignore_limits, reference=nominal),
                 before) for f in fits]
    cmd = nominal.as_pose_array(heldout)
    raw_before = pose_errors(nominal, real, cmd, ignore_limits)
    out = []
    for f in fits:
        cmd_f = transported(f.mechanism, cmd, nominal)
        after = pose_errors(f.mechanism, real, cmd_f, ignore_limits)
        mask = after.valid & raw_before.valid
        if mask.any():
            after = aligned_errors(after, cmd_f, mask, f.mechanism)[0]
            before = aligned_errors(raw_before, cmd, mask, nominal)[0]
        else:
            before = raw_before
        out.append((after, before))
    return out


def _measures(errors: "PoseErrors | ToolErrors") -> dict:
    """Per held-out pose (N,): position (mm), orientation, tilt (rad), height (mm) errors and
    the reading errors (N, m) of a sensor compared on readings that are no position (mm);
    None for a measure the comparison does not have (:func:`absent_columns`): a delta has no
    orientation (nor tilt), the tool of a planar machine no tilt or height, its plate angle
    is the orientation (none for 2 pose coordinates); what a sensor reads has no tilt or
    height, and is a position (a tracker), a pose (a full-pose sensor) or only readings
    (dial indicators, a Z probe)."""
    if isinstance(errors, ToolErrors):
        angle = None if np.all(np.isnan(errors.angle)) else errors.angle
        return {"position": errors.tool, "orientation": angle, "tilt": None, "height": None, "reading": None}
    return {"position": errors.position, "orientation": errors.orientation, "tilt": errors.tilt,
            "height": errors.height, "reading": errors.reading}


def absent_columns(machine, compare: str = "commanded", sensor=None) -> tuple[str, ...]:
    """The held-out columns that stay empty for ``machine`` compared by ``compare`` (its
    ``sensor`` for ``sensor``): its kind or the comparison has no such error
    (:func:`_measures`); ``summary.csv`` leaves them out for its configurations."""
    from pkmcal.identification.heldout import READS

    absent = []
    if compare == "sensor":
        pos, rot = READS.get(sensor.kind, (None, None))
        absent += ["tilt", "height"] + (["position"] if pos is None else ["reading"]) + \
            (["orientation"] if rot is None else [])
    else:
        absent.append("reading")
        if not any(machine.pose_is_angle):
            absent.append("orientation")
        if compare == "tool":
            absent += ["tilt", "height"]
        elif not any(machine.pose_is_angle):
            absent.append("tilt")
    return tuple(c for c in HELDOUT_COLUMNS if any(f"_{m}_" in c for m in absent))


def heldout_columns(after: "PoseErrors | ToolErrors", before: "PoseErrors | ToolErrors") -> dict:
    """The held-out columns of one fit (module docstring, step 6): errors after and before
    calibration over the poses the real machine reaches through both models; empty (NaN)
    those of a measure the machine does not have (:func:`_measures`)."""
    common = after.valid & before.valid
    out: dict = {"heldout_used": int(common.sum())}
    if not common.any():
        out["message"] = "the real machine reaches none of the held-out poses with both models"
        return out
    for model, suffix in ((after, ""), (before, "_before")):
        e = _measures(model)
        p_rms, p_max = _abs_stats(e["position"], 1.0, common)
        o_rms, o_max = _abs_stats(e["orientation"], DEG, common)
        out[f"heldout_position_rms{suffix}_mm"] = p_rms
        out[f"heldout_orientation_rms{suffix}_deg"] = o_rms
        out[f"heldout_tilt_rms{suffix}_deg"] = _abs_stats(e["tilt"], DEG, common)[0]
        out[f"heldout_height_rms{suffix}_mm"] = _abs_stats(e["height"], 1.0, common)[0]
        out[f"heldout_reading_rms{suffix}_mm"] = _abs_stats(e["reading"], 1.0, common)[0]
        if not suffix:
            out.update(heldout_position_max_mm=p_max, heldout_orientation_max_deg=o_max)
    return out


def evaluate(fit: IdentificationResult, truth_full: np.ndarray, is_angle: np.ndarray, nominal, setup, sim,
             method: str, weighted: bool) -> dict:
    """The parameter and fit columns of one fit (module docstring, steps 4–5)."""
    truth, refit, refit_rms = pseudo_truth(fit, truth_full, nominal, setup, sim, method, weighted)
    free = fit.free_index
    e = fit.estimate[free] - truth[free]
    ang = is_angle[free]
    rep = fit.identifiability
    u = fit.uncertainty
    out = {"poses_measured": len(sim.kept), "n_free": len(free), "rank": rep.rank, "n_candidates": rep.n_params,
           "gauge": " ".join(fit.gauge), "condition": rep.condition_number, "chi2": u.chi2, "dof": u.dof,
           "reduced_chi2": u.reduced_chi2, "nfev": fit.nfev, "truth_refit": refit, "truth_refit_rms": refit_rms}
    mean, rms, mx = _stats(e[~ang])
    out.update(param_error_mean_abs_mm=mean, param_error_rms_mm=rms, param_error_max_abs_mm=mx,
               param_error_rms_deg=_stats(e[ang], DEG)[1],
               param_error_before_mean_abs_mm=_stats((fit.initial[free] - truth[free])[~ang])[0],
               param_error_vs_real_mean_abs_mm=_stats((fit.estimate[free] - truth_full[free])[~ang])[0])
    C = fit.covariance
    sd = np.sqrt(np.clip(np.diag(C), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(e) / sd
    inside = z <= Z95
    try:
        d2 = float(e @ np.linalg.solve(C, e))
    except np.linalg.LinAlgError:
        d2 = float("nan")
    out.update(coverage_fraction=float(inside.mean()), all_within_95=bool(inside.all()), ellipsoid_d2=d2,
               ellipsoid_within_95=None if not np.isfinite(d2) else bool(d2 <= chi2_95(len(free))),
               error_nsigma_rms=float(np.sqrt(np.mean(z * z))))
    return out


#: Trials whose fits :func:`~pkmcal.identification.batched.identify_batch` solves together
#: (bounded memory: (B, 6 N, n) Jacobians). A fit's numbers do not depend on its batch.
FIT_BATCH = 64


@dataclass
class _Measured:
    """A trial after steps 1–2: its rows (one per method), real machine and simulated campaign."""

    rows: list
    real: object
    sim: object


def _measure(ctx: Context, campaign: Campaign, trial: int) -> "_Measured | list[str]":
    """Steps 1–2 (module docstring) of one trial, or its failed lines."""
    st = ctx.study
    mspec, sspec, pspec = st.machines[campaign.machine], st.setups[campaign.setup], st.plans[campaign.plan]
    nominal, setup = mspec.nominal, ctx.setup(campaign)
    base = {"machine": mspec.label, "setup": sspec.label, "plan": pspec.label, "algorithm": pspec.algorithm,
            "n_poses": campaign.n_poses, "plan_resampled": campaign.poses is None, "trial": trial, "failed": False,
            "message": ""}
    rows = [dict(base, config=config, method=st.methods[k].label,
                 identification=st.methods[k].resolved(setup, nominal), weighted=st.methods[k].weighted,
                 heldout_compare=compare)
            for (config, k), compare in zip(campaign.configs(), campaign.compares)]
    try:
        real = real_machine(mspec, st.seed, campaign.machine, trial,
                            ctx.error_index[campaign.machine] if ctx.error_index else None)
        rng = rng_for(st.seed, KEY_TRIAL, campaign.machine, campaign.setup, campaign.plan, campaign.n_index, trial)
        poses = campaign.poses
        if poses is None:
            pool = ctx.pools[campaign.pool]
            G = ctx.pool_blocks[campaign.pool]
            if G is None:
                chosen = select_random(len(pool), campaign.n_poses, rng)
            else:
                chosen = select(G, campaign.n_poses, algorithm=pspec.algorithm, index=pspec.index, rng=rng,
                                positions=pool).chosen
            poses = pool[chosen]
        ignore = mspec.ignore_limits + (printed.bed_limits(nominal) if sspec.on_bed else ())  # probe points on the bed
        if setup.sensor.reads_pose_pairs:   # probe points, then the printed object (study.printed)
            sim = printed.simulate(nominal, real, setup, poses, sspec.object_scale, rng, ignore)
        else:
            sim = simulate_campaign(nominal, real, setup, poses, rng, ignore_limits=ignore)
        if len(sim.kept) == 0:
            raise PkmcalError(f"the real machine reaches none of the {len(poses)} planned poses ({sim.summary()})")
    except PkmcalError as exc:
        return _failed(ctx, rows, exc)
    return _Measured(rows, real, sim)


def _failed(ctx: Context, rows: list, exc: PkmcalError) -> list[str]:
    return [format_row(dict(r, failed=True, message=str(exc)), ctx.names) for r in rows]


def _fit_all(ctx: Context, campaign: Campaign, measured: list[_Measured], k: int) -> list:
    """Step 3 for method ``k`` of every measured trial: the fit or the PkmcalError. The
    weighted ik-residual fits go to :func:`~pkmcal.identification.batched.identify_batch`
    together (when the study has no extra metrics, which are given the engine's result);
    every fit it hands back, and every other fit, to the engine."""
    from pkmcal.identification.batched import batch_applies, identify_batch

    st = ctx.study
    setup = ctx.setup(campaign)
    nominal = read_by(st.machines[campaign.machine].nominal, setup.sensor)   # pose pairs for printed distances
    me = st.methods[k]
    method = me.resolved(setup, nominal)
    fits: list = [None] * len(measured)
    if st.extra_metrics is None and batch_applies(setup, method, me.weighted):
        fits = identify_batch(nominal, setup, [m.sim.measurements for m in measured], free=me.free, fix=me.fix)
    for i, m in enumerate(measured):
        if fits[i] is None:
            try:
                fits[i] = fit_campaign(nominal, setup, m.sim.measurements, method, me.weighted, free=me.free,
                                       fix=me.fix)
            except PkmcalError as exc:
                fits[i] = exc
    return fits


def _verify(ctx: Context, campaign: Campaign, m: _Measured, fitted: list) -> list[str]:
    """Steps 4–6 of one trial from its fits (one per method: a fit or a PkmcalError)."""
    st = ctx.study
    mspec = st.machines[campaign.machine]
    nominal, setup, real, sim = mspec.nominal, ctx.setup(campaign), m.real, m.sim
    fitted_machine = read_by(nominal, setup.sensor)      # what the fits fitted (pose pairs: printed distances)
    truth_full = np.concatenate([real.params, setup.sensor.params])
    is_angle = np.array(tuple(nominal.param_is_angle) + tuple(setup.sensor.param_is_angle), dtype=bool)
    out = [dict(r) for r in m.rows]
    fits = []
    for k, (r, fit) in enumerate(zip(out, fitted)):
        if isinstance(fit, PkmcalError):
            r.update(failed=True, message=str(fit), poses_measured=len(sim.kept))
        else:
            fits.append((k, fit))
    heldout = ctx.heldout[campaign.machine]
    single_setup = single_pose_setup(setup)     # what the setup reads of the single held-out poses
    compared = {}   # k → (after, before): the fits of one comparison share its "before"
    try:
        for compare in dict.fromkeys(campaign.compares[k] for k, _ in fits):
            ks = [k for k, _ in fits if campaign.compares[k] == compare]
            models = [printed.single_pose_fit(fitted[k], setup) for k in ks]
            compared.update(zip(ks, heldout_errors(nominal, single_setup, models, real, heldout, mspec.ignore_limits,
                                                   compare)))
    except PkmcalError as exc:
        return _failed(ctx, m.rows, exc)
    for k, fit in fits:
        r, me = out[k], st.methods[campaign.methods[k]]
        try:
            r.update(evaluate(fit, truth_full, is_angle, fitted_machine, setup, sim, r["identification"], me.weighted))
            r.update(heldout_columns(*compared[k]))
            if st.reads_pose_pairs:     # whether the measurements determine the scale
                r.update(printed.scale_columns(fitted_machine, setup, sim.measurements.commanded, me.free, me.fix))
            if st.extra_metrics is not None:
                r.update(st.extra_metrics(nominal, real, setup, sim, fit, heldout))
        except PkmcalError as exc:
            r.update(failed=True, message=str(exc), poses_measured=len(sim.kept))
    for r in out:
        if r.get("message"):
            r["failed"] = True
    return [format_row(r, ctx.names) for r in out]


def run_trials(ctx: Context, campaign: Campaign, trials) -> list[str]:
    """The CSV lines of trials ``trials`` of ``campaign``, in (trial, method) order.

    Per trial the real machine and the simulated campaign (steps 1–2); then every method
    fits all trials (step 3; the weighted ik-residual fits batched,
    :func:`_fit_all`); then per trial the held-out poses are verified once for the
    nominal model and every calibrated one together (:func:`pose_errors_many`: one FK and
    one limit check of the real machine for all, the same numbers as separate calls) and
    the columns computed (steps 4–6)."""
    done: dict[int, list[str]] = {}
    measured: list[tuple[int, _Measured]] = []
    for t in trials:
        res = _measure(ctx, campaign, t)
        if isinstance(res, list):
            done[t] = res
        else:
            measured.append((t, res))
    if measured:
        per_method = [_fit_all(ctx, campaign, [m for _, m in measured], k) for k in campaign.methods]
        for i, (t, m) in enumerate(measured):
            done[t] = _verify(ctx, campaign, m, [fits[i] for fits in per_method])
    return [line for t in trials for line in done[t]]


def run_trial(ctx: Context, campaign: Campaign, trial: int) -> list[str]:
    """The CSV lines (one per method, in method order) of trial ``trial`` of ``campaign``
    (:func:`run_trials` of that one trial: the same lines as in any batch)."""
    return run_trials(ctx, campaign, [trial])


def run_batch(ctx: Context, campaign: int, first: int, last: int) -> tuple[int, int, int, list[str], float]:
    """Trials ``first``..``last`` (inclusive) of one campaign: ``(campaign, first, last,
    lines, seconds)`` with the lines in (trial, method) order, :data:`FIT_BATCH` trials at a time."""
    from pkmcal.identification.residuals import single_threaded_blas

    t0 = time.perf_counter()
    c = ctx.campaigns[campaign]
    lines: list[str] = []
    with single_threaded_blas():
        for start in range(first, last + 1, FIT_BATCH):
            lines.extend(run_trials(ctx, c, range(start, min(last, start + FIT_BATCH - 1) + 1)))
    return campaign, first, last, lines, time.perf_counter() - t0


__all__ = ["Campaign", "Context", "prepare", "pseudo_truth", "real_machine", "rng_for", "run_batch", "run_trial", "run_trials", "seed_for"]
