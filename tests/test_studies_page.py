"""The source studies are named, not numbered: docs/studies.md names every source study of the
seeds' README by its title, under a section headed by its short name and code, and maps every
case `geogrid-dem cases` lists to the study it rebuilds; the cases table of `geogrid-dem cases`
(case, the study's short name, what it runs) keeps its columns aligned whatever the names."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from geogrid_dem import cli as cli_mod
from geogrid_dem.cases import CASES, SOURCE_STUDIES, Case

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "studies.md"
#: The source studies' README, beside the repository (../shared/seeds); absent outside it.
SEEDS_README = ROOT.parent / "shared" / "seeds" / "README.md"

SEED_ROW = re.compile(r"^\|\s*`(\d{3})_[^`]*\.txt`\s*\|([^|]*)\|", re.M)
TITLE = re.compile(r"[\"“]([^\"”]+)[\"”]")


def seed_titles(readme: str) -> dict[str, str]:
    """code -> title of every seed row of the README's table (the first quoted text of its
    second column)."""
    out = {}
    for code, what in SEED_ROW.findall(readme):
        m = TITLE.search(what)
        assert m, f"seed {code}: no quoted title in {what!r}"
        out[code] = m.group(1)
    return out


def sections(page: str) -> dict[str, str]:
    """The page's level-2 sections: heading -> its text (up to the next level-2 heading)."""
    parts = re.split(r"^## (.+)$", page, flags=re.M)
    return {parts[k].strip(): parts[k + 1] for k in range(1, len(parts), 2)}


def study_section(page: str, name: str, code: str) -> str | None:
    """The text of the section headed by a study's short name and code, e.g. "The thesis
    (001)"; None without one."""
    for head, text in sections(page).items():
        if head.lower().startswith(name.lower()) and f"({code})" in head:
            return text
    return None


def unnamed_seeds(page: str, titles: dict[str, str]) -> list[str]:
    """The seeds the page does not name by title in the section of their code."""
    out = []
    for code, title in titles.items():
        study = next((s for s in SOURCE_STUDIES if s.code == code), None)
        text = study_section(page, study.name, code) if study else None
        if text is None or title not in text:
            out.append(f"{code} {title!r}")
    return out


def listed_cases(stdout: str) -> list[str]:
    """The case names of `geogrid-dem cases`: the first cell of the table's rows (after the
    header, up to the first blank line)."""
    rows = stdout.split("\n\n")[0].splitlines()[1:]
    return [r.split()[0] for r in rows if r.strip()]


def unmapped_cases(page: str, names: list[str], cases: dict[str, Case]) -> list[str]:
    """The cases the page does not show (as `name`) in the section of the study they rebuild,
    or, for a case without a study, anywhere on the page."""
    out = []
    for name in names:
        case = cases[name]
        study = next((s for s in SOURCE_STUDIES if s.title == case.study), None)
        text = study_section(page, study.name, study.code) if study else page
        if text is None or f"`{name}`" not in text:
            out.append(name)
    return out


def misaligned(lines: list[str], rows: list[tuple[str, str, str]]) -> list[str]:
    """The rows of the cases table that are not the cells (case, study, what it runs) padded
    to the columns the header opens, or that run into the next column; [] when aligned."""
    header = lines[0]
    starts = [0, header.index("study"), header.index("what it runs")]
    bad = [] if header == "case".ljust(starts[1]) + "study".ljust(starts[2] - starts[1]) + \
        "what it runs" else [header]
    for line, cells in zip(lines[1:], rows, strict=True):
        fits = all(len(c) < starts[k + 1] - starts[k] for k, c in enumerate(cells[:2]))
        padded = "".join(c.ljust(starts[k + 1] - starts[k]) for k, c in enumerate(cells[:2]))
        if not fits or line != padded + cells[2]:
            bad.append(line)
    return bad


def _table(cases: dict[str, Case]) -> tuple[list[str], list[tuple[str, str, str]]]:
    lines = cli_mod.cases_table()
    n = lines.index("")
    return lines[:n], [(k, c.study_name or "-", c.summary) for k, c in cases.items()]


def _cli_cases() -> str:
    exe = shutil.which("geogrid-dem", path=str(Path(sys.executable).parent))
    cmd = [exe] if exe else [sys.executable, "-m", "geogrid_dem.cli"]
    r = subprocess.run([*cmd, "cases"], capture_output=True, text=True, cwd=ROOT,
                       env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_the_page_names_every_seed_by_its_title():
    if not SEEDS_README.exists():
        pytest.skip(f"no source studies' README at {SEEDS_README}")
    titles = seed_titles(SEEDS_README.read_text(encoding="utf-8"))
    assert len(titles) >= 3, titles
    page = PAGE.read_text(encoding="utf-8")
    assert unnamed_seeds(page, titles) == []
    # The registry's titles are the seeds' (the cases' --help and listing name them).
    assert {s.code: s.title for s in SOURCE_STUDIES} == titles
    # The check can fail: a title missing from its section, or a seed the page lacks.
    code, title = next(iter(titles.items()))
    assert unnamed_seeds(page.replace(title, "a study"), titles) == [f"{code} {title!r}"]
    assert unnamed_seeds(page, {**titles, "999": "A new study"}) == ["999 'A new study'"]


def test_seed_titles_read_the_readme_table():
    readme = ("| file | what it is |\n| --- | --- |\n"
              '| `000_ab.txt` | Conference paper "A pull-out" (Yade). |\n'
              "| `001_cd.txt` | Thesis “A thesis”. |\n")
    assert seed_titles(readme) == {"000": "A pull-out", "001": "A thesis"}


def test_every_listed_case_is_on_the_page_under_its_study():
    out = _cli_cases()
    names = listed_cases(out)
    assert sorted(names) == sorted(CASES)  # the listing is read right
    page = PAGE.read_text(encoding="utf-8")
    for s in SOURCE_STUDIES:  # a section per study, headed by its short name and code
        text = study_section(page, s.name, s.code)
        assert text is not None, f"no section '{s.name} ({s.code})' on {PAGE.name}"
        assert s.title in text and f"**{s.name}**" in text
    assert unmapped_cases(page, names, CASES) == []
    # The check can fail: a case named only in another study's section, or not at all.
    moved = page.replace("`triaxial`", "`triaxial-x`")
    assert unmapped_cases(moved, names, CASES) == ["triaxial"]
    extra = {**CASES, "new-case": Case("new_case", CASES["triaxial"].study, "new")}
    assert unmapped_cases(page, [*names, "new-case"], extra) == ["new-case"]


def test_the_cases_table_is_aligned_and_the_command_prints_it():
    lines, rows = _table(CASES)
    assert misaligned(lines, rows) == []
    assert _cli_cases() == "\n".join(cli_mod.cases_table()) + "\n"
    # Each study's short name and code, with its title, below the table.
    for s in SOURCE_STUDIES:
        assert any(f"{s.name} ({s.code})" in x and f'"{s.title}"' in x
                   for x in cli_mod.cases_table())


def test_the_cases_table_stays_aligned_with_any_name(monkeypatch):
    """A name longer than every other, and a case without a study: every column still starts
    in one place."""
    cases = {**CASES,
             "a-case-with-a-much-longer-name": Case("x", CASES["pullout-000"].study, "long"),
             "no-study": Case("y", "", "none")}
    monkeypatch.setattr(cli_mod, "CASES", cases)
    lines, rows = _table(cases)
    assert misaligned(lines, rows) == []
    # The check can fail: a summary one column off, a name run into the study column.
    off = [lines[0], *lines[1:-1], lines[-1].replace("-  ", "-   ", 1)]
    assert misaligned(off, rows) == [off[-1]]
    width = lines[0].index("study")
    tight = [lines[0]] + [line if k else "x" * width + line[width:]
                          for k, line in enumerate(lines[1:])]
    rows_tight = [("x" * width, *rows[0][1:]), *rows[1:]]
    assert misaligned(tight, rows_tight) == [tight[1]]


def test_the_entry_pages_link_the_studies_page():
    assert "(studies.md)" in (ROOT / "docs" / "start_here.md").read_text(encoding="utf-8")
    assert "(docs/studies.md)" in (ROOT / "README.md").read_text(encoding="utf-8")
