"""pkmcal: calibration of parallel kinematic machines.

Calibration is one weighted nonlinear least-squares problem over a machine's kinematic
parameters and, per measured pose, nuisance unknowns (the real pose, joint deflections).
The package is laid out by concern:

* :mod:`pkmcal.mechanisms`     what moves: the mechanism interface, the hexapod, built-ins
* :mod:`pkmcal.sensors`        what is measured: sensor models with analytic derivatives
* :mod:`pkmcal.identification` the engine and its named methods
* :mod:`pkmcal.planning`       which poses to measure
* :mod:`pkmcal.io`, :mod:`pkmcal.cli`   the edges: files and the command line

Units and the pose convention are defined once, in :mod:`pkmcal.conventions`.
"""

__version__ = "0.1.0"
