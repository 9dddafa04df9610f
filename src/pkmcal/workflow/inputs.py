"""A machine and a setup as a campaign's files name them: the machine as the setup's sensor
reads it (a single pose, or a pair of poses for printed distances:
:class:`pkmcal.mechanisms.pose_pairs.PosePairs`), the setup bound to it.

Shared by ``pkmcal identify``, ``identifiability``, ``verify`` and ``export``'s refit and by
the Python API (:mod:`pkmcal.workflow.calibration`).
"""

from __future__ import annotations

import os

from pkmcal.errors import PkmcalError


def machine_and_setup(machine_spec, setup_spec):
    """The machine of ``machine_spec`` (a file, a built-in name, or a machine) as the setup's
    sensor reads it and the setup bound to it: the machine itself, or, for a sensor of two
    poses (printed distances), the machine read as pose pairs
    (:func:`pkmcal.mechanisms.pose_pairs.read_by`). A setup that neither can take is the
    error of the machine itself."""
    from pkmcal.io.lookup import load_machine

    loaded = load_machine(machine_spec) if isinstance(machine_spec, (str, os.PathLike)) else machine_spec
    return machine_read_by(loaded, setup_spec)


def single_pose_setup_of(setup_spec, machine):
    """The setup ``setup_spec`` as it reads single poses of ``machine`` (held-out poses of
    ``verify --real``): the setup, or the Z probe of a printed-distance setup
    (:func:`pkmcal.sensors.printed_distance.single_pose_setup`)."""
    from pkmcal.sensors.printed_distance import single_pose_setup

    return single_pose_setup(machine_read_by(machine, setup_spec)[1])


def machine_read_by(nominal, setup_spec):
    """:func:`machine_and_setup` of a loaded machine ``nominal``; ``setup_spec`` a setup file,
    a built-in name, or a setup (bound to ``nominal``, or to its pose pairs)."""
    from pkmcal.io.lookup import load_setup
    from pkmcal.mechanisms.pose_pairs import PosePairs

    if not isinstance(setup_spec, (str, os.PathLike)):      # a setup object, as the caller made it
        return (PosePairs(nominal) if setup_spec.sensor.reads_pose_pairs else nominal), setup_spec
    try:
        return nominal, load_setup(setup_spec, nominal)
    except PkmcalError as exc:
        first = exc
    pairs = PosePairs(nominal)
    try:
        setup = load_setup(setup_spec, pairs)
    except PkmcalError:
        raise first from None
    if not setup.sensor.reads_pose_pairs:
        raise first
    return pairs, setup


def klipper_probe_setup(probe_offset):
    """The built-in ``z-probe-klipper`` setup with a printer's probe offset (Klipper's [probe]
    or [bltouch] x_offset, y_offset, z_offset, mm): the setup ``pkmcal import klipper
    --setup-output`` writes."""
    from dataclasses import replace

    import numpy as np

    from pkmcal.sensors.library import builtin_setup

    setup = builtin_setup("z-probe-klipper")
    return replace(setup, sensor=replace(setup.sensor, probe_offset=np.array(probe_offset)))


def setup_of_kind(setup_spec, machine, kind: str, what: str):
    """The setup ``setup_spec`` for ``machine``; an error unless its sensor is ``kind``."""
    from pkmcal.io.lookup import load_setup

    setup = load_setup(setup_spec, machine)
    if setup.sensor.kind != kind:
        raise PkmcalError(f"--setup {setup_spec}: a '{setup.sensor.kind}' setup; {what} are read with a 'sensor: "
                          f"{kind}' setup")
    return setup


def klipper_analyze_pairs(source, machine_spec, setup_spec, object_spec=None):
    """``(result, pairs, setup)`` of ``pkmcal import klipper-analyze``: Klipper's DELTA_ANALYZE
    distances and probe heights of ``source`` (:func:`pkmcal.io.klipper_analyze.read_klipper_analyze`)
    as measurements of pose pairs of the linear delta ``machine_spec`` (the config the probe
    ran with; ``object_spec`` the one the object was printed with),
    :class:`~pkmcal.mechanisms.pose_pairs.PosePairs` of it and the ``printed-distance``
    setup bound to them."""
    from pkmcal.io.klipper_analyze import read_klipper_analyze
    from pkmcal.io.klipper_probe import require_linear_delta
    from pkmcal.io.lookup import load_machine
    from pkmcal.mechanisms.pose_pairs import PosePairs

    machine = load_machine(machine_spec)
    require_linear_delta(machine, "DELTA_ANALYZE results", f"--machine {machine_spec}")
    pairs = PosePairs(machine)
    setup = setup_of_kind(setup_spec, pairs, "printed-distance", "DELTA_ANALYZE results")
    printed_by = None
    if object_spec is not None:
        printed_by = load_machine(object_spec)
        require_linear_delta(printed_by, "DELTA_ANALYZE results", f"--object-machine {object_spec}")
    return read_klipper_analyze(source, machine, setup.sensor.probe_offset, printed_by), pairs, setup


__all__ = ["klipper_analyze_pairs", "klipper_probe_setup", "machine_and_setup", "machine_read_by", "setup_of_kind", "single_pose_setup_of"]
