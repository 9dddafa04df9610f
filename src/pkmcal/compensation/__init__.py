"""Compensation of what a calibrated kinematic model cannot explain (issue 28, item 2).

* :mod:`.fit` — the residuals a calibrated model leaves, a smooth field fitted to them, its
  complexity chosen by k-fold cross-validation over the poses, kept only when it lowers the
  error on held-out data (:func:`~.fit.compensate`);
* :mod:`.basis` — the fields: Klipper's bed mesh (its own interpolation, as a linear basis) and
  polynomials over the pose;
* :mod:`.files` — the correction file and Klipper's ``[bed_mesh NAME]`` profile in the
  SAVE_CONFIG block;
* :mod:`.apply` — the commands that make a controller running the nominal kinematics reach
  the targets on the calibrated machine plus the correction;
* :mod:`.gcode` — G-code programs filtered move by move, every other byte kept;
* :mod:`.simulated` — unmodelled errors for simulated campaigns (a warped bed, a sagging
  hexapod).

docs/compensation.md shows the whole path on a delta printer and on a hexapod.
"""
