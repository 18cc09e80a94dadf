"""The user docs read as reference pages, not as a work log.

Checked for README.md, docs/*.md and the measured studies of docs/studies/*.md:

- no work-log words: "session", "issue N", "#N", "last time";
- no commit hashes (runs of 7-40 hex digits with both a digit and a letter), except on the
  study pages, where each table names the commit that landed it;
- no history in the reference pages (docs/*.md): what was tried, not kept, or predates, and
  what was so "at the time", goes to the CHANGELOG or to a study page;
- docs/multiscale.md is an index of at most 400 lines (its parts have their own pages);
- each coupling part's page (docs/coupling_*.md) has the sections of the template, in order;
- each table of a study page is followed by its command, its commit and its data file;
- every markdown link to a local file resolves (relative to the page), and an anchor in it,
  or one on the same page, names a heading of that page (GitHub's heading ids);
- bench/README.md's index names every benchmark script of bench/;
- every citation key ``[@key]`` in docs/references.md has an entry in docs/references.bib.

Pages being rewritten by others are listed in PENDING and skipped until they land.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
# The measured studies: each table with its command, the commit that landed it and its data.
STUDIES = DOCS / "studies"

# Pages rewritten elsewhere; skipped by the text checks until the lead empties this list.
PENDING = ["docs/output.md"]

WORK_LOG = [
    re.compile(r"\bsessions?\b", re.IGNORECASE),
    re.compile(r"\bissues?\s+\d+", re.IGNORECASE),
    re.compile(r"(?<![\w&/])#\d+\b"),
    re.compile(r"\blast time\b", re.IGNORECASE),
]
# A commit id: 7 to 40 hex digits with at least one digit and at least one letter a-f.
COMMIT_HASH = re.compile(r"(?<![\w.-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![\w-])")
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
CITE = re.compile(r"\[@([A-Za-z0-9_:.-]+)\]")
BIB_KEY = re.compile(r"@\w+\s*\{\s*([^,\s]+)\s*,")


def _pages() -> list[Path]:
    pages = [ROOT / "README.md", *sorted(DOCS.glob("*.md")), *sorted(STUDIES.glob("*.md"))]
    return [p for p in pages if p.exists() and p.relative_to(ROOT).as_posix() not in PENDING]


def _is_study(p: Path) -> bool:
    return p.parent.resolve() == STUDIES.resolve()


def _page_id(p: Path) -> str:
    return p.relative_to(ROOT).as_posix() if p.is_relative_to(ROOT) else str(p)


def heading_ids(page: Path) -> set[str]:
    """GitHub's ids of the page's headings: lower case, punctuation dropped, spaces to '-'."""
    ids, seen = set(), {}
    in_code = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
        if in_code or not re.match(r"^#{1,6} ", line):
            continue
        slug = re.sub(r"[^\w\- ]", "", line.lstrip("#").strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        ids.add(slug if n == 0 else f"{slug}-{n}")
    return ids


def work_log_hits(text: str, commits: bool = True) -> list[str]:
    """Work-log phrases and (unless ``commits`` is False) commit ids found in ``text`` (empty
    when clean)."""
    hits = [m.group(0) for pat in WORK_LOG for m in pat.finditer(text)]
    if commits:
        hits += [m.group(0) for m in COMMIT_HASH.finditer(text)]
    return hits


def test_the_checker_finds_a_synthetic_hash_and_work_log_words():
    assert work_log_hits("Measured against `3f9c2ab` of the tree.") == ["3f9c2ab"]
    assert work_log_hits("see a65d9a1e0b4c7d2f9e8a1b3c5d7e9f0a1b2c3d4e") != []
    assert work_log_hits("In session 4 we fixed issue 12 and #7.") == ["session", "issue 12", "#7"]
    # Numbers that are not commit ids pass: decimals, plain digit runs, words, anchors.
    assert work_log_hits("1000000 steps, 1.54e7 p-steps/s, deadline, [x](a.md#storage-order)") == []


def _generated_lines(text: str) -> set[int]:
    """The lines of the page that scripts/docs_tables.py writes from committed data (their
    provenance names a commit on purpose; tests/test_docs_tables.py checks them)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_tables",
                                                  ROOT / "scripts" / "docs_tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.generated_lines(text)


@pytest.mark.parametrize("page", _pages(), ids=_page_id)
def test_page_has_no_work_log_words_or_commit_ids(page: Path):
    bad = []
    text = page.read_text(encoding="utf-8")
    skip = _generated_lines(text)
    for n, line in enumerate(text.splitlines(), 1):
        if n in skip:
            continue
        bad += [f"line {n}: {h!r}" for h in work_log_hits(line, commits=not _is_study(page))]
    assert not bad, f"{_page_id(page)} reads like a work log: " + "; ".join(bad[:20])


# History words: a reference page gives the current behaviour and figures; what was tried and
# not kept, what predates a change, what was so at the time, goes to the CHANGELOG (or, with
# its command and commit, to a study page of docs/studies/).
HISTORY = re.compile(r"\bpredat\w*|\btried, not kept\b|\bnot kept\b|\bat the time\b",
                     re.IGNORECASE)
MULTISCALE_MAX_LINES = 400


def history_hits(text: str) -> list[str]:
    """``line N: 'words'`` for each history phrase in ``text`` (empty when clean)."""
    return [f"line {n}: {m.group(0)!r}" for n, line in enumerate(text.splitlines(), 1)
            for m in HISTORY.finditer(line)]


def test_the_history_check_finds_the_words():
    assert history_hits("These figures predate `at_level`.\nok\n") == ["line 1: 'predate'"]
    assert history_hits("a patch (tried, not kept)") == ["line 1: 'tried, not kept'"]
    assert history_hits("a variant measured and not kept") == ["line 1: 'not kept'"]
    assert history_hits("measured at the time: 3 s; Predates it") == [
        "line 1: 'at the time'", "line 1: 'Predates'"]
    assert history_hits("the state is kept; a time step; tried cases") == []


@pytest.mark.parametrize("page", [p for p in _pages() if not _is_study(p)], ids=_page_id)
def test_reference_pages_hold_no_history(page: Path):
    bad = history_hits(page.read_text(encoding="utf-8"))
    assert not bad, (f"{_page_id(page)} speaks of history (move it to CHANGELOG.md or to a page "
                     f"of docs/studies/): " + "; ".join(bad[:20]))


# A coupling part's reference page (docs/coupling_*.md) has these sections, in this order.
TEMPLATE = ["What it is", "API", "Options", "Statuses", "Limits"]
# The line under each table of a study page: the command, the commit that landed the table,
# and its committed data file (or "not committed").
PROVENANCE = re.compile(r"^\s*Command: .+ · commit `[0-9a-f]{7,40}` .* · data: .+\.$")


def h2_sections(text: str) -> list[str]:
    """The page's level-2 headings, in order (not those in code blocks)."""
    out, in_code = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and line.startswith("## "):
            out.append(line[3:].strip())
    return out


@pytest.mark.parametrize("page", sorted(DOCS.glob("coupling_*.md")), ids=_page_id)
def test_coupling_pages_follow_the_template(page: Path):
    assert h2_sections(page.read_text(encoding="utf-8")) == TEMPLATE, _page_id(page)


def tables_without_provenance(text: str) -> list[int]:
    """The first line of each table not followed (after blank lines) by a provenance line."""
    lines, bad, k = text.splitlines(), [], 0
    while k < len(lines):
        if lines[k].lstrip().startswith("|"):
            start = k
            while k < len(lines) and lines[k].lstrip().startswith("|"):
                k += 1
            while k < len(lines) and not lines[k].strip():
                k += 1
            if k >= len(lines) or not PROVENANCE.match(lines[k]):
                bad.append(start + 1)
        else:
            k += 1
    return bad


def test_the_provenance_check_finds_a_bare_table():
    table = "| a | b |\n|---|---|\n| 1 | 2 |\n"
    good = "Command: `x --y` · commit `abc1234` (2026-01-02) · data: not committed."
    assert tables_without_provenance(table + "\n" + good + "\n") == []
    assert tables_without_provenance("text\n" + table + "\nmore text\n") == [2]


@pytest.mark.parametrize("page", sorted(STUDIES.glob("*.md")), ids=_page_id)
def test_study_tables_carry_command_commit_and_data(page: Path):
    bad = tables_without_provenance(page.read_text(encoding="utf-8"))
    assert not bad, (f"{_page_id(page)}: the tables at lines {bad} lack their provenance line "
                     "(Command: ... · commit `...` (date) · data: FILE or not committed.)")


def multiscale_too_long(text: str) -> int | None:
    """The line count of docs/multiscale.md's ``text`` when it is over the index's limit."""
    n = len(text.splitlines())
    return n if n > MULTISCALE_MAX_LINES else None


def test_multiscale_is_an_index():
    text = (DOCS / "multiscale.md").read_text(encoding="utf-8")
    n = multiscale_too_long(text)
    assert n is None, (f"docs/multiscale.md has {n} lines (at most {MULTISCALE_MAX_LINES}): it "
                       "is the index; a part's reference goes to docs/coupling_*.md, a measured "
                       "table to docs/studies/")
    # The measure can fail: 401 lines are too many.
    assert multiscale_too_long("x\n" * (MULTISCALE_MAX_LINES + 1)) == MULTISCALE_MAX_LINES + 1


def broken_links(page: Path) -> list[str]:
    """The page's links to a missing local file, or to a heading its target page lacks."""
    missing = []
    for target in LINK.findall(page.read_text(encoding="utf-8")):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):
            continue  # a URL (http:, mailto:)
        path, _, anchor = target.partition("#")
        file = page.parent / path if path else page
        if not file.exists():
            missing.append(target)
        elif anchor and file.suffix == ".md" and _page_id(file.resolve()) not in PENDING:
            if anchor not in heading_ids(file):
                missing.append(target)
    return missing


def test_the_link_checker_finds_a_missing_heading_and_file(tmp_path: Path):
    page = tmp_path / "p.md"
    page.write_text("# Top part\n[a](#top-part) [b](#no-such) [c](gone.md) [d](p.md#top-part)\n")
    assert broken_links(page) == ["#no-such", "gone.md"]


@pytest.mark.parametrize("page", [*_pages(), ROOT / "bench" / "README.md"], ids=_page_id)
def test_local_links_resolve(page: Path):
    missing = broken_links(page)
    assert not missing, f"{_page_id(page)} links to missing files or headings: {missing}"


def bench_scripts_missing_from_index(readme: str, scripts: list[str]) -> list[str]:
    """The benchmark scripts that bench/README.md's "Every benchmark" tables do not name."""
    index = readme.partition("## Every benchmark")[2].partition("\n## ")[0]
    return [s for s in scripts if f"`{s}`" not in index]


def test_the_bench_index_names_every_benchmark():
    scripts = sorted(
        p.name
        for p in (ROOT / "bench").iterdir()
        if p.suffix in (".py", ".sh", ".cpp") and not p.name.startswith(("_", "yade_"))
    )
    readme = (ROOT / "bench" / "README.md").read_text(encoding="utf-8")
    assert len(scripts) > 20
    assert bench_scripts_missing_from_index(readme, scripts) == []
    # The measure can fail: a script that is not in the tables is reported.
    assert bench_scripts_missing_from_index(readme, [*scripts, "new_bench.py"]) == ["new_bench.py"]


def test_references_cite_only_keys_in_the_bib():
    refs = (DOCS / "references.md").read_text(encoding="utf-8")
    bib = (DOCS / "references.bib").read_text(encoding="utf-8")
    cited = set(CITE.findall(refs))
    keys = BIB_KEY.findall(bib)
    assert cited, "docs/references.md cites no [@key]"
    assert len(keys) == len(set(keys)), "docs/references.bib has a key twice"
    missing = sorted(cited - set(keys))
    assert not missing, f"keys cited in docs/references.md but not in references.bib: {missing}"
