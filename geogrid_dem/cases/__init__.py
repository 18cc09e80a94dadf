"""The runnable studies, registered once here: ``geogrid-dem run NAME`` (or
``python -m geogrid_dem.cases.MODULE``, or ``python cases/MODULE.py`` in the source tree).
Each takes ``--smoke`` (test-sized) and ``--out DIR`` and prints progress with an ETA.

The source studies (docs/references.md):

- "Geogrid pull-out modelling using DEM" (a conference paper, run in Yade): ``pullout-000``;
- "Discrete Element Modeling of Soil-Geogrid Interactions" (a thesis, Yade): ``pullout-001``
  and ``triaxial``;
- "Microscopic interaction effects of prestressed geogrids in a reinforced soil element" (a
  journal paper, PFC3D): ``prs-element`` and ``prs-element-002``, and its question at the
  scale of a structure, ``footing-multiscale``.
"""

from __future__ import annotations

from dataclasses import dataclass

#: The titles of the source studies, by their short names in code comments.
PULLOUT_PAPER = "Geogrid pull-out modelling using DEM"
THESIS = "Discrete Element Modeling of Soil-Geogrid Interactions"
PRESTRESS_PAPER = ("Microscopic interaction effects of prestressed geogrids in a reinforced "
                   "soil element")
STUDIES = {"000": PULLOUT_PAPER, "001": THESIS, "002": PRESTRESS_PAPER}


@dataclass(frozen=True)
class Case:
    """A registered case: its module in geogrid_dem.cases, the folder name under results/ of
    its runs without --out, the study it comes from (a title, or '' for none) and one line
    saying what it runs."""

    module: str
    study: str
    summary: str

    @property
    def folder(self) -> str:
        return self.module


#: command name -> Case. The one place a case is registered.
CASES: dict[str, Case] = {
    "pullout-000": Case("pullout_000", PULLOUT_PAPER,
                        "geogrid pull-out in a 1.0 x 0.5 x 0.5 m box, 3000-9000 spheres"),
    "pullout-001": Case("pullout_001", THESIS,
                        "pull-out of square and triangular grids in a 10 cm cube "
                        "(Tables 5.2-5.4)"),
    "triaxial": Case("triaxial", THESIS, "triaxial test with or without a geogrid layer "
                     "(chapter 6)"),
    "prs-element": Case("prs_element", PRESTRESS_PAPER,
                        "reinforced vs prestressed soil element driven by FEM stresses"),
    "prs-element-002": Case("prs_element_002", PRESTRESS_PAPER,
                            "the element rebuilt from the paper's parts: gravel clumps, the "
                            "woven bonded grid, RE vs PRS"),
    "footing-multiscale": Case("footing_multiscale", PRESTRESS_PAPER,
                               "strip footing on unreinforced, RE and PRS soil, a DEM element "
                               "at every cell of the zone under it"),
    "deposition": Case("deposition", "", "spheres deposited into a box under gravity"),
}


def describe(name: str, what: str) -> str:
    """A case's --help description: what it runs, then the study it reproduces by title."""
    case = CASES[name]
    src = f'\n\nSource: "{case.study}".' if case.study else ""
    return what + src
