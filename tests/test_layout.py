"""The package boundaries (docs/developing.md): the DEM library imports nothing of the FEM
library or of the application, and has no import cycles hidden by imports inside functions;
the FEM library imports nothing of the application, has no import cycles, and imports its own
modules at the top of the file (a third-party import may stay inside the function that needs
it, as dolfinx comes through ``femcoupling._dolfinx.load()``)."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "cpp_dem" / "cpp_dem"
FEM_PKG = ROOT / "femcoupling"

_IMPORT_ALL = """
import importlib, pkgutil, sys
import {pkg}
names = [m.name for m in pkgutil.walk_packages({pkg}.__path__, "{pkg}.")]
for n in names:
    importlib.import_module(n)
bad = sorted(m for m in sys.modules if m.split(".")[0] in {banned!r})
print(len(names), ",".join(bad))
"""


def _import_all(pkg: str, banned: tuple[str, ...]) -> list[str]:
    """[number of submodules imported, (the banned modules loaded)] from a fresh interpreter."""
    code = _IMPORT_ALL.format(pkg=pkg, banned=banned)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, cwd=ROOT).stdout.split()


def test_every_cpp_dem_module_imports_without_the_fem_side():
    out = _import_all("cpp_dem", ("femcoupling", "dolfinx", "geogrid_dem", "ufl", "basix"))
    assert int(out[0]) >= 30, out  # every submodule was found and imported
    assert len(out) == 1, f"importing cpp_dem loaded {out[1]}"


def test_every_femcoupling_module_imports_without_the_app_or_the_fem_stack():
    """No femcoupling module imports geogrid_dem; none loads dolfinx, gmsh, PETSc or MPI on
    import (they come through femcoupling._dolfinx.load() when a model is built)."""
    out = _import_all("femcoupling", ("geogrid_dem", "dolfinx", "dolfinx_solver", "ufl",
                                      "basix", "gmsh", "petsc4py", "mpi4py"))
    assert int(out[0]) >= 20, out  # every submodule, in the subpackages too, was imported
    assert len(out) == 1, f"importing femcoupling loaded {out[1]}"


def _module_name(path: Path, pkg_dir: Path) -> str:
    return ".".join(path.relative_to(pkg_dir.parent).with_suffix("").parts).removesuffix(
        ".__init__")


def _absolute(node: ast.ImportFrom, path: Path, pkg_dir: Path) -> str:
    """The module an ``ImportFrom`` names, made absolute (relative imports resolved)."""
    base = node.module or ""
    if node.level:
        parts = _module_name(path, pkg_dir).split(".")
        parts = parts[: len(parts) - node.level + (path.name == "__init__.py")]
        base = ".".join(parts + ([base] if base else []))
    return base


def _imports(path: Path, pkg_dir: Path = PKG) -> set[str]:
    """The modules a file imports anywhere (inside functions too), as absolute names."""
    tree = ast.parse(path.read_text())
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = _absolute(node, path, pkg_dir)
            found.add(base)
            found |= {f"{base}.{a.name}" for a in node.names}
    return found


def _graph(pkg_dir: Path = PKG) -> dict[str, set[str]]:
    mods = {_module_name(f, pkg_dir): f for f in pkg_dir.rglob("*.py")}
    return {m: {i for i in _imports(f, pkg_dir) if i in mods and i != m
                and not m.startswith(i + ".") and not i.startswith(m + ".")}
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


def test_the_graph_sees_a_cycle_through_a_function_level_import(tmp_path):
    """A cycle closed only by an import inside a function (as femcoupling's geometry ->
    elastic -> quadrature -> materials -> geometry was) is a cycle of the graph."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.b import f\n")
    (pkg / "b.py").write_text("def f():\n    from pkg.a import g\n    return g\n")
    assert _cycles(_graph(pkg)) == [["pkg.a", "pkg.b", "pkg.a"]]


def test_femcoupling_has_no_import_cycles():
    """Imports inside functions count, and the package __init__ files are not exempt."""
    graph = _graph(FEM_PKG)
    assert len(graph) >= 20  # every module, in the subpackages too
    assert _cycles(graph) == []


def _nested_own_imports(path: Path, pkg_dir: Path) -> list[str]:
    """'file:line module' for each import of the package's own modules that is not at the
    module's top level (inside a function, or a class body); file relative to the package's
    parent folder."""
    own = pkg_dir.name
    tree = ast.parse(path.read_text())
    top = {id(n) for n in tree.body}
    for n in tree.body:  # module-level if/try blocks (TYPE_CHECKING, fallbacks) are top level
        if isinstance(n, (ast.If, ast.Try)):
            top |= {id(s) for s in ast.walk(n) if isinstance(s, (ast.Import, ast.ImportFrom))}
    found = []
    for node in ast.walk(tree):
        if id(node) in top:
            continue
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            names = [_absolute(node, path, pkg_dir)]
        else:
            continue
        for name in names:
            if name.split(".")[0] == own:
                found.append(f"{path.relative_to(pkg_dir.parent)}:{node.lineno} {name}")
    return found


def test_the_nested_import_finder_finds_one(tmp_path):
    pkg = tmp_path / "femcoupling"
    pkg.mkdir()
    f = pkg / "m.py"
    f.write_text("import numpy\nfrom femcoupling import a\n\n"
                 "def g():\n    import gmsh\n    from femcoupling.fem import b\n"
                 "    from . import c\n    return b, c\n")
    assert _nested_own_imports(f, pkg) == ["femcoupling/m.py:6 femcoupling.fem",
                                           "femcoupling/m.py:7 femcoupling"]


def test_femcoupling_imports_its_own_modules_at_the_top_of_the_file():
    """A femcoupling module imports femcoupling modules at its top, never inside a function:
    an import hidden in a function hid a six-module cycle. (Third-party imports, such as
    gmsh, h5py or basix where they are used, may stay inside functions.)"""
    found = [x for f in sorted(FEM_PKG.rglob("*.py")) for x in _nested_own_imports(f, FEM_PKG)]
    assert found == []


def test_femcoupling_holds_no_drivers():
    """The drivers and studies that compose the two libraries are the application's
    (geogrid_dem/studies/), each with its own Params."""
    assert not (FEM_PKG / "drivers").exists()
    assert (ROOT / "geogrid_dem" / "studies" / "__init__.py").is_file()


_FAILURES_AND_STEPS = """
import dataclasses, importlib, inspect, pkgutil, femcoupling
from femcoupling.fem.steps import LoadStep
failures, steps = set(), set()
for info in pkgutil.walk_packages(femcoupling.__path__, "femcoupling."):
    mod = importlib.import_module(info.name)
    for name, obj in vars(mod).items():
        if not inspect.isclass(obj) or obj.__module__ != info.name:
            continue
        if issubclass(obj, Exception) and not issubclass(obj, (Warning, ValueError)):
            failures.add(name)
        if dataclasses.is_dataclass(obj) and "Step" in name and obj is not LoadStep:
            steps.add(name)
print(sorted(failures), sorted(steps))
"""


def test_femcoupling_has_one_failure_type_and_one_step_record():
    """Every FEM model of femcoupling fails with one type (NewtonFailure: input errors are
    ValueErrors, and warnings are not failures), and every load step's record is a LoadStep
    (femcoupling.fem.steps): the two models had NewtonDivergence beside NewtonFailure, and
    StepResult and HierStep with the same Newton fields under other names; one record now
    serves every body (no subclass of it either)."""
    out = subprocess.run([sys.executable, "-c", _FAILURES_AND_STEPS], capture_output=True,
                         text=True, check=True, cwd=ROOT).stdout.strip()
    assert out == "['NewtonFailure'] []", out
