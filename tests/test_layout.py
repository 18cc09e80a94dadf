"""The package boundaries (docs/developing.md): the DEM library imports nothing of the FEM
library or of the application, and the DEM library has no import cycles hidden by imports
inside functions."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "cpp_dem" / "cpp_dem"

_IMPORT_ALL = """
import importlib, pkgutil, sys
import cpp_dem
names = [m.name for m in pkgutil.walk_packages(cpp_dem.__path__, "cpp_dem.")]
for n in names:
    importlib.import_module(n)
bad = sorted(m for m in sys.modules if m.split(".")[0] in ("femcoupling", "dolfinx", "geogrid_dem", "ufl", "basix"))
print(len(names), ",".join(bad))
"""


def test_every_cpp_dem_module_imports_without_the_fem_side():
    out = subprocess.run([sys.executable, "-c", _IMPORT_ALL], capture_output=True, text=True,
                         check=True).stdout.split()
    assert int(out[0]) >= 30, out  # every submodule was found and imported
    assert len(out) == 1, f"importing cpp_dem loaded {out[1]}"


def _imports(path: Path) -> set[str]:
    """The modules a file imports anywhere (inside functions too), as absolute names."""
    tree = ast.parse(path.read_text())
    pkg = ".".join(path.relative_to(PKG.parent).with_suffix("").parts)
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")[: len(pkg.split(".")) - node.level + (path.name == "__init__.py")]
                base = ".".join(parts + ([base] if base else []))
            found.add(base)
            found |= {f"{base}.{a.name}" for a in node.names}
    return found


def _graph() -> dict[str, set[str]]:
    mods = {}
    for f in PKG.rglob("*.py"):
        name = ".".join(f.relative_to(PKG.parent).with_suffix("").parts).removesuffix(".__init__")
        mods[name] = f
    return {m: {i for i in _imports(f) if i in mods and i != m and not m.startswith(i + ".")
                and not i.startswith(m + ".")}
            for m, f in mods.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The cycles of ``graph`` (a few, by depth-first search), ignoring package __init__ edges
    that only re-export."""
    found, state = [], {}

    def visit(n, stack):
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                found.append(stack[stack.index(m):] + [m])
            elif m not in state:
                visit(m, stack)
        stack.pop()
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [])
    return found


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == [["a", "b", "c", "a"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_cpp_dem_has_no_import_cycles():
    graph = _graph()
    # the face re-exports its parts: edges out of the package __init__ files are not cycles
    for m in list(graph):
        if (PKG.parent / m.replace(".", "/") / "__init__.py").exists():
            graph[m] = set()
    assert _cycles(graph) == []
