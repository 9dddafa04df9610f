"""The closed vocabularies of the campaign's options, named once for the command line and
the Python API: methods (paper 1 ik-residual, paper 2 fk-residual, paper 3 projection and
its baselines), robust losses, clipped-reading policies, built-in setups, export formats;
the planning's algorithms, observability indices, default safety margins and plan formats.
Each is defined where its meaning is implemented; this module only gathers them."""

from __future__ import annotations

from pkmcal.identification.baselines import BASELINES
from pkmcal.identification.residuals import DEFAULT_METHOD_RULE, METHODS
from pkmcal.identification.robust import DEFAULT_F_SCALE, LOSSES, OUTLIER_SIGMA
from pkmcal.io.measurements import CLIPPED_POLICIES
from pkmcal.planning.indices import INDEX_DESCRIPTIONS, INDEX_NAMES
from pkmcal.planning.margins import ASSUMED_JOINT_ERROR_MM, CLEARANCE_MARGIN_MM
from pkmcal.planning.selection import ALGORITHMS as PLAN_ALGORITHMS
from pkmcal.sensors.library import BUILTIN_SETUPS
from pkmcal.workflow.export import EXPORT_FORMATS
from pkmcal.workflow.plan import PLAN_FORMATS

__all__ = ["BASELINES", "BUILTIN_SETUPS", "CLIPPED_POLICIES", "DEFAULT_F_SCALE", "DEFAULT_METHOD_RULE", "EXPORT_FORMATS",
           "LOSSES", "METHODS", "OUTLIER_SIGMA"]
__all__ += ["ASSUMED_JOINT_ERROR_MM", "CLEARANCE_MARGIN_MM", "INDEX_DESCRIPTIONS", "INDEX_NAMES", "PLAN_ALGORITHMS",
            "PLAN_FORMATS"]
