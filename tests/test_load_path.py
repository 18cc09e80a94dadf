"""The one load-step loop of every FEM model (femcoupling.fem.steps.load_path): what it takes,
cuts, grows back and where it leaves a load it cannot finish. Synthetic steps: a Newton that
converges only below a load factor, counted."""

import ast
from pathlib import Path

import pytest

from femcoupling.fem.steps import LoadStep, NewtonFailure, load_path

ROOT = Path(__file__).resolve().parents[1]


class _Load:
    """A load whose Newton converges up to ``limit`` (taking ``its`` iterations) and fails
    above it; the state is the load factor of the last accepted step."""

    def __init__(self, limit=2.0, its=3):
        self.limit, self.its = limit, its
        self.tried, self.accepted, self.at, self.rollbacks = [], 0.0, 0.0, 0

    def take(self, lf):
        self.tried.append(lf)
        self.at = lf
        if lf > self.limit:
            raise NewtonFailure(f"no convergence at {lf}")
        self.accepted = lf
        return LoadStep(newton_iterations=self.its)

    def rollback(self):
        self.rollbacks += 1
        self.at = self.accepted

    def restore(self, lf):
        self.at = lf


def _run(load, **kw):
    args = dict(steps=1, max_cuts=4, max_newton=10, where="the test load")
    args.update(kw)
    return load_path(load.take, load.rollback, load.restore, **args)


def test_a_load_newton_carries_is_taken_in_its_nominal_steps():
    load = _Load()
    out = _run(load, steps=4)
    assert load.tried == [0.25, 0.5, 0.75, 1.0] and len(out) == 4 and load.rollbacks == 0


def test_a_failed_step_is_halved_and_an_easy_one_grows_back():
    # fails above 0.6: 1.0 fails, 0.5 passes (easy: 3 <= 10 // 2) and grows back to 1.0,
    # which fails, 0.75 fails, 0.625 fails, 0.5625 passes ...
    load = _Load(limit=0.6, its=3)
    with pytest.raises(NewtonFailure, match=r"the test load: Newton failed at load factor "
                       r"0.6\d* with the step cut 4 times \(to 1/16 of its nominal size\); "
                       r"the stage stopped at load factor 0.5\d*.*no convergence at 0.6"):
        _run(load)
    assert load.tried[:3] == [1.0, 0.5, 1.0]
    assert 0.5 < load.accepted <= 0.6
    assert load.at == load.accepted  # the load is put back where the last step was accepted
    assert load.rollbacks == sum(lf > 0.6 for lf in load.tried)


def test_a_hard_step_keeps_the_cut_size():
    # not easy (8 > 10 // 2): after the cut the next steps keep the halved size
    load = _Load(limit=2.0, its=8)
    tried = []

    def take(lf):
        if not tried:
            tried.append(lf)
            raise NewtonFailure("first try")
        tried.append(lf)
        return load.take(lf)

    load_path(take, load.rollback, load.restore, steps=1, max_cuts=4, max_newton=10,
              where="x")
    assert tried == [1.0, 0.5, 1.0]


def test_no_cut_at_all_fails_at_once():
    load = _Load(limit=0.0)
    with pytest.raises(NewtonFailure, match=r"cut 0 times .* stopped at load factor 0\b"):
        _run(load, max_cuts=0)
    assert load.tried == [1.0] and load.at == 0.0


def test_every_fem_model_steps_through_the_one_loop():
    """No model of femcoupling halves its steps by a loop of its own: the one model is a
    FemSolver, whose _load (the soil body's stages, the step of every body of
    femcoupling.fem.bodies: rectangle, box, cylinder) is the one call of load_path."""
    calls, own = set(), []
    for path in sorted((ROOT / "femcoupling").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "load_path":
                calls.add(path.relative_to(ROOT).as_posix())
            # a step halved in place, or a recursive cut: the marks of a loop of its own
            if isinstance(node, ast.AugAssign) and isinstance(node.op, ast.Div) \
                    and path.name != "steps.py":
                own.append(f"{path.name}:{node.lineno}")
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Sub) \
                    and isinstance(node.left, ast.Name) and node.left.id == "max_cuts":
                own.append(f"{path.name}:{node.lineno}")
    assert calls == {"femcoupling/fem/solver.py"}, calls  # (FemSolver._load)
    assert own == [], own
    from femcoupling.fem.model import FemModel, FemSolver

    assert FemModel._load is FemSolver._load and FemModel.status is FemSolver.status


def test_one_model_class_solves_every_body():
    """Issue 61: one class solves the continuum. FemModel is the only FemSolver of the
    package, and every class that builds a QuadratureSystem (the spaces, forms and solver)
    is one of its parts."""
    import importlib
    import inspect
    import pkgutil

    import femcoupling
    from femcoupling.fem.model import FemModel, FemSolver

    solvers, builders = set(), set()
    for info in pkgutil.walk_packages(femcoupling.__path__, "femcoupling."):
        mod = importlib.import_module(info.name)
        for _, cls in inspect.getmembers(mod, inspect.isclass):
            if cls.__module__ != mod.__name__:
                continue
            if issubclass(cls, FemSolver) and cls is not FemSolver:
                solvers.add(cls)
            if "QuadratureSystem(" in inspect.getsource(cls):
                builders.add(cls)
    assert solvers == {FemModel}, solvers
    assert builders and all(c in FemModel.__mro__ for c in builders), builders


def test_every_footing_model_measures_its_footing_by_the_same_names():
    """The soil body and a Rectangle with a footing give the footing's pressure and
    settlement under one name each (SI units in the names), the same methods of the one
    model."""
    from femcoupling.fem.model import FemModel

    assert callable(getattr(FemModel, "footing_pressure_pa", None))
    assert callable(getattr(FemModel, "footing_settlement_m", None))
    assert not hasattr(FemModel, "footing_pressure")
