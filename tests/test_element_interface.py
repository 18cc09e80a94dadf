"""The one interface of the DEM elements the pool hosts (cpp_dem.elements.interface; issue
37, item 3): both families satisfy it (the strain-driven DemElement, the two-way loop's
region runners), and an object that lacks a method is refused by name, before any cluster
starts."""

from __future__ import annotations

import numpy as np
import pytest

from cpp_dem._core import ParameterError
from cpp_dem.elements.interface import (RunnerElement, RunnerFactory, StrainElement,
                                        TargetElement, check_element, check_runner)


class NoTangent:
    """A strain element without network_tangent()."""

    def apply_strain(self, de, **kw):
        return np.zeros((3, 3))

    def contact_count(self):
        return 0

    def stress_scatter(self):
        return np.zeros((3, 3))

    def fd_tangent(self, **kw):
        return np.eye(6)

    def to_bytes(self):
        return b""

    @classmethod
    def from_bytes(cls, data):
        return cls()


class HalfState:
    """A runner with state() but no set_state()."""

    def __call__(self, name, initial, final):
        return name

    def state(self):
        return b""


class Echo:
    def __init__(self):
        self.seen = []

    def __call__(self, name, initial, final):
        self.seen.append(name)
        return (name, initial, final)

    def state(self):
        return repr(self.seen).encode()

    def set_state(self, data):
        import ast

        self.seen = ast.literal_eval(data.decode())


def test_both_families_satisfy_the_interface():
    from cpp_dem.elements.periodic import DemElement
    from femcoupling.materials.dem_elements import PeriodicRegionElement
    from geogrid_dem.studies.prs_element import _Runner

    assert check_element(DemElement, StrainElement, "element_type") is DemElement
    for runner in (PeriodicRegionElement(n=50), _Runner.__new__(_Runner), Echo()):
        check_runner(runner)
        el = RunnerElement(runner, "a")
        assert isinstance(el, TargetElement)
        assert check_element(el, TargetElement, "element") is el


def test_an_element_missing_a_method_is_refused_by_name():
    with pytest.raises(ParameterError, match=r"factory\(0\): a NoTangent has no "
                       r"network_tangent\(\) method; a StrainElement needs"):
        check_element(NoTangent(), StrainElement, "factory(0)")
    with pytest.raises(ParameterError, match=r"a NoTangent has no run\(\) method"):
        check_element(NoTangent(), TargetElement, "element")
    with pytest.raises(ParameterError, match=r"element_type: a object has no apply_strain"):
        check_element(object, StrainElement, "element_type")


def test_a_runner_missing_a_method_is_refused_by_name_before_a_cluster_starts():
    from cpp_dem.elements.pool import ElementPool

    with pytest.raises(ParameterError, match=r"element_runner: a HalfState has state\(\) but "
                       r"no set_state\(\) method"):
        ElementPool.runners(HalfState(), ["a"], workers=1)
    with pytest.raises(ParameterError, match=r"element_runner=3: not callable"):
        ElementPool.runners(3, ["a"], workers=1)
    with pytest.raises(ParameterError, match=r"names=\['a', 'a'\]: the regions' names, a "
                       "non-empty list of distinct"):
        ElementPool.runners(Echo(), ["a", "a"], workers=1)
    with pytest.raises(ParameterError, match=r"labels=\['x'\]: one string per element \(2\)"):
        ElementPool([b"", b""], labels=["x"], workers=1)


def test_a_runner_element_round_trips_its_state_or_the_runner_as_sent():
    el = RunnerFactory(Echo(), ["a", "b"])(1)
    assert el.run(1, 2) == ("b", 1, 2)
    back = RunnerElement.from_bytes(el.to_bytes())
    assert back.name == "b" and back.runner.seen == ["b"]  # with its state
    el2 = RunnerFactory(CountOnly(), ["a"])(0)
    el2.run(None, None)
    assert el2.runner.n == 1
    assert RunnerElement.from_bytes(el2.to_bytes()).runner.n == 0  # as it was sent
    with pytest.raises(ParameterError, match="data: not a saved RunnerElement"):
        RunnerElement.from_bytes(b"nonsense")


class CountOnly:
    """A runner without byte state."""

    def __init__(self):
        self.n = 0

    def __call__(self, name, initial, final):
        self.n += 1
        return self.n
