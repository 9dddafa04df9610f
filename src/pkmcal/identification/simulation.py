"""Simulated calibration campaigns: what a sensor and the encoders would read on a "real"
machine commanded with a nominal model.

Paper 1 §IV (steps 1–4) and paper 2 §5 (Table 5): a commanded pose x_c is turned into
actuator commands by the nominal model, q = IK(x_c, ρ_nom); the real machine goes where its
own kinematics take it, x_r = FK(q, ρ_real) (Newton from x_c); the sensor reads
y = h(x_r, θ) + e_y and the encoders q + e_q, with e_y, e_q drawn from the setup's
:class:`~pkmcal.sensors.base.NoiseModel` (Gaussian, or uniform of half-width h = √3·std).
Encoder noise is a reading error: the machine moves to FK(q), the file records q + e_q.

Several sessions (:func:`simulate_sessions`): the commanded poses split in order into
sessions, each read by its own sensor (another world/tool frame: the instrument set up
again), and optionally measured after re-homing, the actuator zeros of session s moved by
δq_s: the real machine goes to FK(q + δq_s, ρ_real) while the file records q (+ e_q), so
that IK(x, ρ_real) = q + δq_s (:mod:`pkmcal.sensors.sessions`).

Poses the real machine cannot reach — FK not converged, or converged on another assembly
mode than the commanded pose (:attr:`~pkmcal.mechanisms.base.FKResult.same_branch`: a
mirror solution, not where the machine goes), real pose outside the real machine's limits,
or not readable by the sensor (indicator plane near vertical) — are dropped and reported
with their reasons. Noise is drawn for all N commanded poses before dropping, so a
pose's noise does not depend on which other poses were dropped.

Redundantly actuated machines (l actuators > n pose coordinates, paper 3 §2–3; the
mechanism's declaration, :func:`settles_at_equilibrium`) are over-constrained: commanded
with c = IK(x_c, ρ_nom) the real machine does not go to FK(c) but settles where its
actuator springs and the tool load balance (:func:`pkmcal.mechanisms.statics.equilibrium`,
paper 3 eq. 1–3 solved nonlinearly),

    Γᵀ K (q(x) − c) − J_fᵀ F = 0,

with K and F from the setup's ``simulation:`` block
(:class:`~pkmcal.mechanisms.statics.StaticsModel`), never seen by the identifier (nor the
block's backlash, which shifts each actuator by half its dead band against the direction
of its last commanded motion, poses taken in the order given). The encoders then read
q(x) + e_q (following error q(x) − c ≠ 0) and the sensor y = h(x, θ) + e_y. The same
:func:`simulate_campaign` does both (:func:`reach` is where the real machine goes).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.io.measurements import Measurements
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.statics import StaticsModel, equilibrium
from pkmcal.progress import Progress
from pkmcal.sensors.base import MeasurementSetup, Sensor
from pkmcal.sensors.sessions import Sessions


def as_rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    """A NumPy generator from a generator, a seed, or None (fresh entropy)."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, (int, np.integer)):
        return np.random.default_rng(rng)
    raise PkmcalError(f"expected a seed (integer) or numpy Generator; got {type(rng).__name__}")


@dataclass(frozen=True)
class SimulationResult:
    """A simulated campaign.

    ``commanded`` (N, 6) all commanded poses; ``kept`` (K,) indices of the poses measured;
    ``dropped`` {index: reason} for the others; for the kept poses: ``real_poses`` (K, 6)
    reached by the real machine, ``actuator_true`` (K, l) the commands (noise-free readings),
    ``sensor_true`` (K, m) noise-free sensor readings, ``actuator_readings`` and
    ``sensor_readings`` the noisy ones. Internal units (mm, rad).
    """

    commanded: np.ndarray
    kept: np.ndarray
    dropped: dict[int, str]
    real_poses: np.ndarray
    actuator_true: np.ndarray
    sensor_true: np.ndarray
    actuator_readings: np.ndarray
    sensor_readings: np.ndarray
    setup: MeasurementSetup
    #: the session of each kept pose (:func:`simulate_sessions`); None: one session
    sessions: Sessions | None = None

    @property
    def measurements(self) -> Measurements:
        """The kept poses as :class:`~pkmcal.io.measurements.Measurements` (what a CSV holds)."""
        return Measurements(
            actuators=self.actuator_readings,
            readings=self.sensor_readings,
            commanded=self.commanded[self.kept],
            source=None,
            sessions=self.sessions,
        )

    def subset(self, positions: np.ndarray | slice) -> "SimulationResult":
        """This campaign restricted to some of its measured poses: ``positions`` index
        :attr:`kept` (an index array or a slice); the poses left out are neither kept nor
        dropped. The readings are those already drawn, so poses chosen among those the real
        machine reached need no second simulation (the noise of a pose is drawn per
        commanded pose, before any is dropped)."""
        take = lambda a: a[positions]  # noqa: E731
        return replace(self, kept=take(self.kept), real_poses=take(self.real_poses),
                       actuator_true=take(self.actuator_true), sensor_true=take(self.sensor_true),
                       actuator_readings=take(self.actuator_readings), sensor_readings=take(self.sensor_readings),
                       sessions=None if self.sessions is None else self.sessions.subset(positions))

    def summary(self) -> str:
        """Lines for the terminal: poses kept, dropped with reasons."""
        n = len(self.commanded)
        lines = [f"{len(self.kept)} of {n} poses measured, {len(self.dropped)} dropped"
                 + (" (pose numbers count the commanded poses from 1)" if self.dropped else "")]
        by_reason: dict[str, list[int]] = {}
        for k, why in self.dropped.items():
            by_reason.setdefault(why, []).append(k)
        for why, ks in sorted(by_reason.items()):
            shown = ", ".join(str(k + 1) for k in ks[:20]) + (", ..." if len(ks) > 20 else "")
            lines.append(f"  dropped ({why}): {len(ks)} pose(s): {shown}")
        return "\n".join(lines)


def _unreadable(real: Mechanism, sensor: Sensor, poses: np.ndarray) -> np.ndarray:
    """True where the sensor cannot read the real machine's frame at the pose
    (:meth:`Sensor.readable`, e.g. an indicator plane near vertical)."""
    return ~sensor.readable(real.frame(poses))[0]


def campaign_inputs(nominal: Mechanism, real: Mechanism, setup: MeasurementSetup, commanded_poses: np.ndarray,
                    rng: np.random.Generator | int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Checked commanded poses (N, n) and the sensor and encoder noise (N, m), (N, l) of all
    N poses, drawn before any pose is dropped (same seed, same noise per pose)."""
    commanded = nominal.as_pose_array(commanded_poses)
    if not np.all(np.isfinite(commanded)):
        raise PkmcalError("a commanded pose is not a finite number")
    if nominal.n_actuators != real.n_actuators or nominal.n_dof != real.n_dof:
        raise PkmcalError(f"nominal machine '{nominal.name}' and real machine '{real.name}' are not the same kind "
                          f"({nominal.n_actuators} and {real.n_actuators} actuators, {nominal.n_dof} and "
                          f"{real.n_dof} pose coordinates)")
    n = len(commanded)
    e_y, e_q = setup.noise.sample(as_rng(rng), (n, setup.sensor.n_readings), (n, real.n_actuators))
    return commanded, e_y, e_q


#: Commanded poses simulated per chunk: bounded memory on large campaigns, and one
#: ``progress(done, total)`` call per chunk.
CHUNK_POSES = 20_000


def simulate_campaign(
    nominal: Mechanism,
    real: Mechanism,
    setup: MeasurementSetup,
    commanded_poses: np.ndarray,
    rng: np.random.Generator | int | None = None,
    ignore_limits: tuple[str, ...] = (),
    progress: Progress | None = None,
    actuator_offset: np.ndarray | None = None,
) -> SimulationResult:
    """Simulate measuring ``commanded_poses`` (N, n; mm, rad) on ``real`` commanded by ``nominal``.

    See the module docstring for the model: FK of the commands, or, for a machine that
    :func:`settles_at_equilibrium`, the static equilibrium under the setup's ``simulation:``
    stiffness and load (``actuator_true`` then the noise-free encoder readings there,
    commands + following errors). ``rng`` is a seed or a generator; the same seed
    gives bit-identical readings. ``ignore_limits`` names limits of the real machine not
    checked (e.g. ``("leg_collision",)``: a parameter perturbation of a few mm can bring
    the modelled legs of a tight design such as ``stewart-prototype`` into contact).
    The poses are simulated in chunks of :data:`CHUNK_POSES` (at equilibrium in one: the
    backlash follows the path), ``progress(done, N)`` called after each. ``actuator_offset``
    (l,): the actuators' zeros moved by δq (re-homing): the real machine goes to FK(q + δq),
    the readings are q (module docstring); not simulated at equilibrium.
    """
    commanded, e_y, e_q = campaign_inputs(nominal, real, setup, commanded_poses, rng)
    sensor = setup.sensor
    n = len(commanded)
    chunk = max(n, 1) if settles_at_equilibrium(nominal) else CHUNK_POSES
    parts, dropped = [], {}
    for start in range(0, max(n, 1), chunk):
        q_c, poses_c, ok_c, dropped_c = reach(nominal, real, setup, commanded[start:start + chunk], ignore_limits,
                                              actuator_offset)
        parts.append((q_c, poses_c, ok_c))
        dropped.update({start + k: why for k, why in dropped_c.items()})
        if progress is not None:
            progress(min(start + chunk, n), n)
    q, poses, ok = (np.concatenate(a) for a in zip(*parts))

    kept = np.flatnonzero(ok)
    real_poses = poses[kept]
    y_true = sensor.predict(real.frame(real_poses)) if len(kept) else np.zeros((0, sensor.n_readings))
    q_true = q[kept]
    return SimulationResult(
        commanded=commanded,
        kept=kept,
        dropped=dict(sorted(dropped.items())),
        real_poses=real_poses,
        actuator_true=q_true,
        sensor_true=y_true,
        actuator_readings=q_true + e_q[kept],
        sensor_readings=y_true + e_y[kept],
        setup=setup,
    )


def settles_at_equilibrium(machine: Mechanism) -> bool:
    """True where the machine, commanded, settles at a static equilibrium rather than at the
    FK of its commands: it declares more actuators than pose coordinates (redundantly
    actuated, paper 3)."""
    return machine.n_actuators > machine.n_dof


def reach(nominal: Mechanism, real: Mechanism, setup: MeasurementSetup, commanded: np.ndarray,
          ignore_limits: tuple[str, ...], actuator_offset: np.ndarray | None = None,
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, str]]:
    """Where ``real`` goes for each of the ``commanded`` poses (N, n) commanded through
    ``nominal``'s IK, c = IK(x_c, ρ_nom) (module docstring): ``(q, poses, ok, reasons)``,
    q (N, l) the noise-free readings (the commands; the encoders at equilibrium), the real
    poses (N, n; placeholders where not ok), whether each was reached and read, the
    reasons of the others by position."""
    if settles_at_equilibrium(nominal):
        if actuator_offset is not None:
            raise PkmcalError(f"machine '{nominal.name}' is redundantly actuated: it settles at equilibrium under "
                              "its encoders; re-homing (actuator offsets) is not simulated there")
        with np.errstate(invalid="ignore"):
            commands = nominal.ik(commanded)
        poses, readings, ok, dropped = settle(real, setup, commands, commanded, ignore_limits)
        return readings, poses, ok, dropped
    return _reach_fk(nominal, real, setup.sensor, commanded, ignore_limits, actuator_offset)


def _reach_fk(nominal: Mechanism, real: Mechanism, sensor: Sensor, commanded: np.ndarray,
              ignore_limits: tuple[str, ...], actuator_offset: np.ndarray | None = None,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, str]]:
    """Where ``real`` goes for each of the ``commanded`` poses (one chunk): the commands
    q = IK(x_c, ρ_nom) (N, l), the real poses (N, n; the commanded pose where not reached;
    FK of q + ``actuator_offset`` when given), whether each was reached and read, and the
    reasons of the others by position."""
    q = nominal.ik(commanded)
    dropped: dict[int, str] = {}
    finite = np.all(np.isfinite(q), axis=1)
    for k in np.flatnonzero(~finite):
        dropped[int(k)] = "nominal-ik-failed"
    moved = q if actuator_offset is None else q + np.asarray(actuator_offset, dtype=float)
    fk = real.fk(np.where(finite[:, None], moved, 0.0), guess=commanded)
    bad_fk = finite & ~fk.converged
    for k in np.flatnonzero(bad_fk):
        dropped[int(k)] = f"fk-not-converged (residual {fk.residual[k]:.3g})"
    for k in np.flatnonzero(finite & fk.branch_changed):
        dropped[int(k)] = "fk-other-assembly-mode"
    ok = finite & fk.ok
    poses = np.where(ok[:, None], fk.poses, commanded)   # placeholders where not ok, never kept
    ok = drop_limit_violations(real, poses, ok, ignore_limits, dropped)
    unread = ok & _unreadable(real, sensor, poses)
    for k in np.flatnonzero(unread):
        dropped[int(k)] = "not-readable-by-sensor"
    return q, poses, ok & ~unread, dropped


def _statics(setup: MeasurementSetup, machine: Mechanism) -> tuple[np.ndarray, np.ndarray | None]:
    sim: StaticsModel | None = setup.simulation
    if sim is None:
        raise PkmcalError(f"machine '{machine.name}' is redundantly actuated: simulating it needs the actuator "
                          "stiffness (and the tool load) in the setup's 'simulation:' block, e.g. "
                          "simulation: {stiffness: 2.0e4, load: [0, -30]} (N/mm or N*mm/rad; N)")
    return sim.stiffness_for(machine), sim.load


def settle(real: Mechanism, setup: MeasurementSetup, commands: np.ndarray, guess: np.ndarray,
           ignore_limits: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, str]]:
    """Equilibrium of ``real`` under ``commands`` (N, l), in path order: (poses, readings, ok,
    reasons). With backlash (``simulation.backlash``) the springs act on the commands less
    the backlash shift s b/2 and the encoders read the joints plus it
    (:meth:`~pkmcal.mechanisms.statics.StaticsModel.backlash_shift`)."""
    K, F = _statics(setup, real)
    shift = setup.simulation.backlash_shift(commands)
    n = len(commands)
    finite = np.all(np.isfinite(commands), axis=1) & np.all(np.isfinite(guess), axis=1)
    reasons: dict[int, str] = {int(k): "nominal-ik-failed" for k in np.flatnonzero(~finite)}
    poses = np.array(guess, dtype=float)
    readings = np.full((n, real.n_actuators), np.nan)
    ok = finite.copy()
    if finite.any():
        eq = equilibrium(real, commands[finite] - shift[finite], K, F, setup.sensor, guess=guess[finite])
        idx = np.flatnonzero(finite)
        poses[idx] = eq.poses
        readings[idx] = eq.readings + shift[finite]
        for j in np.flatnonzero(~eq.converged):
            reasons[int(idx[j])] = f"equilibrium-not-converged (force residual {eq.force_residual[j]:.3g})"
        ok[idx[~eq.converged]] = False
    with np.errstate(invalid="ignore"):
        ok = drop_limit_violations(real, np.where(ok[:, None], poses, real.home_pose), ok, ignore_limits, reasons)
    return poses, readings, ok, dict(sorted(reasons.items()))


def simulate_sessions(
    nominal: Mechanism,
    real: Mechanism,
    setup: MeasurementSetup,
    commanded_poses: np.ndarray,
    sensors: tuple[Sensor, ...],
    rng: np.random.Generator | int | None = None,
    offsets: np.ndarray | None = None,
    simulate=None,
    **kw,
) -> SimulationResult:
    """The campaign of :func:`simulate_campaign` measured in S = len(``sensors``) sessions:
    the commanded poses split in order into S parts of (nearly) equal size, labelled
    ``1 … S``, part s read by ``sensors[s]`` and, with ``offsets`` (S, l), measured with the
    actuator zeros moved by ``offsets[s]`` (re-homing; row 0 is normally zero). One seeded
    generator draws the parts' noise in turn (same seed, same bytes). ``simulate`` replaces
    :func:`simulate_campaign` (same arguments), which simulates every machine (at
    equilibrium too, which takes no offsets); ``kw`` goes to it."""
    commanded = nominal.as_pose_array(commanded_poses)
    gen = as_rng(rng)
    n_ses = len(sensors)
    if n_ses < 1 or n_ses > max(len(commanded), 1):
        raise PkmcalError(f"{n_ses} sessions for {len(commanded)} commanded poses: give 1 to {len(commanded)}")
    simulate = simulate or simulate_campaign
    parts = np.array_split(np.arange(len(commanded)), n_ses)
    results = []
    for s, (idx, sensor) in enumerate(zip(parts, sensors)):
        extra = {} if offsets is None else {"actuator_offset": np.asarray(offsets, dtype=float)[s]}
        results.append(simulate(nominal, real, replace(setup, sensor=sensor), commanded[idx], gen, **kw, **extra))
    starts = [int(idx[0]) if len(idx) else 0 for idx in parts]
    cat = lambda name: np.concatenate([getattr(r, name) for r in results])  # noqa: E731
    kept = np.concatenate([r.kept + a for r, a in zip(results, starts)])
    labels = tuple(str(s + 1) for s in range(n_ses))
    return SimulationResult(
        commanded=commanded, kept=kept,
        dropped=dict(sorted({k + a: why for r, a in zip(results, starts) for k, why in r.dropped.items()}.items())),
        real_poses=cat("real_poses"), actuator_true=cat("actuator_true"), sensor_true=cat("sensor_true"),
        actuator_readings=cat("actuator_readings"), sensor_readings=cat("sensor_readings"), setup=setup,
        sessions=Sessions(labels, np.concatenate([np.full(len(r.kept), s, dtype=np.intp)
                                                  for s, r in enumerate(results)])))


def session_sensors_drawn(sensor: Sensor, n_sessions: int, magnitude_mm: float,
                          rng: np.random.Generator | int | None = None, given: dict | None = None,
                          radius_mm: float = 1000.0) -> tuple[Sensor, ...]:
    """The true sensors of ``n_sessions`` sessions: session ``"1"`` is ``sensor``; a session
    whose label ``given`` names has that sensor; every other one is ``sensor`` with its free
    parameters (``default_free``: the unknown frames) moved by U(−m, m) mm, angles
    m/``radius_mm`` rad (the rule of :func:`perturb_machine`), m = ``magnitude_mm``."""
    gen = as_rng(rng)
    given = given or {}
    free = [sensor.param_names.index(n) for n in sensor.default_free]
    is_angle = np.array(sensor.param_is_angle, dtype=bool)[free]
    out = []
    for s in range(n_sessions):
        label = str(s + 1)
        if label in given:
            out.append(given[label])
        elif s == 0:
            out.append(sensor)
        else:
            theta = sensor.params
            delta = gen.uniform(-magnitude_mm, magnitude_mm, size=len(free))
            theta[free] += np.where(is_angle, delta / radius_mm, delta)
            out.append(sensor.with_params(theta))
    return tuple(out)


def perturb_machine(
    machine: Mechanism,
    magnitude_mm: float,
    rng: np.random.Generator | int | None = None,
    distribution: str = "uniform",
    name: str | None = None,
    radius_mm: float = 1000.0,
) -> Mechanism:
    """A random "real" machine: every kinematic parameter plus an error of size ``magnitude_mm``.

    ``distribution="uniform"``: errors U(−m, m) (paper 1 §IV: ±5 mm); ``"gaussian"``: N(0, m²).
    Lengths (and linear encoder offsets) get errors in mm; angle parameters
    (:attr:`~pkmcal.mechanisms.base.Mechanism.param_is_angle`: tower angles, leans, way
    directions, rotary encoder offsets) ``magnitude_mm / radius_mm`` rad, the same
    displacement at ``radius_mm`` = 1 m. Parameters in other units (a hexapod's leg gains,
    mm per reading unit) have no error in mm and are kept; perturb them explicitly
    (``machine.with_params``). One rule for every machine: a hexapod, whose other parameters
    are all lengths, draws exactly as before. The home pose is kept, so the real machine is
    commanded as the nominal one is.
    """
    p = machine.params
    drawn = np.flatnonzero(np.isin(machine.param_units, ("mm", "deg")))
    delta = np.zeros(p.shape)
    delta[drawn] = parameter_errors(drawn.size, magnitude_mm, rng, distribution)
    delta = np.where(np.array(machine.param_is_angle, dtype=bool), delta / radius_mm, delta)
    return machine.with_params(p + delta, name=name or f"{machine.name}-perturbed")


def parameter_errors(
    size: int | tuple[int, ...],
    magnitude_mm: float,
    rng: np.random.Generator | int | None = None,
    distribution: str = "uniform",
) -> np.ndarray:
    """Random parameter errors of shape ``size``: U(−m, m) for ``"uniform"`` (paper 1 §IV: ±5 mm),
    N(0, m²) for ``"gaussian"``, m = ``magnitude_mm``."""
    if not np.isfinite(magnitude_mm) or magnitude_mm < 0:
        raise PkmcalError(f"parameter error magnitude must be a non-negative number of mm; got {magnitude_mm}")
    gen = as_rng(rng)
    if distribution == "uniform":
        return gen.uniform(-magnitude_mm, magnitude_mm, size=size)
    if distribution == "gaussian":
        return gen.standard_normal(size=size) * magnitude_mm
    raise PkmcalError(f"unknown error distribution '{distribution}'; use uniform or gaussian")


def limits_violated(machine: Mechanism, poses: np.ndarray,
                    ignore_limits: tuple[str, ...] = ()) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``(bad (N,), {limit: verdicts (N,)})``: the poses outside ``machine``'s limits, all but
    ``ignore_limits`` (an ignored name that is not a limit is a user error), and per limit
    checked which poses break it. Only the verdicts are used: a hexapod checks without its
    margins (same verdicts, faster)."""
    report = machine.check_limits(poses, margins=False)
    unknown = [n for n in ignore_limits if n not in report.violations]
    if unknown:
        raise PkmcalError(f"machine '{machine.name}' has no limit {', '.join(unknown)}; "
                          f"its limits are {', '.join(report.violations)}")
    violated = {n: v for n, v in report.violations.items() if n not in ignore_limits}
    bad = np.zeros(len(poses), dtype=bool)
    for v in violated.values():
        bad |= v
    return bad, violated


def drop_limit_violations(
    real: Mechanism,
    poses: np.ndarray,
    ok: np.ndarray,
    ignore_limits: tuple[str, ...],
    dropped: dict[int, str],
) -> np.ndarray:
    """``ok`` (N,) with the poses outside ``real``'s limits (all but ``ignore_limits``) turned
    False; each such pose that was ok gets the reason ``"real-limits: name+name"`` in
    ``dropped`` (updated in place) (:func:`limits_violated`)."""
    bad, violated = limits_violated(real, poses, ignore_limits)
    for k in np.flatnonzero(ok & bad):
        dropped[int(k)] = "real-limits: " + "+".join(n for n, v in violated.items() if v[k])
    return ok & ~bad
