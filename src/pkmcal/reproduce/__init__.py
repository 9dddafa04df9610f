"""Reproductions of the papers' tables: our numbers beside the published ones.

One module per paper table or study (:mod:`.paper1`, :mod:`.paper1_error_maps`, :mod:`.paper2`,
:mod:`.paper2_planning`, :mod:`.paper2_study` (Table 6 and Fig. 6, run as :mod:`pkmcal.study`
studies), :mod:`.paper2_plate`, :mod:`.paper2_singularity`, :mod:`.paper3`,
:mod:`.paper3_compliance`; the known-stiffness baseline of paper 3's ref. [7] is
:mod:`.known_stiffness`); each reproduction is a function ``f(seed=0, quick=False,
progress=None) -> Reproduction`` (:mod:`.table`), deterministic for a seed, with a ``quick``
mode (few Monte Carlo runs) for tests and a ``progress(done, total)`` callback over its Monte
Carlo loop (:mod:`pkmcal.progress`). Its ``figures`` are the paper's figures as we redraw them
(``pkmcal reproduce NAME --figures DIR``). :data:`REPRODUCTIONS`
is the registry behind ``pkmcal reproduce NAME``; :func:`run_reproduction` runs one by name.
:data:`CATALOGUE` (:mod:`.catalogue`) lists every table and figure of the three papers with
the reproduction that covers it or the reason none can (``pkmcal reproduce --list``).

Paper 2 Tables 1–2 (observability indices of random and optimal pose sets) are in
:mod:`.paper2_planning`; ``benchmarks/planning_tables.py`` prints them (docs/planning.md).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from importlib import import_module
from typing import Callable

from pkmcal.errors import PkmcalError
from pkmcal.progress import Progress
from pkmcal.reproduce.catalogue import CATALOGUE, format_catalogue
from pkmcal.reproduce.table import Reproduction, Row

# The two reproductions named as their modules are bound here, after their modules are
# imported (an import of the module would otherwise leave the package's name on the module).
from pkmcal.reproduce.paper2_singularity import paper2_singularity  # noqa: E402
from pkmcal.reproduce.paper3_compliance import paper3_compliance  # noqa: E402

#: name → (module under pkmcal.reproduce, function, one-line description)
_ENTRIES: dict[str, tuple[str, str, str]] = {
    "paper1-table1": ("paper1", "paper1_table1", "paper 1 Table I, Figs. 10-11 (parameter errors, boundary vs interior "
                                                 "poses, D-optimal poses for context) and its verification claims, "
                                                 "with the Gauss-Markov bound"),
    "paper1-figs4-9": ("paper1_error_maps", "paper1_figs4_9", "paper 1 Figs. 4-9 (pose error along slices of each "
                                                              "coordinate) and whether they support 'measure at the "
                                                              "boundary'"),
    "paper2-table5": ("paper2", "paper2_table5", "paper 2 Table 5 (3 indicators, Table 4 real machine, four noise "
                                                 "levels), gauge evidence, Table 7 evidence"),
    "paper2-tables1-2": ("paper2_planning", "paper2_tables1_2", "paper 2 Tables 1-2 (observability indices O1-O4 of "
                                                                "random and optimal sets of 14-112 poses)"),
    "paper2-table6": ("paper2_study", "paper2_table6", "paper 2 Table 6 (random vs optimally selected poses: D_E, "
                                                       "P_Er), as a study"),
    "paper2-fig6": ("paper2_study", "paper2_fig6", "paper 2 Fig. 6 (parameter error vs number of random poses, auto "
                                                   "and paper gauge), as a study"),
    "paper2-plate-frame": ("paper2_plate", "paper2_plate_frame", "paper 2 §2.3/§6: the indicator plate as its own "
                                                                 "frame (parallel frames assumed, plate surveyed, "
                                                                 "plate identified)"),
    "paper2-singularity": ("paper2_singularity", "paper2_singularity", "paper 2 §2.1: Merlet's |J⁻¹| singularity "
                                                                       "detector beside the inverse condition number"),
    "paper3-case1": ("paper3", "paper3_case1", "paper 3 case 1 (2-dof, 3 rotary actuators): held-out improvement, "
                                               "Table 1, Figs. 4-5 (path forward/backward, backlash), ref. [7] "
                                               "known-stiffness baseline"),
    "paper3-case2": ("paper3", "paper3_case2", "paper 3 case 2 (3-dof, 4 linear actuators): held-out improvement, "
                                               "Table 2, Figs. 7-8 (path forward/backward, backlash), ref. [7] "
                                               "known-stiffness baseline"),
    "paper3-compliance": ("paper3_compliance", "paper3_compliance", "paper 3: the load/compliance trap (softer "
                                                                    "actuators, larger loads: floor, projection, "
                                                                    "naive and known-stiffness fits) and the report's "
                                                                    "warning"),
}


class _Reproductions(Mapping):
    """name → (function, one-line description), each reproduction's module imported when
    its entry is read, so that importing one module of this package (the paper-3 baselines
    of ``pkmcal identify``) does not import every reproduction."""

    def __getitem__(self, name: str) -> tuple[Callable[..., Reproduction], str]:
        module, function, text = _ENTRIES[name]
        return getattr(import_module(f"pkmcal.reproduce.{module}"), function), text

    def __iter__(self) -> Iterator[str]:
        return iter(_ENTRIES)

    def __len__(self) -> int:
        return len(_ENTRIES)


#: name → (function, one-line description)
REPRODUCTIONS: Mapping[str, tuple[Callable[..., Reproduction], str]] = _Reproductions()


def __getattr__(name: str):
    """The reproduction functions (``paper1_table1``, …) by name, imported on first use."""
    for module, function, _ in _ENTRIES.values():
        if function == name:
            return getattr(import_module(f"pkmcal.reproduce.{module}"), function)
    raise AttributeError(f"module 'pkmcal.reproduce' has no attribute '{name}'")


def run_reproduction(name: str, seed: int = 0, quick: bool = False, progress: Progress | None = None) -> Reproduction:
    """Run the reproduction ``name`` (see :data:`REPRODUCTIONS`), reporting its Monte Carlo
    loop to ``progress(done, total)``."""
    try:
        fn, _ = REPRODUCTIONS[name]
    except KeyError:
        raise PkmcalError(f"unknown reproduction '{name}'; available: {', '.join(REPRODUCTIONS)} "
                          "(run 'pkmcal reproduce --list')") from None
    return fn(seed=seed, quick=quick, progress=progress)


__all__ = ["CATALOGUE", "REPRODUCTIONS", "Reproduction", "Row", "format_catalogue", "run_reproduction",
           "paper1_table1", "paper1_figs4_9", "paper2_table5", "paper2_tables1_2", "paper2_table6", "paper2_fig6",
           "paper2_plate_frame", "paper2_singularity", "paper3_case1", "paper3_case2", "paper3_compliance"]
