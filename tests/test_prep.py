"""Preparation: radius growth to a stress, REFD to a porosity, and clear failures."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import measure
from cpp_dem.protocols import prep
from cpp_dem.build import psd
from cpp_dem.build.packing import loose_cloud
from cpp_dem.protocols.triaxial import build_box_sample


def sample(seed=4):
    r = psd.radii_uniform(0.005, 0.0015, 250, seed=seed)
    c, r = loose_cloud(r * 0.75, (0, 0, 0), (0.07, 0.07, 0.07), seed=seed)
    return build_box_sample(c, r, (0, 0, 0), (0.07, 0.07, 0.07), young=1e7, poisson=0.3,
                            friction_deg=30, density=2650, local_damping=0.3)


def test_grow_to_stress():
    s = sample()
    res = prep.grow_to_stress(s.scene, s.walls, 2e4, tol=0.01, unbalanced=0.01)
    assert res.converged
    assert abs(res.mean_stress / 2e4 - 1) <= 0.01 and res.unbalanced_force < 0.01
    assert res.extra["growth_factor"] > 1


def test_refd_reaches_porosity_and_restores_friction():
    s = sample()
    res = prep.refd(s.scene, s.walls, s.material, stress=2e4, porosity=0.44,
                    friction_steps_deg=(10.0, 0.0))
    assert res.friction_deg_reached == 0.0  # 0.469 at 30 deg, 0.446 at 10, 0.422 at 0
    assert res.porosity <= 0.44 + 0.005 and abs(res.stress / 2e4 - 1) <= 0.01
    assert set(s.scene.material_ids) == {s.material}  # friction restored


def test_refd_unreachable_porosity_fails_clearly():
    s = sample()
    with pytest.raises(dem.ParameterError, match=r"porosity=0.2: not reachable; REFD reached"):
        prep.refd(s.scene, s.walls, s.material, stress=2e4, porosity=0.2,
                  friction_steps_deg=(0.0,), max_steps_per_stage=20_000)


def test_wrong_sign_stress_refused():
    s = sample()
    with pytest.raises(dem.ParameterError, match=r"stress=-75000.0: must be > 0"):
        prep.compact_isotropic(s.scene, s.walls, -75e3)


def test_drive_to_stresses_reaches_an_anisotropic_state_and_solve_to_equilibrium_settles():
    import cpp_dem as dem
    from cpp_dem import measure
    from cpp_dem.protocols import prep
    from cpp_dem.build.packing import loose_cloud
    from cpp_dem.protocols.triaxial import build_box_sample

    c, r = loose_cloud(np.full(150, 0.003), (0, 0, 0), (0.05, 0.05, 0.05), seed=4)
    sample = build_box_sample(c, r * 1.2, (0, 0, 0), (0.05, 0.05, 0.05), young=5e7, poisson=0.3,
                              friction_deg=30, density=2650, local_damping=0.3)
    targets = (10e3, 10e3, 25e3)  # Pa, a K0-like state
    st = prep.drive_to_stresses(sample.scene, sample.walls, targets,
                                controller=sample.controller, tol=0.02, unbalanced=0.02)
    assert st.converged
    np.testing.assert_allclose(measure.axis_stresses(sample.scene, sample.walls), targets,
                               rtol=0.02)
    ok, steps, u = prep.solve_to_equilibrium(sample.scene, unbalanced=0.02)
    assert ok and u < 0.02
    with pytest.raises(dem.ParameterError, match=r"stresses\[2\]=-1.0"):
        prep.drive_to_stresses(sample.scene, sample.walls, (1e3, 1e3, -1.0))
