"""Bad inputs to the FEM side (femcoupling.fem) are refused by name before they hang a load,
pass an unsolved step as converged, or are silently ignored: each raises FemInputError (or,
for a load that cannot advance, NewtonFailure) whose message names the field, its value and
what is allowed. Coarse meshes; the whole file runs in seconds."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from femcoupling import FemInputError  # noqa: E402
from femcoupling.fem import steps as steps_mod  # noqa: E402
from femcoupling.fem.bodies import Box, Cylinder, Rectangle  # noqa: E402
from femcoupling.fem.geometry import GeogridLayer, ReinforcedSoilBody  # noqa: E402
from femcoupling.fem.model import FemModel  # noqa: E402
from femcoupling.fem.steps import LoadStep, NewtonFailure, load_path  # noqa: E402
from femcoupling.materials.continuum import (DruckerPrager, GeogridLayerMaterial,  # noqa: E402
                                             LinearElastic)

BODY = dict(width_m=4.0, height_m=3.0, footing_half_width_m=0.5, mesh_size_m=1.0,
            fine_size_m=0.25)
DP = DruckerPrager(young_pa=50e6, poisson=0.3, cohesion_pa=10e3, friction_deg=30.0)
RECT = dict(lx=0.02, ly=0.02, nx=1, ny=1)


def _soil(**kw):
    kw.setdefault("soil", DP)
    kw.setdefault("unit_weight_n_m3", 18e3)
    kw.setdefault("degree", 1)
    return FemModel(ReinforcedSoilBody(**BODY), **kw)


def _refused(match: str, f, *args, **kw) -> str:
    with pytest.raises(FemInputError, match=match) as e:
        f(*args, **kw)
    return str(e.value)


class _Load:
    """A stand-in load whose Newton converges up to load factor ``limit`` and fails above it;
    counts its solves and stops a load that would never end."""

    def __init__(self, limit: float = 0.6, most: int = 20_000) -> None:
        self.limit, self.most, self.tried = limit, most, []

    def take(self, lf: float) -> LoadStep:
        self.tried.append(lf)
        assert len(self.tried) < self.most, "the load never ends"
        if lf > self.limit:
            raise NewtonFailure(f"no convergence at {lf}")
        return LoadStep(newton_iterations=1, load_factor=lf)

    def run(self, **kw):
        args = dict(steps=1, max_cuts=4, max_newton=10, where="the test load")
        args.update(kw)
        return load_path(self.take, lambda: None, lambda lf: None, **args)


# ---- 1. max_cuts, and a step that no longer moves the load -------------------------------
@pytest.mark.parametrize("bad", [21, 60, -1, None, "3", 2.0, True])
def test_load_path_refuses_a_max_cuts_outside_0_to_20(bad):
    load = _Load()
    msg = _refused("max_cuts=", load.run, max_cuts=bad)
    assert f"max_cuts={bad!r}" in msg and "[0, 20]" in msg
    assert load.tried == []  # (refused before any solve)


def test_the_soil_body_refuses_max_cuts_before_meshing():
    msg = _refused("max_cuts=60", _soil, max_cuts=60)
    assert "[0, 20]" in msg
    _refused("max_cuts=None", _soil, max_cuts=None)


def test_a_step_below_the_load_factors_resolution_ends_the_load(monkeypatch):
    """With the bound on max_cuts lifted (as a caller bypassing it would), 60 cuts reach a
    step that no longer moves the load factor: it is never taken (it was accepted, grown back
    and failed for ever); NewtonFailure names the load factor reached."""
    monkeypatch.setattr(steps_mod, "_max_cuts", lambda v: v)
    load = _Load(limit=0.6)
    with pytest.raises(NewtonFailure, match=r"the test load: the step cut to .* no longer "
                       r"moves the load factor .* stopped at load factor 0\.(6|59999)") as e:
        load.run(max_cuts=60)
    assert "no convergence at 0.6" in str(e.value)


def test_load_path_refuses_bad_steps_and_max_newton():
    load = _Load()
    for bad in (0, -1, 0.5, float("nan"), True):
        assert f"steps={bad!r}" in _refused("steps=", load.run, steps=bad)
    for bad in (0, -1, 2.5, None, True):
        assert f"max_newton={bad!r}" in _refused("max_newton=", load.run, max_newton=bad)
    assert load.tried == []


# ---- 3. newton_rtol ----------------------------------------------------------------------
@pytest.mark.parametrize("bad", [0.5, 2.0, 0.0, -1e-3, float("nan"), "1e-3", 0.0100001])
def test_newton_rtol_outside_0_to_1e_2_is_refused_on_every_body(bad):
    for make in (lambda: _soil(newton_rtol=bad),
                 lambda: FemModel(Rectangle(**RECT), elements=None, newton_rtol=bad)):
        msg = _refused("newton_rtol=", make)
        assert msg.startswith(f"newton_rtol={bad!r}: ")
        assert ("must be in (0, 0.01]" in msg if isinstance(bad, float) and math.isfinite(bad)
                else "must be finite" in msg or "must be a real number" in msg)


def test_newton_rtol_at_its_bound_is_taken():
    m = _soil(newton_rtol=1e-2)
    assert m.newton_rtol == 1e-2


# ---- 4. set_geostatic(k0=) ---------------------------------------------------------------
@pytest.fixture(scope="module")
def dp_model():
    return _soil()


def test_a_k0_outside_the_yield_surface_is_refused_and_leaves_no_state(dp_model):
    m = dp_model
    for k0 in (50.0, 0.01):
        msg = _refused(f"k0={k0!r}: the K0 state lies outside the yield surface",
                       m.set_geostatic, k0=k0)
        assert "holds k0 in [0.2932, 3.468]" in msg  # (phi 30, c 10 kPa, 54 kPa at the base)
        assert m.history == [] and not np.any(m.sig_n)
    # just inside the range at the base: taken, in equilibrium at once
    for k0 in (0.30, 3.4):
        m.set_geostatic(k0=k0)
        r = m.history[-1]
        assert (r.newton_iterations, r.plastic_points, r.status) == (0, 0, "converged")


# ---- 5. Rectangle, Box, Cylinder: confining_pa and what a body ignores ------------------
@pytest.mark.parametrize("bad,what", [(float("nan"), "must be finite"),
                                      (float("inf"), "must be finite"),
                                      (-100e3, "must be >= 0"),
                                      ("100e3", "must be a real number")])
def test_a_bad_confining_pressure_is_refused_on_every_body(bad, what):
    for make in (lambda: Rectangle(**RECT, confining_pa=bad),
                 lambda: Rectangle(**RECT, platens="rough", confining_pa=bad),
                 lambda: Box(lx=1, ly=1, lz=1, nx=1, ny=1, nz=1, confining_pa=bad),
                 lambda: Cylinder(radius_m=0.05, height_m=0.1, size_m=0.05,
                                  confining_pa=bad)):
        assert what in _refused("confining_pa=", make)


def test_a_confining_pressure_a_homogeneous_body_would_ignore_is_refused():
    msg = _refused(r"confining_pa=100000.0: not with homogeneous=True", Rectangle, **RECT,
                   homogeneous=True, confining_pa=100e3)
    assert "give one or the other" in msg
    _refused(r"confining_pa=100000.0: not with homogeneous=True", Box, lx=1, ly=1, lz=1, nx=1,
             ny=1, nz=1, homogeneous=True, confining_pa=1e5)
    _refused(r"confining_pa=100000.0: not with homogeneous=True", Cylinder, radius_m=0.05,
             height_m=0.1, size_m=0.05, homogeneous=True, confining_pa=1e5)


def test_a_right_displacement_a_loaded_side_would_ignore_is_refused():
    smooth = Rectangle(**RECT, confining_pa=1e5)
    _refused(r"right_displacement=1e-05: the right side carries confining_pa=100000.0",
             smooth.target, top_displacement=-2e-6, right_displacement=1e-5)
    rough = Rectangle(**RECT, platens="rough", confining_pa=1e5)
    _refused(r"right_displacement=1e-05: with platens='rough'", rough.target,
             top_displacement=-2e-6, right_displacement=1e-5)
    # where the right side moves, or stays (0), it is taken
    assert smooth.target(top_displacement=-2e-6) == (-2e-6, 0.0)
    assert Rectangle(**RECT).target(top_displacement=-2e-6, right_displacement=1e-5) == \
        (-2e-6, 1e-5)
    assert Rectangle(**RECT, homogeneous=True).target(
        top_displacement=-2e-6, right_displacement=1e-5) == (-2e-6, 1e-5)


# ---- 9. layer_force_n_per_m --------------------------------------------------------------
@pytest.fixture(scope="module")
def layered_model():
    body = ReinforcedSoilBody(**BODY, layers=(GeogridLayer(z_m=2.5, x_min_m=0.0, x_max_m=2.0,
                                                           thickness_m=0.05),))
    return FemModel(body, soil=LinearElastic(50e6, 0.3), unit_weight_n_m3=18e3, degree=1,
                    layers=[GeogridLayerMaterial(1e6, prestress_n_per_m=1e3)])


def test_a_layer_the_body_does_not_have_is_refused(layered_model):
    m = layered_model
    for bad in (1, -1, 7, True, 0.0, "0"):
        msg = _refused(f"i={bad!r}: must be a whole number in \\[0, 0\\]",
                       m.layer_force_n_per_m, bad)
        assert "1 geogrid layers" in msg
    assert math.isfinite(m.layer_force_n_per_m(0))


def test_a_reversed_or_empty_x_range_is_refused(layered_model):
    m = layered_model
    _refused(r"x_range_m=\(1.0, 0.0\): must be \(low, high\) with low < high",
             m.layer_force_n_per_m, 0, x_range_m=(1.0, 0.0))
    _refused(r"x_range_m=\(3.0, 4.0\): no cell of geogrid layer 0 \(x from 0 to 2 m\)",
             m.layer_force_n_per_m, 0, x_range_m=(3.0, 4.0))
    _refused(r"x_range_m\[1\]=nan: must be finite", m.layer_force_n_per_m, 0,
             x_range_m=(0.0, float("nan")))
    _refused(r"x_range_m=1.0: must be \(low, high\)", m.layer_force_n_per_m, 0, x_range_m=1.0)
    assert math.isfinite(m.layer_force_n_per_m(0, x_range_m=(0.0, 1.0)))


# ---- 10. max_newton ----------------------------------------------------------------------
@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "10"])
def test_max_newton_below_1_or_not_whole_is_refused_on_every_body(bad):
    for make in (lambda: _soil(max_newton=bad),
                 lambda: FemModel(Rectangle(**RECT), elements=None, max_newton=bad)):
        assert f"max_newton={bad!r}: must be a whole number >= 1" in _refused("max_newton=",
                                                                               make)


# ---- 11. types that slipped past the checks ----------------------------------------------
def test_whole_numbers_and_flags_of_the_wrong_type_are_refused():
    _refused(r"degree=2.0: must be 1 or 2 \(a whole number, not a float\)", _soil, degree=2.0)
    _refused(r"degree=True: must be 1 or 2", _soil, degree=True)
    _refused(r"dim=2.0: must be 2 or 3 \(a whole number, not a float\)", ReinforcedSoilBody,
             **BODY, dim=2.0)
    _refused(r"nx=2.5: must be a whole number >= 1", Rectangle, lx=0.02, ly=0.02, nx=2.5, ny=1)
    _refused(r"ny=True: must be a whole number >= 1", Rectangle, lx=0.02, ly=0.02, nx=1,
             ny=True)
    _refused(r"degree=2.0: must be 1 \(P1", Rectangle, **RECT, degree=2.0, homogeneous=True)
    _refused(r"homogeneous='no': must be True or False", Rectangle, **RECT, homogeneous="no")
    _refused(r"homogeneous=1: must be True or False", Box, lx=1, ly=1, lz=1, nx=1, ny=1, nz=1,
             homogeneous=1)
    _refused(r"lx='1': must be a real number", Rectangle, lx="1", ly=0.02, nx=1, ny=1)
    # (NumPy whole numbers are whole numbers)
    assert Rectangle(lx=0.02, ly=0.02, nx=np.int64(2), ny=1).nx == 2


def test_a_comm_that_is_not_a_communicator_is_refused():
    _refused(r"comm='x': an mpi4py communicator", _soil, comm="x")
    _refused(r"comm=5: an mpi4py communicator", FemModel, Rectangle(**RECT), elements=None,
             comm=5)


# ---- 12. NaN and inf boundary values -----------------------------------------------------
def test_non_finite_boundary_values_are_refused_by_the_body():
    r = Rectangle(**RECT, homogeneous=True)
    _refused(r"top_displacement=nan: must be finite", r.target, top_displacement=float("nan"))
    _refused(r"right_displacement=inf: must be finite", r.target, top_displacement=-4e-6,
             right_displacement=float("inf"))
    _refused(r"top_displacement='abc': must be a real number", r.target,
             top_displacement="abc")
    box = Box(lx=1, ly=1, lz=1, nx=1, ny=1, nz=1, confining_pa=1e5)
    _refused(r"top_displacement=-inf: must be finite", box.target,
             top_displacement=-float("inf"))


def test_a_non_finite_step_leaves_the_model_where_it_was():
    from cpp_dem.elements.pool import ElementPool, PeriodicFactory

    with ElementPool.build(2, PeriodicFactory(n=100, same=True), workers=1) as pool:
        m = FemModel(Rectangle(**RECT, homogeneous=True), elements=pool)
        u = m.u.x.array.copy()
        _refused(r"top_displacement=nan: must be finite", m.step,
                 top_displacement=float("nan"))
        _refused(r"right_displacement=inf: must be finite", m.step, top_displacement=-4e-6,
                 right_displacement=float("inf"))
        _refused(r"max_cuts=21: must be a whole number in \[0, 20\]", m.step,
                 top_displacement=-2e-6, max_cuts=21)
        assert m.history == [] and np.array_equal(m.u.x.array, u)
