"""The user docs read as reference pages, not as a work log.

Checked for README.md and docs/*.md:

- no work-log words: "session", "issue N", "#N", "last time";
- no commit hashes (runs of 7-40 hex digits with both a digit and a letter);
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
    pages = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
    return [p for p in pages if p.exists() and p.relative_to(ROOT).as_posix() not in PENDING]


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


def work_log_hits(text: str) -> list[str]:
    """Work-log phrases and commit ids found in ``text`` (empty when clean)."""
    hits = [m.group(0) for pat in WORK_LOG for m in pat.finditer(text)]
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
        bad += [f"line {n}: {h!r}" for h in work_log_hits(line)]
    assert not bad, f"{_page_id(page)} reads like a work log: " + "; ".join(bad[:20])


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
