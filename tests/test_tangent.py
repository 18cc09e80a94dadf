"""The network tangent (cpp_dem.measure.network_tangent): a simple cubic lattice against its analytic moduli,
objectivity under a rigid spin, the symmetries of an elastic network, and the DEM element's
network tangent against finite differences of its cloned states in the elastic range."""

from __future__ import annotations

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.measure import network_tangent as tangent
from cpp_dem.elements.periodic import DemElement


def _cubic(nc=3, d=2e-3, kn=1e6, ks=3e5, fn=1.0):
    """Simple cubic lattice of nc^3 grains, spacing d, periodic; contacts to the +x, +y, +z
    neighbours (through the faces for the last layer)."""
    idx = np.arange(nc**3).reshape(nc, nc, nc)
    i, j, l = [], [], []
    for a in range(nc):
        for b in range(nc):
            for c in range(nc):
                for ax, off in enumerate(np.eye(3, dtype=int)):
                    p = (np.array([a, b, c]) + off) % nc
                    i.append(idx[a, b, c])
                    j.append(idx[tuple(p)])
                    l.append(d * off.astype(float))
    l = np.array(l)
    C = len(i)
    return dict(i=np.array(i), j=np.array(j), branch=l, normal=l / d,
                li=np.full(C, d / 2), lj=np.full(C, d / 2), kn=np.full(C, kn),
                ks=np.full(C, ks), fn=np.full(C, fn), fs=np.zeros((C, 3)),
                tan_phi=np.full(C, 0.5), volume=(nc * d) ** 3, n_bodies=nc**3)


def test_simple_cubic_lattice_has_its_analytic_moduli():
    kn, ks, d = 1e6, 3e5, 2e-3
    D, info = tangent.network_tangent(**_cubic(d=d, kn=kn, ks=ks), geometric=False)
    C = tangent.to_voigt(D)
    expect = np.diag([kn / d] * 3 + [ks / (2 * d)] * 3)
    assert np.allclose(C, expect, rtol=1e-10, atol=1e-10 * kn / d)
    # no relaxation in a lattice where every grain sees the same: D equals its affine part
    # on symmetric strains (a rotation turns the grains, which the affine part holds still)
    assert np.allclose(C, info["affine_voigt"], rtol=0, atol=1e-10 * kn / d)
    assert info["residual"] < 1e-10
    # with the geometric terms the difference is of order fn / (kn d)
    Dg, _ = tangent.network_tangent(**_cubic(d=d, kn=kn, ks=ks), geometric=True)
    rel = np.abs(tangent.to_voigt(Dg) - C).max() / (kn / d)
    assert 0 < rel < 10 * 1.0 / (kn * d)


def _random_network(seed=3, n=60):
    rng = np.random.default_rng(seed)
    edge = 1e-2
    x = rng.random((n, 3)) * edge
    i, j, l = [], [], []
    for a in range(n):
        for b in range(a + 1, n):
            dv = x[b] - x[a]
            dv -= edge * np.round(dv / edge)  # minimum image
            if np.linalg.norm(dv) < 0.32 * edge:
                i.append(a), j.append(b), l.append(dv)
    l = np.array(l)
    C = len(i)
    nrm = l / np.linalg.norm(l, axis=1)[:, None]
    r = 0.5 * np.linalg.norm(l, axis=1)
    fs = rng.normal(size=(C, 3))
    fs -= np.einsum("ca,ca->c", fs, nrm)[:, None] * nrm
    return dict(i=np.array(i), j=np.array(j), branch=l, normal=nrm, li=r, lj=r,
                kn=rng.uniform(1e5, 3e5, C), ks=rng.uniform(3e4, 1e5, C),
                fn=rng.uniform(0.5, 2.0, C), fs=0.2 * fs, tan_phi=np.full(C, 10.0),
                volume=edge**3, n_bodies=n)


def test_elastic_network_is_symmetric_positive_and_softer_than_affine():
    net = _random_network()
    D, info = tangent.network_tangent(**net, geometric=False, sliding="elastic")
    C = tangent.to_voigt(D)
    assert np.abs(C - C.T).max() < 1e-8 * np.abs(C).max()  # a potential: major symmetry
    assert np.linalg.eigvalsh(0.5 * (C + C.T)).min() > -1e-8 * np.abs(C).max()
    relax = info["affine_voigt"] - C  # the relaxation only softens
    assert np.linalg.eigvalsh(0.5 * (relax + relax.T)).min() > -1e-8 * np.abs(C).max()
    # a rigid spin moves nothing relative: no stress without the geometric terms
    W = np.array([[0, -1.0, 0.5], [1.0, 0, -0.2], [-0.5, 0.2, 0]])
    assert np.abs(np.einsum("ijkl,kl->ij", D, W)).max() < 1e-9 * np.abs(C).max()


@pytest.fixture(scope="module")
def elastic_element():
    """A periodic element at rest at 100 kPa with the grains' friction raised so that no
    contact slides (bytes)."""
    from cpp_dem.protocols import prep

    el = DemElement.periodic(300, stress=100e3, seed=2)
    s = el.scene
    prep.set_friction(s, np.arange(s.num_bodies), s.material(0), 89.0)
    el._relax(1e-6, 100_000)
    return el.to_bytes()


def test_rigid_spin_rotates_the_stress_objectively(elastic_element):
    # On a packing in equilibrium (unbalanced force 1e-6), with the geometric terms: a rigid
    # spin W gives d sigma = W sigma - sigma W (the stress turns with the material).
    el = DemElement.from_bytes(elastic_element)
    data = el.network_data()
    D, _ = tangent.network_tangent(**data, geometric=True)
    sig = tangent.stress_from_contacts(branch=data["branch"], normal=data["normal"],
                                       fn=data["fn"], fs=data["fs"], volume=data["volume"])
    W = np.array([[0, -1.0, 0.5], [1.0, 0, -0.2], [-0.5, 0.2, 0]])
    ds = np.einsum("ijkl,kl->ij", D, W)
    assert np.allclose(ds, W @ sig - sig @ W, rtol=0, atol=1e-4 * np.abs(sig).max())


def _string(tension=10.0, k=1e6, cell=(0.02, 0.01, 0.01)):
    """A straight bonded string along x through a periodic cell: grains 0 and 1 half a cell
    apart, bonded to each other and to the next cell's image, in tension (N)."""
    lx = cell[0]
    l = np.array([[lx / 2, 0.0, 0.0]] * 2)
    return dict(i=np.array([0, 1]), j=np.array([1, 0]), branch=l, normal=l / (lx / 2),
                li=np.full(2, lx / 4), lj=np.full(2, lx / 4), kn=np.full(2, k),
                ks=np.full(2, k / 2), fn=np.full(2, -tension), fs=np.zeros((2, 3)),
                tan_phi=np.full(2, 0.5), volume=float(np.prod(cell)), n_bodies=2,
                bonded=np.ones(2, bool), k_bend=np.full(2, 1e-3), k_twist=np.full(2, 1e-3))


def test_a_bonded_string_in_tension_keeps_its_springs_and_turns_objectively():
    # Two springs k in series along the cell: d sigma_xx / d E_xx = k lx / (2 A). With the
    # geometric terms the tension's own part cancels (T lx / V from the stretched branch, less
    # the volume's), so that holds in tension too. A rigid spin turns its stress.
    k, T, cell = 1e6, 10.0, (0.02, 0.01, 0.01)
    net = _string(T, k, cell)
    for geometric in (False, True):
        D, info = tangent.network_tangent(**net, geometric=geometric)
        assert info["n_contacts_used"] == 2 and info["n_sliding"] == 0
        assert D[0, 0, 0, 0] == pytest.approx(k * cell[0] / (2 * cell[1] * cell[2]),
                                              rel=1e-9)
    sig = tangent.stress_from_contacts(branch=net["branch"], fn=net["fn"], fs=net["fs"],
                                       volume=net["volume"])
    assert sig[0, 0] == pytest.approx(T * cell[0] / net["volume"])  # (tension positive)
    W = np.array([[0, -1.0, 0.5], [1.0, 0, -0.2], [-0.5, 0.2, 0]])
    ds = np.einsum("ijkl,kl->ij", D, W)
    assert np.allclose(ds, W @ sig - sig @ W, rtol=0, atol=1e-9 * sig[0, 0])
    # weights count the rows in the stress: all rows twice is twice the tangent
    D2, _ = tangent.network_tangent(**net, weights=np.full(2, 2.0))
    assert np.allclose(D2, 2 * D, rtol=1e-12, atol=0)
    # the same rows as contacts are dropped in tension: nothing is left
    D0, info0 = tangent.network_tangent(**{**net, "bonded": None})
    assert info0["n_contacts_used"] == 0 and not D0.any()


def test_bad_input_names_the_field():
    net = _cubic()
    with pytest.raises(dem.ParameterError, match="volume"):
        tangent.network_tangent(**{**net, "volume": -1.0})
    with pytest.raises(dem.ParameterError, match="kn"):
        tangent.network_tangent(**{**net, "kn": net["kn"][:-1]})
    with pytest.raises(dem.ParameterError, match="sliding"):
        tangent.network_tangent(**net, sliding="maybe")
    with pytest.raises(dem.ParameterError, match="body indices"):
        tangent.network_tangent(**{**net, "n_bodies": 3})
    with pytest.raises(dem.ParameterError, match="bonded"):
        tangent.network_tangent(**net, bonded=np.ones(2, bool))
    with pytest.raises(dem.ParameterError, match="weights"):
        tangent.network_tangent(**net, weights=np.ones(2))


def test_element_network_tangent_matches_finite_differences_in_the_elastic_range(
        elastic_element):
    # No contact slides: the network tangent equals the finite-difference tangent of cloned,
    # relaxed states (h = 1e-6) within 1 % (measured 0.1 % at 400 grains), and the affine
    # estimate is far stiffer (the grains' relaxation matters).
    el = DemElement.from_bytes(elastic_element)
    d_net, info = el.network_tangent()
    assert info["n_sliding"] == 0
    d_fd = el.fd_tangent(h=1e-6, unbalanced=1e-6, max_relax_steps=100_000)
    rel = np.linalg.norm(d_net - d_fd) / np.linalg.norm(d_fd)
    assert rel < 0.01, (rel, d_net / 1e6, d_fd / 1e6)
    assert np.trace(info["affine_voigt"]) > 1.3 * np.trace(d_net)


def test_the_tangent_does_not_depend_on_the_blas_threads():
    # OpenBLAS splits some kernels of SciPy's sparse LU by thread count: in this sheared
    # state (a dense element at a K0 stress) the unguarded assembly gave another rounding on
    # 2 BLAS threads than on 1, and a Dask worker (one thread) another tangent than the
    # client. network_tangent runs BLAS on one thread, and gives the threads back.
    from threadpoolctl import threadpool_info, threadpool_limits

    from femcoupling.coupling.handover import fem_to_dem
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    k0 = fem_to_dem(np.diag([-2314.285714285711, -2314.285714285711, -5399.999999999994]))
    el, _ = PeriodicRegionElement(n=100, seed=5, tol=0.02, unbalanced=1e-2).prepare("a", k0)
    de = np.array([[1e-4, 0, 2e-5], [0, 0, 0], [2e-5, 0, -3e-4]])
    for k in (3, 6, 9):
        el.apply_strain(k * de)
    data = el.network_data()
    out = []
    for threads in (1, 2):
        with threadpool_limits(limits=threads, user_api="blas"):
            before = threadpool_info()
            out.append(tangent.network_tangent(**data)[0])
            assert threadpool_info() == before  # (the caller's threads given back)
    assert np.array_equal(out[0], out[1])
