"""Verification of the continuum side (femcoupling.fem.model.FemModel on the soil body) against analytic solutions.

- Flamant/Boussinesq strip load on an elastic half-space (plane strain): on the centreline
  sigma_z(z) = -(p / pi) (alpha + sin alpha), alpha = 2 atan(b / z). Tolerance 2 % at
  z/b = 0.5, 1, 2, 3 (measured: <= 0.2 %, docs/fem.md).
- Prandtl: smooth strip footing on weightless Drucker-Prager soil matched to Mohr-Coulomb in
  plane strain, phi = 30 deg: q_u = c N_c, N_c = 30.14. Tolerance 5 % (measured +1.1 % on
  this mesh).
- The Drucker-Prager return mapping: stresses on the yield surface, consistent tangent equal
  to the finite-difference derivative.
- MPI (`mpiexec -n 2`) is checked by hand, see docs/fem.md (a subprocess test hung inside
  pytest on this machine and was left out).
"""

from __future__ import annotations

import math
import pathlib

import numpy as np
import pytest

from femcoupling import FemInputError
from femcoupling.fem.geometry import ElementRegion, ReinforcedSoilBody
from femcoupling.fem.model import FemModel
from femcoupling.materials.continuum import (DruckerPrager, LinearElastic, drucker_prager_return,
                                             mandel_identity)

ROOT = pathlib.Path(__file__).resolve().parents[1]
B_M = 1.0
P_PA = 100e3


def flamant_sigma_z(z_m: float) -> float:
    a = 2.0 * math.atan(B_M / z_m)
    return -(P_PA / math.pi) * (a + math.sin(a))


def strip_model(fine: float = 0.1, coarse: float = 3.0, size: float = 20.0) -> FemModel:
    body = ReinforcedSoilBody(width_m=size * B_M, height_m=size * B_M, footing_half_width_m=B_M,
                              regions=(ElementRegion("under", (0.5, size * B_M - 1.0), 0.5),),
                              mesh_size_m=coarse, fine_size_m=fine, fine_radius_m=3 * B_M)
    m = FemModel(body, soil=LinearElastic(10e6, 0.3))
    m.set_geostatic()
    m.load_footing(pressure_pa=P_PA, steps=1)
    return m


@pytest.fixture(scope="module")
def strip():
    return strip_model()


@pytest.mark.parametrize("z_over_b", [0.5, 1.0, 2.0, 3.0])
def test_flamant_strip_load_centreline_within_2_percent(strip, z_over_b):
    z = z_over_b * B_M
    s = strip.point_stress([[0.0, 20 * B_M - z]])[0]
    assert s[2, 2] == pytest.approx(flamant_sigma_z(z), rel=0.02)


def test_strip_load_stress_symmetric_and_region_average_consistent(strip):
    s = strip.region_stress("under")
    assert np.allclose(s, s.T)
    assert s[1, 1] == pytest.approx(0.3 * (s[0, 0] + s[2, 2]), rel=1e-6)  # plane strain
    assert s[2, 2] < 0 and abs(s[2, 2]) < P_PA


def test_prandtl_limit_load_within_5_percent():
    c = 10e3
    phi = math.radians(30.0)
    nq = math.exp(math.pi * math.tan(phi)) * math.tan(math.pi / 4 + phi / 2) ** 2
    nc = (nq - 1.0) / math.tan(phi)
    assert nc == pytest.approx(30.14, abs=0.01)
    body = ReinforcedSoilBody(width_m=12.0, height_m=6.0, footing_half_width_m=1.0,
                              mesh_size_m=1.0, fine_size_m=0.05, fine_radius_m=0.5)
    m = FemModel(body, soil=DruckerPrager(young_pa=1e8, poisson=0.3, cohesion_pa=c,
                                           friction_deg=30.0))
    m.set_geostatic()
    steps = m.load_footing(settlement_m=0.025, steps=15)
    q = np.array([r.footing_pressure_pa for r in steps])
    s = np.array([r.footing_settlement_m for r in steps])
    assert q[-1] / c == pytest.approx(nc, rel=0.05)
    # a plateau: the last 20 % of the settlement adds less than 0.5 % load
    late = s >= 0.8 * s[-1]
    assert (q[-1] - q[late][0]) / q[-1] < 0.005


def test_return_mapping_lands_on_the_yield_surface_and_tangent_is_consistent():
    mat = DruckerPrager(young_pa=50e6, poisson=0.3, cohesion_pa=10e3, friction_deg=30.0)
    a, b, k = mat.dp_parameters()
    K, G = mat.bulk_pa, mat.shear_pa
    rng = np.random.default_rng(3)
    for ncomp in (4, 6):
        trial = rng.normal(scale=100e3, size=(50, ncomp)) - 50e3 * mandel_identity(ncomp)
        sig, tan, dl = drucker_prager_return(trial, bulk_pa=K, shear_pa=G, alpha=a, beta=b,
                                             k_pa=k)
        p = sig[:, :3].sum(1) / 3
        sdev = sig - p[:, None] * mandel_identity(ncomp)
        f = 3 * a * p + np.linalg.norm(sdev, axis=1) / math.sqrt(2) - k
        assert np.all(f <= 1e-6 * k)
        assert np.all(np.abs(f[dl > 0]) <= 1e-6 * k)
        assert np.count_nonzero(dl > 0) > 10
        # finite-difference check of the consistent tangent at cone points
        from femcoupling.materials.continuum import elastic_tangent
        C = elastic_tangent(K, G, ncomp)[0]
        for i in np.flatnonzero(dl > 0)[:5]:
            num = np.zeros((ncomp, ncomp))
            h = 1e-7
            for j in range(ncomp):
                de = np.zeros(ncomp)
                de[j] = h
                sp = drucker_prager_return((trial[i] + C @ de)[None], bulk_pa=K, shear_pa=G,
                                           alpha=a, beta=b, k_pa=k)[0][0]
                sm = drucker_prager_return((trial[i] - C @ de)[None], bulk_pa=K, shear_pa=G,
                                           alpha=a, beta=b, k_pa=k)[0][0]
                num[:, j] = (sp - sm) / (2 * h)
            np.testing.assert_allclose(tan[i], num, rtol=1e-4, atol=1e-4 * np.abs(C).max())


@pytest.mark.parametrize("kwargs,msg", [
    (dict(footing_half_width_m=30.0), "footing_half_width_m=30.0: must be <= width_m=20.0 "
     "(= width_m: a uniform surcharge on the whole top)"),
    (dict(height_m=-1.0), "height_m=-1.0: must be > 0"),
    (dict(dim=4), "dim=4: must be 2 or 3"),
    (dict(regions=(ElementRegion("e", (0.02, 5.0), 0.1),)),
     "regions[0].center_m[0]=0.02: the region (size 0.1) must lie inside [0, 20.0]"),
])
def test_bad_geometry_is_named(kwargs, msg):
    base = dict(width_m=20.0, height_m=20.0, footing_half_width_m=1.0)
    with pytest.raises(FemInputError) as e:
        ReinforcedSoilBody(**{**base, **kwargs})
    assert str(e.value) == msg


def test_bad_material_is_named():
    with pytest.raises(FemInputError, match=r"^friction_deg=70.0: must be in \[0, 60\]$"):
        DruckerPrager(young_pa=1e7, poisson=0.3, cohesion_pa=1.0, friction_deg=70.0)
    with pytest.raises(FemInputError, match=r"^poisson=0.5: must be in \(-1, 0.5\)$"):
        LinearElastic(1e7, 0.5)


def test_point_stress_on_p1_is_the_cells_stress():
    """P1 cells have one quadrature point: point_stress projects on DG0 and gives that
    point's stress (it projected on DG1, whose mass matrix one point cannot integrate, and
    returned NaN and inf)."""
    body = ReinforcedSoilBody(width_m=4.0, height_m=3.0, footing_half_width_m=0.5,
                              mesh_size_m=0.6, fine_size_m=0.1)
    m = FemModel(body, soil=LinearElastic(50e6, 0.3), unit_weight_n_m3=18e3, degree=1)
    m.set_geostatic()
    m.load_footing(pressure_pa=100e3, steps=1)
    import dolfinx.geometry as dg

    pts = np.array([[0.25, 2.7], [1.3, 1.1]])
    got = m.point_stress(pts)
    assert np.all(np.isfinite(got))
    p3 = np.c_[pts, np.zeros(2)]
    tree = dg.bb_tree(m.mesh, 2)
    coll = dg.compute_colliding_cells(m.mesh, dg.compute_collisions_points(tree, p3), p3)
    cms = m.cell_mean_stress()
    from femcoupling.materials.continuum import mandel_to_tensor

    for i in range(2):
        want = mandel_to_tensor(cms[coll.links(i)[0]])
        np.testing.assert_allclose(got[i], want, rtol=0, atol=1e-9 * np.abs(want).max())
    assert got[0, 2, 2] < -50e3  # under the footing
