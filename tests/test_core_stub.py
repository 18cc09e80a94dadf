"""The typed stub cpp_dem/_core.pyi covers the compiled module: every public name of
cpp_dem._core, and every public method and property of its classes, appears in it (so a
binding added without regenerating the stub, scripts/gen_core_stub.sh, fails here)."""

import ast
from pathlib import Path

import cpp_dem._core as core

STUB = Path(__file__).resolve().parents[1] / "cpp_dem" / "cpp_dem" / "_core.pyi"


def stub_names():
    tree = ast.parse(STUB.read_text())
    top, members = set(), {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            top.add(node.name)
            members[node.name] = {n.name for n in node.body
                                  if isinstance(n, (ast.FunctionDef, ast.AnnAssign))
                                  and not isinstance(n, ast.AnnAssign)} | {
                n.target.id for n in node.body if isinstance(n, ast.AnnAssign)}
        elif isinstance(node, ast.FunctionDef):
            top.add(node.name)
        elif isinstance(node, ast.AnnAssign):
            top.add(node.target.id)
    return top, members


def test_stub_parses_and_is_shipped_typed():
    ast.parse(STUB.read_text())
    assert (STUB.parent / "py.typed").exists()


def test_every_public_name_of_the_module_is_in_the_stub():
    top, members = stub_names()
    public = [n for n in dir(core) if not n.startswith("_")]
    missing = [n for n in public if n not in top]
    assert not missing, f"not in _core.pyi (run scripts/gen_core_stub.sh): {missing}"
    for name in public:
        obj = getattr(core, name)
        if isinstance(obj, type) and not issubclass(obj, BaseException):
            attrs = [a for a in vars(obj) if not a.startswith("_")]
            gone = [a for a in attrs if a not in members.get(name, set())]
            assert not gone, f"{name}: {gone} not in _core.pyi (run scripts/gen_core_stub.sh)"
