"""The tutorial scripts examples/*.py, each run at smoke size (``--smoke --out DIR``) in a
subprocess: it must exit 0 and write the files it declares in its module-level ``OUTPUTS``
(read with ast, the script is not imported), each non-empty; a script that declares
``RUN_BY`` is run by that test instead (examples/05 runs under mpiexec). A script that declares
``DEM_ONLY = True`` must not import dolfinx (nor gmsh, ufl, PETSc). docs/fem.md shows the
middle of examples/03_fem_driven_element.py; the page's code must be that part, line for line.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
FEM_EXAMPLE = ROOT / "examples" / "03_fem_driven_element.py"
FEM_MODULES = ("dolfinx", "dolfinx_solver", "ufl", "petsc4py", "gmsh")

# Runs the script as __main__ and then reports the FEM modules it imported.
RUNNER = """
import json, runpy, sys
sys.argv = [{path!r}, "--smoke", "--out", {out!r}]
try:
    runpy.run_path({path!r}, run_name="__main__")
except SystemExit as e:
    if e.code not in (0, None):
        raise
print("FEM_MODULES=" + json.dumps(sorted(m for m in sys.modules
                                        if m.split(".")[0] in {fem!r})))
"""


def declared(path: Path, name: str, default=None):
    """The literal value of a module-level ``name = ...`` in ``path`` (ast, not imported)."""
    for node in ast.parse(path.read_text()).body:
        targets = (node.targets if isinstance(node, ast.Assign) else
                   [node.target] if isinstance(node, ast.AnnAssign) else [])
        if any(isinstance(t, ast.Name) and t.id == name for t in targets):
            return ast.literal_eval(node.value)
    return default


def test_there_are_examples_and_each_declares_its_outputs():
    assert len(EXAMPLES) >= 4, [p.name for p in EXAMPLES]
    for path in EXAMPLES:
        outputs = declared(path, "OUTPUTS")
        assert isinstance(outputs, list) and outputs, f"{path.name}: no OUTPUTS list"
        assert any(o.endswith(".csv") for o in outputs), f"{path.name}: no CSV in OUTPUTS"
        assert any(o.endswith(".png") for o in outputs), f"{path.name}: no PNG in OUTPUTS"
        lines = len(path.read_text().splitlines())
        assert lines <= 110, f"{path.name}: {lines} lines; a tutorial script stays short"


def test_an_example_run_by_another_test_is_run_there():
    """An example that declares ``RUN_BY`` (a test that runs it in its own way, e.g. under
    mpiexec) is run by that test: it names the script and checks its OUTPUTS."""
    for path in EXAMPLES:
        by = declared(path, "RUN_BY")
        if by is None:
            continue
        text = (ROOT / by).read_text()
        assert path.name in text and "OUTPUTS" in text, f"{path.name}: {by} does not run it"


@pytest.mark.parametrize("path", [p for p in EXAMPLES if declared(p, "RUN_BY") is None],
                         ids=lambda p: p.stem)
def test_example_runs_at_smoke_size(path: Path, tmp_path: Path):
    out = tmp_path / "out"
    code = RUNNER.format(path=str(path), out=str(out), fem=FEM_MODULES)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=600, cwd=ROOT)
    assert p.returncode == 0, f"{path.name} failed:\n{p.stdout[-2000:]}\n{p.stderr[-4000:]}"
    for name in declared(path, "OUTPUTS"):
        f = out / name
        assert f.is_file(), f"{path.name}: declared output {name} not written"
        assert f.stat().st_size > 0, f"{path.name}: {name} is empty"
        if f.suffix == ".csv":
            rows = [r for r in f.read_text().splitlines() if r.strip()]
            assert len(rows) >= 2, f"{path.name}: {name} has no data row"
    fem = json.loads(p.stdout.strip().splitlines()[-1].removeprefix("FEM_MODULES="))
    if declared(path, "DEM_ONLY", False):
        assert fem == [], f"{path.name} declares DEM_ONLY but imported {fem}"


def _shown_part(path: Path) -> list[str]:
    """The lines of ``path`` between its markers '# --- ... docs/fem.md shows ...' lines."""
    lines = path.read_text().splitlines()
    start = next(k for k, s in enumerate(lines) if s.startswith("# ---") and "docs/fem.md" in s)
    end = next(k for k, s in enumerate(lines) if k > start and s.startswith("# --- end"))
    return lines[start + 1:end]


def _code_blocks(page: Path) -> list[list[str]]:
    blocks, cur = [], None
    for line in page.read_text().splitlines():
        if cur is None and line.startswith("```python"):
            cur = []
        elif cur is not None and line.startswith("```"):
            blocks.append(cur)
            cur = None
        elif cur is not None:
            cur.append(line)
    return blocks


def test_fem_page_shows_the_example_code():
    """docs/fem.md's one-way example is the middle of examples/03_fem_driven_element.py (which
    test_example_runs_at_smoke_size runs), so the page shows code that runs."""
    shown = _shown_part(FEM_EXAMPLE)
    assert len(shown) > 15 and any("one_way(" in s for s in shown)
    assert shown in _code_blocks(ROOT / "docs" / "fem.md"), (
        "docs/fem.md: no python block equals the part of examples/03_fem_driven_element.py "
        "between its markers; paste that part again")


#: The page that walks through the examples, and how it says their number.
START_PAGE = ROOT / "docs" / "start_here.md"
NUMBERS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7,
           "eight": 8, "nine": 9, "ten": 10}
#: A file name the page gives: a stem (templates such as <grid> allowed) and an extension.
FILE_NAME = re.compile(r"[\w<>|/.-]*[\w>]\.(?:csv|png|pdf|h5|md|json|xdmf|npz|vtp|pvd|toml)")


def _names_match(named: str, output: str) -> bool:
    """``named`` (a name on the page, maybe a template: <A|B> for A or B, <x> for one part
    without '_' or '/') is ``output`` (an OUTPUTS entry) or its file name."""

    def part(p: str) -> str:
        if not p.startswith("<"):
            return re.escape(p)
        alts = p[1:-1].split("|")
        return "(?:" + "|".join(map(re.escape, alts)) + ")" if len(alts) > 1 else "[^/_]+"

    pattern = "".join(map(part, re.split(r"(<[^>]*>)", named)))
    return any(re.fullmatch(pattern, o) for o in (output, output.rsplit("/", 1)[-1]))


def test_the_start_page_names_every_example_and_only_files_they_write():
    """docs/start_here.md (and README.md's link to it): the number of examples, a section for
    each script, and in each section's "Writes." paragraph the files of that script's OUTPUTS
    and no other."""
    text = START_PAGE.read_text()
    first = re.search(r"(\w+) complete scripts in", text)
    assert first and NUMBERS.get(first.group(1).lower()) == len(EXAMPLES), \
        f"the page says {first and first.group(1)!r} scripts; there are {len(EXAMPLES)}"
    readme = re.search(r"then the (\w+) examples in order", (ROOT / "README.md").read_text())
    assert readme and NUMBERS.get(readme.group(1).lower()) == len(EXAMPLES), \
        f"README.md says {readme and readme.group(1)!r} examples; there are {len(EXAMPLES)}"
    sections = re.split(r"\n## ", text)
    for path in EXAMPLES:
        link = f"(../examples/{path.name})"
        own = [s for s in sections if link in s.split("\n\n", 2)[1]]
        assert len(own) == 1, f"{path.name}: no section of the page links it first"
        writes = re.search(r"\*\*Writes\.\*\*(.*?)(?:\n\n|$)", own[0], re.DOTALL)
        assert writes, f"{path.name}: its section has no **Writes.** paragraph"
        outputs = declared(path, "OUTPUTS")
        named = [n for span in re.findall(r"`([^`]+)`", writes.group(1))
                 for n in FILE_NAME.findall(span) if not n.startswith(".")]
        assert named, f"{path.name}: its **Writes.** paragraph names no file"
        for n in named:
            assert any(_names_match(n, o) for o in outputs), \
                f"{path.name}: the page says it writes {n}; its OUTPUTS are {outputs}"
        for o in outputs:  # and every declared output is on the page
            assert any(_names_match(n, o) for n in named), \
                f"{path.name}: writes {o} (OUTPUTS), which the page does not name"
