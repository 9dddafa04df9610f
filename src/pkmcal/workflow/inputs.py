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


__all__ = ["klipper_probe_setup", "machine_and_setup", "machine_read_by", "single_pose_setup_of"]
