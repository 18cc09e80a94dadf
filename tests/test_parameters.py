"""Bad input is answered with errors naming the field, the value and what is allowed."""

import subprocess

import numpy as np
import pytest

import cpp_dem as dem
from conftest import PYTHON


def mat(**kw):
    base = dict(model="linear", density=2600.0, young=1e7, poisson=0.3, friction_angle_deg=30.0)
    base.update(kw)
    return dem.Material(**base)


@pytest.mark.parametrize(
    "kw, field",
    [
        (dict(density=0.0), "density=0"),
        (dict(density=-5.0), "density=-5"),
        (dict(young=0.0), "young=0"),
        (dict(poisson=0.6), "poisson=0.6"),
        (dict(poisson=0.0), "poisson=0"),  # linear law: k_s/k_n must be > 0
        (dict(model="hertz_mindlin", poisson=-1.0), "poisson=-1"),
        (dict(friction_angle_deg=90.0), "friction_angle_deg=90"),
        (dict(friction_angle_deg=-1.0), "friction_angle_deg=-1"),
        (dict(damping_normal=1.5), "damping_normal=1.5"),
        (dict(damping_shear=-0.1), "damping_shear=-0.1"),
        (dict(rolling_stiffness=-1.0), "rolling_stiffness=-1"),
        (dict(model="hertz"), "model='hertz'"),
        (dict(young=float("nan")), "young=nan"),
    ],
)
def test_material_validation_names_field_and_value(kw, field):
    with pytest.raises(ValueError) as err:
        mat(**kw)
    assert field in str(err.value)
    assert isinstance(err.value, dem.ParameterError)


def test_hertz_mindlin_accepts_negative_poisson():
    m = mat(model="hertz_mindlin", poisson=-0.5)
    assert m.poisson == -0.5


def test_a_material_pickles_exactly():
    # (to Dask workers and process pools: a periodic element's options carry one)
    import pickle

    for m in (mat(friction_angle_deg=38.66, damping_normal=0.1, rolling_stiffness=0.3,
                  rolling_friction=0.2),
              mat(model="hertz_mindlin", poisson=0.23, friction_angle_deg=1e-3 * 12345.678)):
        back = pickle.loads(pickle.dumps(m))
        names = ("model", "density", "young", "poisson", "friction_angle_deg", "damping_normal",
                 "damping_shear", "rolling_stiffness", "rolling_friction", "shear_modulus")
        assert [getattr(back, k) for k in names] == [getattr(m, k) for k in names]


def test_scene_validation():
    s = dem.Scene()
    m = s.add_material(mat())
    with pytest.raises(ValueError, match=r"radius=-0.1: must be > 0"):
        s.add_spheres([[0, 0, 0]], [-0.1], material=m)
    with pytest.raises(ValueError, match=r"radius=0: must be > 0"):
        s.add_spheres([[0, 0, 0]], [0.0], material=m)
    with pytest.raises(ValueError, match=r"material=7: no such material"):
        s.add_spheres([[0, 0, 0]], [0.1], material=7)
    with pytest.raises(ValueError, match=r"dt=0: must be > 0"):
        s.dt = 0.0
    with pytest.raises(ValueError, match=r"dt=-1e-05: must be > 0"):
        s.dt = -1e-5
    with pytest.raises(ValueError, match=r"local_damping=1: must be in \[0, 1\)"):
        s.local_damping = 1.0
    with pytest.raises(ValueError, match=r"axis=3"):
        s.add_wall(axis=3, position=0.0, sense=1, material=m)
    with pytest.raises(ValueError, match=r"sense=0"):
        s.add_wall(axis=2, position=0.0, sense=0, material=m)
    with pytest.raises(ValueError, match=r"hi\[0\]=0.0: must be > lo\[0\]=1.0"):
        s.add_box((1, 0, 0), (0, 1, 1), material=m)
    with pytest.raises(ValueError, match=r"unknown DOF 'q'"):
        s.add_spheres([[0, 0, 0]], [0.1], material=m)
        s.block_dofs(0, "x q")
    with pytest.raises(ValueError, match=r"positions: has 2 rows, the scene has 1 bodies"):
        s.positions = np.zeros((2, 3))
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        s.velocities = np.zeros((1, 2))
    with pytest.raises(ValueError, match=r"steps=-1"):
        s.run(-1)
    with pytest.raises(ValueError, match=r"max_overlap_ratio=0"):
        s.max_overlap_ratio = 0.0
    with pytest.raises(ValueError, match=r"friction_coefficient=-0.1"):
        dem.hertz_mindlin_material(density=2640, shear_modulus=3e10, poisson=0.25,
                                   friction_coefficient=-0.1)


def test_blocked_dofs_roundtrip():
    s = dem.Scene()
    m = s.add_material(mat())
    s.add_spheres([[0, 0, 0], [1, 0, 0]], [0.1, 0.1], material=m)
    s.block_dofs([0, 1], "x rz")
    assert s.blocked_dofs(1) == "x rz"
    s.block_dofs(0, "")
    assert s.blocked_dofs(0) == ""


def test_import_cpp_dem_does_not_import_dolfinx():
    code = ("import sys, cpp_dem; bad = [m for m in ('dolfinx', 'dolfinx_solver', 'ufl', "
            "'gmsh', 'petsc4py', 'femcoupling') if m in sys.modules]; assert not bad, bad")
    subprocess.run([PYTHON, "-c", code], check=True)


def test_packing_csv_roundtrip_and_errors(tmp_path):
    c = np.array([[0.1, 0.2, 0.3], [1e-3, 2e-3, 3e-3]])
    r = np.array([0.01, 0.0015])
    p = tmp_path / "pack.csv"
    dem.write_packing_csv(p, c, r)
    assert p.read_text().splitlines()[0] == "x,y,z,r"
    c2, r2 = dem.read_packing_csv(p)
    np.testing.assert_array_equal(c, c2)
    np.testing.assert_array_equal(r, r2)
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z,r\n0,0,0,-1\n")
    with pytest.raises(ValueError, match=r"bad.csv:2: r=-1.0: must be > 0"):
        dem.read_packing_csv(bad)
    bad.write_text("a,b\n")
    with pytest.raises(ValueError, match=r"header is 'a,b'"):
        dem.read_packing_csv(bad)
