"""The runnable studies, registered once here: ``geogrid-dem run NAME`` (or
``python -m geogrid_dem.cases.MODULE``, or ``python cases/MODULE.py`` in the source tree).
Each takes ``--smoke`` (test-sized) and ``--out DIR`` and prints progress with an ETA.

The source studies (docs/studies.md maps each to its cases; docs/references.md), by the short
names the docs use, with the code that cites them in equation references ("000 eq (8)"):

- the pull-out paper (000), "Geogrid pull-out modelling using DEM" (a conference paper, run
  in Yade): ``pullout-000``;
- the thesis (001), "Discrete Element Modeling of Soil-Geogrid Interactions" (Yade):
  ``pullout-001`` and ``triaxial``;
- the prestressed-element paper (002), "Microscopic interaction effects of prestressed
  geogrids in a reinforced soil element" (a journal paper, PFC3D): ``prs-element`` and
  ``prs-element-002``, and its question at the scale of a structure, ``footing-multiscale``.
"""

from __future__ import annotations

from dataclasses import dataclass

#: The titles of the source studies, by their short names in code comments.
PULLOUT_PAPER = "Geogrid pull-out modelling using DEM"
THESIS = "Discrete Element Modeling of Soil-Geogrid Interactions"
PRESTRESS_PAPER = ("Microscopic interaction effects of prestressed geogrids in a reinforced "
                   "soil element")


@dataclass(frozen=True)
class Study:
    """A source study: its code (the alias of equation citations, "000 eq (8)", and of case
    names such as ``pullout-000``), its title, and the short readable name the docs, reports
    and case listings use (docs/studies.md)."""

    code: str
    title: str
    name: str


#: The source studies, in the order of their codes.
SOURCE_STUDIES = (Study("000", PULLOUT_PAPER, "the pull-out paper"),
                  Study("001", THESIS, "the thesis"),
                  Study("002", PRESTRESS_PAPER, "the prestressed-element paper"))
#: code -> title.
STUDIES = {s.code: s.title for s in SOURCE_STUDIES}


def study_named(title: str) -> Study | None:
    """The source study of this title (a Case's ``study``), or None for '' (no study)."""
    if not title:
        return None
    for s in SOURCE_STUDIES:
        if s.title == title:
            return s
    raise KeyError(f"no source study titled {title!r}")


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

    @property
    def study_name(self) -> str:
        """The study's short readable name ("the thesis"), or '' for none."""
        s = study_named(self.study)
        return s.name if s else ""


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
    """A case's --help description: what it runs, then the study it reproduces by its short
    name and title."""
    case = CASES[name]
    src = (f'\n\nSource: {case.study_name}, "{case.study}" (docs/studies.md).' if case.study
           else "")
    return what + src
