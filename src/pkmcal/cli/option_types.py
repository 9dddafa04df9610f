"""Click parameter types shared by the commands: values a command can use, or a usage error.

* :data:`SEED`: a random seed, an integer ≥ 0 (NumPy's ``default_rng`` refuses negative seeds).
* :class:`FiniteFloat`: a float range that also refuses ``nan`` and ``inf`` (click's
  ``FloatRange`` lets ``nan`` through every bound: a ``--margin nan`` would switch every
  limit check off, since no comparison with ``nan`` is true).
"""

from __future__ import annotations

import math

import click

SEED = click.IntRange(min=0)


class FiniteFloat(click.FloatRange):
    """A finite float, optionally within [min, max]."""

    name = "finite number"

    def convert(self, value, param, ctx):
        rv = click.types.FloatParamType.convert(self, value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return super().convert(rv, param, ctx)

    def _describe_range(self) -> str:
        """The range for the help text; none without bounds (click's own says 'x<=None')."""
        return "" if self.min is None and self.max is None else super()._describe_range()


__all__ = ["FiniteFloat", "SEED"]
