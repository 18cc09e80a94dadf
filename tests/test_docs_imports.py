"""Every import of the project's packages that the docs show (code blocks, `python -c`
commands) imports: a module moved or renamed makes this fail with the page and the line."""

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("**/*.md"))]  # docs/studies/ too
_FROM = re.compile(r"from ((?:cpp_dem|femcoupling|geogrid_dem)(?:\.\w+)*) import ([\w, ]+)")
_IMPORT = re.compile(r"(?<![\w.])import ((?:cpp_dem|femcoupling|geogrid_dem)(?:\.\w+)*)")


def _imports():
    out = []
    for page in PAGES:
        for k, line in enumerate(page.read_text(encoding="utf-8").splitlines(), start=1):
            where = f"{page.relative_to(ROOT)}:{k}"
            for m in _FROM.finditer(line):
                names = [n.split()[0] for n in m[2].split(",") if n.strip()]
                out.append((where, m[1], tuple(names)))
            for m in _IMPORT.finditer(line.split(" as ")[0] if "from " not in line else ""):
                out.append((where, m[1], ()))
    return out


IMPORTS = _imports()


def test_the_docs_show_imports():
    assert len(IMPORTS) > 20


@pytest.mark.parametrize("where,module,names", IMPORTS, ids=[f"{w} {m}" for w, m, _ in IMPORTS])
def test_a_documented_import_works(where, module, names):
    if module.startswith("femcoupling"):
        pytest.importorskip("dolfinx_solver")
    mod = importlib.import_module(module)
    for n in names:
        if not hasattr(mod, n):
            importlib.import_module(f"{module}.{n}")  # a submodule
