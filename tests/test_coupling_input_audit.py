"""The coupling's inputs refused at their entry, each naming the field, its value and what
is allowed: the periodic region element's fields and its servo (a chunk of no steps ran
forever), the two-way loop's arguments (checked before the first FEM solve) and its history
rows (each region under its own name), the state, records and history of another run, the
handover's floors and bounds, and the pool's client. Stand-in models and runners, tiny
elements, no Dask cluster."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest

from femcoupling import FemInputError
from femcoupling.coupling.handover import (fem_to_dem, secant_stiffness, secant_tangent,
                                           spd_floor)

S0 = np.diag([-50e3, -50e3, -100e3])


# ---- the periodic region element and its servo --------------------------------------------

class _NoElement:
    """An element that must not be touched: the servo's settings are refused first."""

    def __getattr__(self, name):
        raise AssertionError(f"the element was used ({name}) before the settings were checked")


@pytest.mark.parametrize("kw, field", [
    (dict(chunk_steps=0), "chunk_steps=0"), (dict(chunk_steps=-5), "chunk_steps=-5"),
    (dict(chunk_steps=2.5), "chunk_steps=2.5"), (dict(chunk_steps=True), "chunk_steps=True"),
    (dict(max_strain=math.inf), "max_strain=inf"), (dict(max_strain=0.0), "max_strain=0.0"),
    (dict(max_strain=math.nan), "max_strain=nan"), (dict(tol=0.0), "tol=0.0"),
    (dict(tol=-1e-3), "tol=-0.001"), (dict(unbalanced=0.0), "unbalanced=0.0"),
    (dict(unbalanced="1e-3"), "unbalanced='1e-3'")])
def test_servo_refuses_settings_that_never_end_or_make_no_sense(kw, field):
    from femcoupling.materials.dem_elements import servo

    args = {**dict(tol=0.005, unbalanced=1e-3, chunk_steps=50, max_strain=0.05), **kw}
    with pytest.raises(FemInputError, match=re.escape(field)):
        servo(_NoElement(), S0, **args)


@pytest.mark.parametrize("kw, msg", [
    (dict(n=1), "n=1: must be a whole number >= 2"), (dict(n=30.0), "n=30.0"),
    (dict(n=True), "n=True"), (dict(seed=-1), "seed=-1: must be a whole number >= 0"),
    (dict(seed=1.5), "seed=1.5"),
    (dict(prep_friction_deg=90.0), r"prep_friction_deg=90.0: must be in [0, 90)"),
    (dict(prep_friction_deg=-1.0), "prep_friction_deg=-1.0"),
    (dict(tol=0.0), "tol=0.0: must be in (0, 1)"), (dict(tol=math.nan), "tol=nan"),
    (dict(unbalanced=2.0), "unbalanced=2.0: must be in (0, 1)"),
    (dict(max_strain=math.inf), "max_strain=inf"),
    (dict(max_strain=-0.05), "max_strain=-0.05: must be in (0, 1)"),
    (dict(chunk_steps=0), "chunk_steps=0: must be a whole number >= 1"),
    (dict(chunk_steps=100.0), "chunk_steps=100.0"),
    (dict(cache_dir=3), "cache_dir=3"), (dict(options=[1]), "options=[1]")])
def test_periodic_region_element_refuses_its_fields_out_of_range(kw, msg):
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    with pytest.raises(FemInputError, match=re.escape(msg)):
        PeriodicRegionElement(**kw)


def test_a_field_set_after_the_runner_was_made_is_checked_before_it_prepares():
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    runner = PeriodicRegionElement(n=30)
    runner.n = 0
    with pytest.raises(FemInputError, match=re.escape("n=0: must be a whole number >= 2")):
        runner.prepare("a", fem_to_dem(S0))


# ---- the two-way loop: arguments at entry, history rows under their names -----------------

class _Model:
    """A stand-in FEM model (fake2way style) that counts its solves."""

    def __init__(self):
        from mpi4py import MPI

        self.comm, self.calls, self.loaded, self.E = MPI.COMM_SELF, 0, False, {}

    def save_state(self):
        return {}

    def restore_state(self, state):
        self.loaded = False

    def region_stress(self, r):
        self.calls += 1
        if not self.loaded:
            return np.array(S0)
        return 2.0 * S0 * (1 + 1e6 / self.E.get(r, 10e6))

    def set_region_material(self, r, m):
        self.E[r] = m.young_pa


def _load(m):
    m.loaded = True


def _runner(name, ini, fin):
    from femcoupling.coupling.twoway import ElementResponse

    ds = fin.normal_pa - ini.normal_pa
    return ElementResponse(ini.normal_pa, fin.normal_pa, ds / 20e6, {})


def _two_way(model=None, **kw):
    from femcoupling.coupling.twoway import two_way

    args = dict(regions=["A"], load=_load, element_runner=_runner)
    args.update(kw)
    return two_way(_Model() if model is None else model, **args)


@pytest.mark.parametrize("kw, msg", [
    (dict(regions=[]), "regions=[]: must name at least one element region"),
    (dict(regions="AB"), "regions='AB': must be a list of element regions"),
    (dict(regions=["A", "A"]), "['A'] listed more than once"),
    (dict(regions=["A", 3]), "3 is not a name"),
    (dict(tol=math.inf), "tol=inf: must be a finite number > 0"),
    (dict(tol=math.nan), "tol=nan: must be a finite number > 0"),
    (dict(tol=True), "tol=True: must be a finite number > 0"),
    (dict(tol="0.1"), "tol='0.1': must be a finite number > 0"),
    (dict(tol=0.0), "tol=0.0: must be a finite number > 0"),
    (dict(scatter_factor="1"), "scatter_factor='1': must be a finite number > 0"),
    (dict(workers=True), "workers=True: must be an integer >= 1"),
    (dict(relaxation=True), "relaxation=True"),
    (dict(max_rotation_deg="15"), "max_rotation_deg='15': must be a real number"),
    (dict(max_strain_ratio=math.inf), "max_strain_ratio=inf"),
    (dict(load="footing"), "load='footing': must be callable"),
    (dict(element_runner=None), "element_runner=None: must be callable"),
    (dict(log=print, history_names="A"), "history_names='A'"),
    (dict(log=3), "log=3: must be callable"),
    (dict(client="tcp://127.0.0.1:1"), "client='tcp://127.0.0.1:1': must be a "
                                        "dask.distributed.Client")])
def test_two_way_checks_its_arguments_before_the_first_fem_solve(kw, msg):
    model = _Model()
    with pytest.raises(FemInputError, match=re.escape(msg)):
        _two_way(model, **kw)
    assert model.calls == 0  # (refused at entry: no FEM stress asked for)


def test_two_way_writes_no_history_row_under_another_region(tmp_path):
    from femcoupling.coupling.twoway import HandoverHistory

    model = _Model()
    with HandoverHistory(tmp_path / "h1.h5", regions=["A", "B"]) as h:
        with pytest.raises(FemInputError, match=re.escape(
                "history_names=['b']: ['b'] not among the history's regions ['A', 'B']")):
            _two_way(model, regions=["B"], history=h, history_names=["b"])
        assert h.n == 0
    with HandoverHistory(tmp_path / "h2.h5", regions=["A"]) as h:
        with pytest.raises(FemInputError, match=re.escape(
                "regions=['B']: ['B'] not among the history's regions ['A']")):
            _two_way(model, regions=["B"], history=h)
        assert h.n == 0
    assert model.calls == 0
    # named as the history lists it: its rows under that region (index 1)
    import h5py

    with HandoverHistory(tmp_path / "h3.h5", regions=["A", "B"]) as h, \
            warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the stand-in's loop stalls: no strains)
        _two_way(regions=["x"], history=h, history_names=["B"])
    with h5py.File(tmp_path / "h3.h5") as f:
        assert len(f["region"]) > 0 and set(f["region"][:]) == {1.0}


def test_history_append_file_refuses_another_run_s_metadata(tmp_path):
    import h5py

    from femcoupling.coupling.twoway import HandoverHistory

    with HandoverHistory(tmp_path / "b.h5", regions=["A"],
                         metadata={"tol": 0.5, "E_pa": 5e9}) as b:
        b.append(iteration=1, region=0)
    with HandoverHistory(tmp_path / "a.h5", regions=["A"],
                         metadata={"tol": 0.02, "E_pa": 1e7}) as a:
        with pytest.raises(FemInputError, match=re.escape(
                "E_pa: 5000000000.0 there, 10000000.0 here; tol: 0.5 there, 0.02 here")):
            a.append_file(tmp_path / "b.h5")
        assert a.n == 0
    with HandoverHistory(tmp_path / "c.h5", regions=["A"]) as c:  # (no metadata at all)
        with pytest.raises(FemInputError, match=re.escape("tol: 0.5 there, none here")):
            c.append_file(tmp_path / "b.h5")
    # the same metadata: merged
    with HandoverHistory(tmp_path / "d.h5", regions=["A"],
                         metadata={"tol": 0.5, "E_pa": 5e9}) as d:
        d.append_file(tmp_path / "b.h5")
    with h5py.File(tmp_path / "d.h5") as f:
        assert f["iteration"][:].tolist() == [1.0]


# ---- the state and the records of another run ---------------------------------------------

@pytest.fixture(scope="module")
def prepared():
    """A 30-grain runner, its element prepared at S0, and its state."""
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    runner = PeriodicRegionElement(n=30, chunk_steps=500)
    el, kept = runner.prepare("A", fem_to_dem(S0))
    assert not kept
    return runner, el.to_bytes(), runner.state()


def test_a_runner_refuses_the_state_of_a_runner_of_other_settings(prepared):
    from cpp_dem.elements import state_format
    from femcoupling.materials.dem_elements import _KEPT_KIND, PeriodicRegionElement

    _, data, state = prepared
    other = PeriodicRegionElement(n=40, seed=7, chunk_steps=500)
    with pytest.raises(FemInputError, match=re.escape(
            "other settings (n: 30 there, 40 here; seed: 1 there, 7 here)")):
        other.set_state(state)
    assert other._kept == {}
    # a state without its settings: refused
    fields, parts = state_format.unpack(state, _KEPT_KIND)
    bare = state_format.pack(_KEPT_KIND, {"keys": fields["keys"]}, parts)
    with pytest.raises(FemInputError, match="without the settings"):
        PeriodicRegionElement(n=30, chunk_steps=500).set_state(bare)
    # the same settings: its element taken, bitwise
    same = PeriodicRegionElement(n=30, chunk_steps=500)
    same.set_state(state)
    el, kept = same.prepare("A", fem_to_dem(S0))
    assert kept and el.to_bytes() == data


def test_a_runner_whose_settings_changed_does_not_take_its_earlier_elements(prepared):
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    _, data, state = prepared
    runner = PeriodicRegionElement(n=30, chunk_steps=500)
    runner.set_state(state)
    assert len(runner._kept) == 1
    runner.seed = 2  # (its kept element is of seed 1)
    el, kept = runner.prepare("A", fem_to_dem(S0))
    assert not kept and el.to_bytes() != data


def test_region_material_records_refuse_an_earlier_run_s_file(prepared, tmp_path):
    import h5py

    from cpp_dem.elements.periodic import DemElement
    from femcoupling.materials.dem_elements import DemRegionMaterial

    _, data, _ = prepared
    path = tmp_path / "region_records.h5"
    m = DemRegionMaterial(DemElement.from_bytes(data), records=path)
    m.trial(np.diag([-1e-5, 0, 0]))
    m.commit()
    with pytest.raises(FemInputError, match=re.escape(
            f"records={str(path)!r}: holds the records of an earlier run; give a new file, "
            "or overwrite=True")):
        DemRegionMaterial(DemElement.from_bytes(data), records=path)
    m2 = DemRegionMaterial(DemElement.from_bytes(data), records=path, overwrite=True)
    m2.trial(np.diag([-1e-5, 0, 0]))
    m2.commit()
    with h5py.File(path) as f:
        assert f["step"][:].tolist() == [1]  # (the second run's only)


def test_pool_materials_refuse_records_client_and_floor_before_a_cluster_starts(
        tmp_path, monkeypatch):
    from cpp_dem.elements.pool import ElementPool
    from femcoupling.materials.dem_elements import PeriodicRegionElement, PoolRegionMaterials

    def no_pool(*a, **k):
        raise AssertionError("a pool was built before the inputs were checked")

    monkeypatch.setattr(ElementPool, "build", no_pool)
    path = tmp_path / "cells.h5"
    path.write_bytes(b"")
    runner = PeriodicRegionElement(n=30)
    with pytest.raises(FemInputError, match=re.escape(f"records={str(path)!r}: holds")):
        PoolRegionMaterials.build({"a": S0}, runner, workers=1, records=path)
    with pytest.raises(FemInputError, match=re.escape("client='tcp://127.0.0.1:1'")):
        PoolRegionMaterials.build({"a": S0}, runner, client="tcp://127.0.0.1:1")
    with pytest.raises(FemInputError, match=re.escape("min_eig_fraction=2.0")):
        PoolRegionMaterials.build({"a": S0}, runner, workers=1, min_eig_fraction=2.0)


# ---- the handover's floors and bounds ------------------------------------------------------

T = np.diag([3e7, 2e7, 1e7, 1e7, -1e6, 5e6])


@pytest.mark.parametrize("f, msg", [
    (-1.0, "min_eig_fraction=-1.0: must be in (0, 1)"), (0.0, "min_eig_fraction=0.0"),
    (1.0, "min_eig_fraction=1.0"), (2.0, "min_eig_fraction=2.0: must be in (0, 1)"),
    (math.nan, "min_eig_fraction=nan: must be finite"),
    (True, "min_eig_fraction=True: must be a real number")])
def test_the_eigenvalue_floor_is_a_fraction_in_0_1(f, msg):
    with pytest.raises(FemInputError, match=re.escape(msg)):
        spd_floor(T, f)
    de = np.array([1e-4, 0, 0, 0, 0, 0])
    with pytest.raises(FemInputError, match=re.escape(msg)):
        secant_tangent(T, strain_increment=de, stress_increment_pa=T @ de,
                       min_eig_fraction=f)


def test_region_material_refuses_an_eigenvalue_floor_out_of_range(prepared):
    from cpp_dem.elements.periodic import DemElement
    from femcoupling.materials.dem_elements import DemRegionMaterial

    with pytest.raises(FemInputError, match=re.escape("min_eig_fraction=-1.0")):
        DemRegionMaterial(DemElement.from_bytes(prepared[1]), min_eig_fraction=-1.0)

    class Untouched(_NoElement):
        kind = "periodic"

    with pytest.raises(FemInputError, match=re.escape("min_eig_fraction=2.0: must be in")):
        DemRegionMaterial(Untouched(), min_eig_fraction=2.0)  # (before the element is read)


@pytest.mark.parametrize("bounds, msg", [
    ((0.45, 0.0), "poisson_bounds=(0.45, 0.0): must be (lo, hi) with -1 <= lo <= hi < 0.5"),
    ((0.6, 0.9), "poisson_bounds=(0.6, 0.9)"), ((-1.5, 0.3), "poisson_bounds=(-1.5, 0.3)"),
    ((0.0, 0.5), "poisson_bounds=(0.0, 0.5)"),
    ((math.nan, 0.45), "poisson_bounds[0]=nan: must be finite"),
    ((0.0, math.inf), "poisson_bounds[1]=inf: must be finite"),
    ((0.3,), "poisson_bounds=(0.3,): must be a pair"), ("ab", "poisson_bounds='ab'")])
def test_secant_stiffness_refuses_poisson_bounds_outside_an_isotropic_solid_s(bounds, msg):
    ds, de = np.array([100e3, 40e3, 40e3]), np.array([1e-3, -5e-4, -5e-4])
    with pytest.raises(FemInputError, match=re.escape(msg)):
        secant_stiffness(stress_increment_pa=ds, strain_increment=de, poisson_bounds=bounds)
    # a fixed nu (lo = hi) stays allowed
    assert secant_stiffness(stress_increment_pa=ds, strain_increment=de,
                            poisson_bounds=(0.3, 0.3))[1] == 0.3


@pytest.mark.parametrize("ms, msg", [(-50e3, "min_stress_pa=-50000.0: must be >= 0 Pa"),
                                     (math.nan, "min_stress_pa=nan: must be finite")])
def test_fem_to_dem_refuses_a_pulling_wall_floor(ms, msg):
    with pytest.raises(FemInputError, match=re.escape(msg)):
        fem_to_dem(np.diag([10e3, -50e3, -100e3]), min_stress_pa=ms)


# ---- the pool's client ----------------------------------------------------------------------

@pytest.mark.parametrize("client", ["tcp://127.0.0.1:1", "not an address", 12345])
def test_runner_pool_refuses_a_client_that_is_not_one(client):
    from femcoupling.coupling.runner_pool import RunnerPool
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    with pytest.raises(FemInputError, match=re.escape(
            f"client={client!r}: must be a dask.distributed.Client")) as e:
        RunnerPool(PeriodicRegionElement(n=30), ["A", "B"], client=client)
    assert "dask_client" in str(e.value)



def test_an_element_that_hovers_near_its_target_is_stopped():
    # Neither settled nor strained past max_strain: the servo used to loop for ever.
    from femcoupling.materials import dem_elements as de

    class Hover:
        calls = 0

        def strain(self):
            return np.full((3, 3), 1e-6 * (self.calls % 2))

        def stress(self):
            return np.zeros((3, 3))

        def apply_stress(self, target, *, tol, unbalanced, max_steps):
            self.calls += 1
            raise RuntimeError("not settled")

    el = Hover()
    from femcoupling.coupling.handover import HandoverError

    with pytest.raises(HandoverError, match=r"neither reached its target stress .* nor "
                                                   r"strained past max_strain=0.05 in 2000000 "
                                                   r"steps"):
        de.servo(el, np.zeros((3, 3)), tol=0.01, unbalanced=0.01, chunk_steps=1000,
                 max_strain=0.05)
    assert el.calls == 2000
