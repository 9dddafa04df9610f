"""Every table and figure of the three papers, and where pkmcal reproduces it — or why not.

:data:`CATALOGUE` lists each table and figure of paper 1 (Agheli & Nategh: Figs. 1–11,
Table I), paper 2 (Saputra, Ong & Nee: Figs. 1–6, Tables 1–7) and paper 3 (Jeon et al.:
Figs. 1–8, Tables 1–2), plus the papers' claims in the text that a reproduction checks
(paper 2 §2.1's singularity detector, §6's "not limited to parallel frames"). Each item is
one of

* ``reproduced`` — by the registered reproductions named (ours beside theirs);
* ``input`` — the paper's data that our machines and setups are built from (checked by
  the tests named), so there is nothing to compare;
* ``method`` — a diagram of an algorithm or model that pkmcal implements (where named);
* ``not reproducible`` — a photograph or a schematic drawing, with the reason.

``pkmcal reproduce --list`` prints it (:func:`format_catalogue`).
"""

from __future__ import annotations

from dataclasses import dataclass

STATUSES = ("reproduced", "input", "method", "not reproducible")
#: The papers' short names (docs/reproductions.md).
PAPERS = {1: "Agheli & Nategh", 2: "Saputra, Ong & Nee", 3: "Jeon et al."}


@dataclass(frozen=True)
class PaperItem:
    """One table or figure (or claim, ``item`` starting with '§') of paper ``paper``:
    ``what`` it shows, its ``status`` (:data:`STATUSES`), and ``where``: the reproduction
    names for ``reproduced``, else the module or the reason."""

    paper: int
    item: str
    what: str
    status: str
    where: str

    @property
    def reproductions(self) -> tuple[str, ...]:
        """The reproduction names of a ``reproduced`` item (empty otherwise)."""
        return tuple(w.strip() for w in self.where.split(",")) if self.status == "reproduced" else ()


def _items(paper: int, rows) -> tuple[PaperItem, ...]:
    return tuple(PaperItem(paper, *row) for row in rows)


CATALOGUE: tuple[PaperItem, ...] = _items(1, (
    ("Fig. 1", "the hexapod machine tool", "not reproducible",
     "a drawing of the authors' machine, whose dimensions the paper does not give; the report draws ours "
     "(machine-poses figure)"),
    ("Fig. 2", "vector chain of leg i (eq. 1)", "method", "pkmcal.mechanisms.hexapod (l_i = p + R a_i − b_i)"),
    ("Fig. 3", "flowchart of the identification algorithm", "method",
     "pkmcal.identification.engine, method ik-residual (steps 1-6: plan, IK, measure, cost, minimise)"),
    ("Fig. 4", "pose error against x (20 of 100 slices)", "reproduced", "paper1-figs4-9"),
    ("Fig. 5", "pose error against y", "reproduced", "paper1-figs4-9"),
    ("Fig. 6", "pose error against z", "reproduced", "paper1-figs4-9"),
    ("Fig. 7", "pose error against a", "reproduced", "paper1-figs4-9"),
    ("Fig. 8", "pose error against b", "reproduced", "paper1-figs4-9"),
    ("Fig. 9", "pose error against c", "reproduced", "paper1-figs4-9"),
    ("Fig. 10", "identified kinematic parameters", "reproduced", "paper1-table1"),
    ("Fig. 11", "position and orientation errors at the verification poses", "reproduced", "paper1-table1"),
    ("Table I", "mean parameter error before / after (interior, boundary)", "reproduced", "paper1-table1"),
)) + _items(2, (
    ("Fig. 1", "schematic of the Stewart platform", "not reproducible",
     "a schematic drawing; the machine is Table 3's (stewart-prototype), drawn by the report"),
    ("Fig. 2", "digital indicator measurement framework ({F}, {P}, {T}, {W})", "reproduced",
     "paper2-plate-frame"),
    ("Fig. 3", "determining the expected indicator readings (eqs. 4-6)", "method",
     "pkmcal.sensors.indicators (eqs. 4-6, with the plate frame {W})"),
    ("Fig. 4", "cuckoo search with Lévy flights (pseudocode)", "method",
     "pkmcal.planning.selection.select_cuckoo (used by paper2-table6)"),
    ("Fig. 5", "photograph of the prototype", "not reproducible", "a photograph"),
    ("Fig. 6", "parameter error against the number of poses", "reproduced", "paper2-fig6"),
    ("Table 1", "observability indices O1-O4, random poses", "reproduced", "paper2-tables1-2"),
    ("Table 2", "observability indices O1-O4, optimally selected poses", "reproduced", "paper2-tables1-2"),
    ("Table 3", "nominal geometry of the prototype", "input",
     "built-in machine stewart-prototype (tests/mechanisms/test_builtin_machines.py checks it against the table)"),
    ("Table 4", "real model for the calibration simulation", "input",
     "built-in machine stewart-prototype-real = Table 3 + Table 4 (tests/mechanisms/test_builtin_machines.py)"),
    ("Table 5", "error comparison of the calibration simulation (four noise levels)", "reproduced",
     "paper2-table5"),
    ("Table 6", "error reduction, random against optimally selected poses", "reproduced", "paper2-table6"),
    ("Table 7", "kinematic parameters after calibration (110 optimal poses)", "reproduced",
     "paper2-table5"),
    ("§2.1", "singularity detector |J⁻¹| against a threshold (Merlet [16])", "reproduced", "paper2-singularity"),
    ("§6", "world and base frames parallel, 'not limited to this assumption'", "reproduced",
     "paper2-plate-frame"),
)) + _items(3, (
    ("Fig. 1", "error propagation with redundant actuation (four-bar linkage)", "not reproducible",
     "a schematic of the constraint force; its physics is pkmcal.mechanisms.statics (paper 3 eqs. 1-3)"),
    ("Fig. 2", "kinematic error model of the 2-dof machine", "input",
     "built-in machine planar-2dof-3act, our reconstruction (docs/redundant-machines.md)"),
    ("Fig. 3", "photograph of the laser tracker set-up", "not reproducible", "a photograph"),
    ("Fig. 4", "measurement points and sequence, 2-dof machine", "reproduced", "paper3-case1"),
    ("Fig. 5", "position error before and after, forward and backward, 2-dof machine", "reproduced",
     "paper3-case1"),
    ("Fig. 6", "kinematic error model of the 3-dof machine", "input",
     "built-in machine planar-3dof-4act, our reconstruction (docs/redundant-machines.md)"),
    ("Fig. 7", "measurement points and sequence, 3-dof machine", "reproduced", "paper3-case2"),
    ("Fig. 8", "position error before and after, 3-dof machine", "reproduced", "paper3-case2"),
    ("Table 1", "identified kinematic parameters, 2-dof machine", "reproduced", "paper3-case1"),
    ("Table 2", "identified kinematic parameters, 3-dof machine", "reproduced", "paper3-case2"),
))


def format_catalogue(reproductions: dict) -> str:
    """The text of ``pkmcal reproduce --list``: the reproductions (name, description), then
    every table and figure of the papers with its status."""
    lines = ["Reproductions (pkmcal reproduce NAME [--quick] [--figures DIR]):"]
    lines += [f"  {key:<20}{text}" for key, (_, text) in reproductions.items()]
    for paper, who in PAPERS.items():
        lines += ["", f"Paper {paper} ({who}): every table and figure"]
        for it in CATALOGUE:
            if it.paper == paper:
                lines.append(f"  {it.item:<8} {it.what}")
                lines.append(f"  {'':<8}   {it.status}: {it.where}")
    return "\n".join(lines)


__all__ = ["CATALOGUE", "PAPERS", "PaperItem", "STATUSES", "format_catalogue"]
