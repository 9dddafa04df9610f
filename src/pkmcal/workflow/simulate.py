"""A simulated measurement campaign from files (``pkmcal simulate``; the Python API's
:func:`pkmcal.simulate` works on objects): the nominal machine, the "real" one (a file, or
drawn: :func:`pkmcal.identification.simulation.perturb_machine`, paper 1 §IV's uniform errors),
the setup and the commanded poses; q = IK(x_c, ρ_nom), x_r = FK(q, ρ_real) (a redundantly
actuated machine at static equilibrium), y = h(x_r) + noise
(:func:`pkmcal.identification.simulation.simulate_campaign`), in sessions each read with its
own true sensor (and re-homed actuators) when asked. A Z probe reads only on the bed: poses
off it are refused unless the probe is allowed anywhere.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from pkmcal.errors import PkmcalError


@dataclass
class SimulatedCampaign:
    """What :func:`simulate_files` made: the machines and setup, the commanded poses
    (internal units), the :class:`~pkmcal.identification.simulation.SimulationResult` and, with
    sessions, the summary lines of each session's true sensor (file units)."""

    nominal: Any
    real: Any
    setup: Any
    commanded: np.ndarray
    result: Any
    session_lines: list[str] = field(default_factory=list)


def simulate_files(machine, setup_spec, poses, *, real=None, random_errors: float | None = None,
                   error_distribution: str = "uniform", seed=0, ignore_limits=(), n_sessions: int | None = None,
                   session_errors: float = 5.0, session_offsets: float | None = None, probe_anywhere: bool = False,
                   mapping=None, progress: Callable[[], Any] | None = None) -> SimulatedCampaign:
    """``pkmcal simulate MACHINE --setup SETUP --poses POSES.csv (--real REAL | --random-errors
    MM)``: the module docstring's campaign; ``progress`` makes the progress bar of a campaign
    without sessions (a context manager called with each pose done)."""
    from pkmcal.identification.simulation import perturb_machine, simulate_campaign
    from pkmcal.io.lookup import load_setup
    from pkmcal.io.machine_file import load_machine
    from pkmcal.io.tables import read_poses

    real_spec = real
    nominal = load_machine(machine)
    setup = load_setup(setup_spec, nominal)
    commanded = read_poses(poses, nominal, mapping)
    if not probe_anywhere and refuse_off_bed(nominal, setup, commanded, poses):
        # probe points on the bed: the real nozzle may be found below it (study.printed.BED_LIMITS)
        from pkmcal.study.printed import bed_limits

        ignore_limits = tuple(dict.fromkeys(tuple(ignore_limits) + bed_limits(nominal)))
    rng = np.random.default_rng(seed)
    if random_errors is not None:
        real = perturb_machine(nominal, random_errors, rng, distribution=error_distribution,
                               name=f"{nominal.name}-random-{random_errors:g}mm-seed{seed}")
    else:
        real = load_machine(real_spec)
    if real.kind != nominal.kind:
        raise PkmcalError(f"the real machine '{real.name}' is not of the kind of '{nominal.name}' "
                          f"({real.kind} vs {nominal.kind})")
    if session_offsets is not None and n_sessions is None:
        raise PkmcalError("--session-offsets re-homes the actuators between sessions; give --sessions S too")
    session_text: list[str] = []
    if n_sessions is not None:
        result, session_text = simulate_in_sessions(nominal, real, setup, commanded, rng, n_sessions, session_errors,
                                                    session_offsets, tuple(ignore_limits))
    else:
        with (progress() if progress is not None else contextlib.nullcontext()) as bar:
            result = simulate_campaign(nominal, real, setup, commanded, rng, ignore_limits=tuple(ignore_limits),
                                       progress=bar)
    return SimulatedCampaign(nominal, real, setup, commanded, result, session_text)


#: How far from the bed (mm) a commanded probe point may be and still be read as on it: the
#: 0.001 mm to which Klipper prints positions (a pose file rounded to 3 decimals is on the bed).
BED_TOLERANCE_MM = 1e-3


def refuse_off_bed(nominal, setup, commanded: np.ndarray, path: str) -> bool:
    """A Z probe reads where it touches the bed: refuse the first commanded pose whose probe
    point the nominal machine puts more than :data:`BED_TOLERANCE_MM` off the bed (the
    sensor's reading there, :mod:`pkmcal.sensors.z_probe`). Whether the setup is a Z probe
    (then every pose is on the bed, and the real machine's bed limits are not checked at
    them, as a study's ``on_bed``: :mod:`pkmcal.study.printed`)."""
    from pkmcal.study.printed import probes_the_bed

    if not probes_the_bed(setup.sensor):
        return False
    with np.errstate(invalid="ignore"):
        height = setup.sensor.predict(nominal.frame(commanded))[:, 0]
    off = np.flatnonzero(~(np.abs(height) <= BED_TOLERANCE_MM))
    if off.size:
        k = int(off[0])
        where = ", ".join(f"{n} {v:g}" for n, v in zip(nominal.pose_names, commanded[k]))
        raise PkmcalError(f"{path}, pose {k + 1} ({where}): the Z probe's point is {height[k]:.4g} mm from the bed "
                          f"there ({off.size} of {len(commanded)} poses off the bed); a probe reads only where it "
                          "touches the bed: plan the poses with 'pkmcal plan' (on the bed by default), or give "
                          "--probe-anywhere for a probe on gauge blocks")
    return True


def simulate_in_sessions(nominal, real, setup, commanded, rng, n_sessions: int, errors: float, offsets_mm,
                       ignore_limits) -> tuple:
    """``simulate --sessions``: the campaign in sessions (:func:`simulate_sessions`) and the
    summary lines of each session's true sensor and offsets (file units)."""
    from pkmcal.identification.simulation import session_sensors_drawn, settles_at_equilibrium, simulate_sessions
    from pkmcal.sensors.sessions import SessionSensor, Sessions, session_setup_values

    sensors = session_sensors_drawn(setup.sensor, n_sessions, errors, rng, dict(setup.session_sensors))
    offsets = None
    if offsets_mm is not None:
        if settles_at_equilibrium(nominal):
            raise PkmcalError("--session-offsets: a redundantly actuated machine settles at equilibrium under its "
                              "encoders; re-homing is not simulated there")
        delta = rng.uniform(-offsets_mm, offsets_mm, size=(n_sessions, nominal.n_actuators))
        offsets = np.where(np.array(nominal.actuator_is_angle, dtype=bool), delta / 1000.0, delta)
        offsets[0] = 0.0
    result = simulate_sessions(nominal, real, setup, commanded, sensors, rng, offsets, ignore_limits=ignore_limits)
    labels = tuple(str(s + 1) for s in range(n_sessions))
    truth = SessionSensor(sensors, Sessions(labels, np.zeros(0, dtype=np.intp)))
    values = session_setup_values(truth, None if offsets is None else dict(zip(labels[1:], offsets[1:])),
                                  nominal.actuator_is_angle)
    counts = result.sessions.counts()
    lines = [f"{n_sessions} sessions (column 'session'), true sensor of each (mm, deg):"]
    for (lab, groups), n in zip(values.items(), counts):
        parts = [f"{key}: " + (", ".join(f"{k} {v!r}" for k, v in val.items()) if isinstance(val, dict)
                               else ", ".join(repr(v) for v in val)) for key, val in groups.items()]
        lines.append(f"  session {lab} ({int(n)} poses): " + "; ".join(parts))
    return result, lines


__all__ = ["BED_TOLERANCE_MM", "SimulatedCampaign", "refuse_off_bed", "simulate_files", "simulate_in_sessions"]
