"""Hierarchical FEM x DEM in plane strain (femcoupling.fem.model.FemModel on a Rectangle): a DEM
element at every quadrature point, on Dask workers. In a homogeneous field Newton converges in
one iteration and every element answers as the stand-alone element given the same increment (bitwise);
1 and 2 workers give bitwise the same run."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from cpp_dem.elements.pool import ElementPool, PeriodicFactory  # noqa: E402
from femcoupling.fem.bodies import Rectangle  # noqa: E402
from femcoupling.fem.model import FemModel, split_options  # noqa: E402
from femcoupling.materials.element_pool import dem_increment, fem_stress  # noqa: E402

FACTORY = PeriodicFactory(n=100, same=True)


def _rect(pool, **kw):
    """A FemModel on a Rectangle of ``kw``'s body arguments, the rest the model's."""
    body, options = split_options(Rectangle, kw)
    return FemModel(Rectangle(**body), elements=pool, **options)


def _run(workers, out=None):
    with ElementPool.build(8, FACTORY, workers=workers) as pool:
        m = _rect(pool, lx=0.02, ly=0.02, nx=2, ny=2, homogeneous=True,
                                    out=out)
        steps = [m.step(top_displacement=-2e-6 * k, right_displacement=1e-6 * k)
                 for k in (1, 2)]
        return steps, m.u.x.array.copy()


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    return tmp_path_factory.mktemp("hier")


@pytest.fixture(scope="module")
def runs(records):
    return {1: _run(1), 2: _run(2, out=records)}


def test_records_one_row_per_element_per_step(runs, records):
    import h5py

    steps, _ = runs[2]
    with h5py.File(records / "elements.h5") as f:
        assert f["stress_pa"].shape == (16, 3, 3) and f["tangent_pa"].shape == (16, 6, 6)
        assert list(f["step"][:]) == [0] * 8 + [1] * 8
        assert list(f["element"][:]) == list(range(8)) * 2
        for k, r in enumerate(steps):
            rows = slice(8 * k, 8 * k + 1 * 8)
            assert np.array_equal(np.array([fem_stress(s) for s in f["stress_pa"][rows]]),
                                  r.element_stresses)
            assert np.array_equal(f["increment"][rows], r.increments)
        assert np.all(f["contacts"][:] > 0) and np.all(f["cpu_s"][:] > 0)
        assert np.all(np.isfinite(f["tangent_pa"][:]))
    lines = (records / "steps.csv").read_text().splitlines()
    assert lines[0].startswith("step,load_m,iterations") and len(lines) == 3
    xdmf = (records / "fem.xdmf").read_text()
    assert xdmf.count('Attribute Name="stress_pa"') == 2
    assert xdmf.count('Attribute Name="displacement_m"') == 2


def test_homogeneous_field_converges_in_one_iteration(runs):
    steps, _ = runs[2]
    for r in steps:
        assert r.newton_iterations == 1
        assert r.residual < 1e-3
        # every element sees the homogeneous increment: to rounding in the first step
        # (4e-19 of 1e-4); in the second to 3e-4 of it, as the first step's element stresses
        # differed by 5e-5 (below) and moved the interior node accordingly
        assert np.allclose(r.increments, r.increments[0], rtol=0, atol=1e-3 * 1e-4)
        e = r.increments[0]
        assert e[0, 0] == pytest.approx(1e-6 / 0.02, rel=1e-9)
        assert e[2, 2] == pytest.approx(-2e-6 / 0.02, rel=1e-9)
        # ... and answers alike (the DEM's relaxation to a tolerance turns 1e-16 differences
        # of the input into about 5e-5 of the stress)
        s = r.element_stresses
        assert np.abs(s - s.mean(axis=0)).max() < 1e-3 * np.abs(s).max()


def test_each_element_is_the_stand_alone_element(runs):
    steps, _ = runs[2]
    for k in range(8):
        el = FACTORY(k)
        for r in steps:
            s = el.apply_strain(r.increments[k])
        assert np.array_equal(fem_stress(s), steps[-1].element_stresses[k])


def test_one_and_two_workers_give_the_same_run(runs):
    (s1, u1), (s2, u2) = runs[1], runs[2]
    assert np.array_equal(u1, u2)
    for a, b in zip(s1, s2):
        assert np.array_equal(a.element_stresses, b.element_stresses)


def test_dem_increment_maps_the_plane_to_x_z():
    g = np.array([[1.0, 2.0], [3.0, 4.0]])
    de = dem_increment(g)
    assert de[0, 0] == 1 and de[0, 2] == 2 and de[2, 0] == 3 and de[2, 2] == 4
    assert np.count_nonzero(de) == 4  # the out-of-plane y is held


def test_a_broken_element_tangent_keeps_the_last_good_one():
    with ElementPool.build(2, PeriodicFactory(n=80, same=True), workers=1) as pool:
        m = _rect(pool, lx=0.01, ly=0.01, nx=1, ny=1)
        good = m._tan.copy()
        stresses = [np.diag([-1e5, -1e5, -1e5])] * 2
        bad = np.zeros((6, 6))
        bad[0, 0] = -1e9  # far from positive
        nan = np.full((6, 6), np.nan)
        _, tan = m.material._fem_answers(stresses, [bad, nan])
        assert m.bad_tangents == 2
        assert np.array_equal(tan, good)


def test_aitken_factor():
    from femcoupling.coupling.relaxation import aitken_factor

    d = np.array([1.0, -2.0, 0.5])
    assert aitken_factor(1.0, d, -d) == pytest.approx(0.5)  # a 2-cycle halves it
    assert aitken_factor(0.4, d, 0.5 * d) == pytest.approx(0.8)  # steady: / (1 - a)
    assert aitken_factor(0.8, d, 0.5 * d) == 1.0  # ... up to 1
    assert aitken_factor(0.3, d, d) == 0.3  # equal corrections: unchanged
    assert aitken_factor(1.0, d, -100 * d) == 0.1  # kept >= 0.1


def test_bad_convergence_options_are_refused():
    from femcoupling import FemInputError

    with ElementPool.build(2, PeriodicFactory(n=60, same=True), workers=1) as pool:
        for kw, field in (({"convergence": "loose"}, "convergence"),
                          ({"relaxation": 1.5}, "relaxation"),
                          ({"relaxation": "fast"}, "relaxation"),
                          ({"noise_factor": 0.0}, "noise_factor"),
                          ({"noise_ceiling": 1e-4, "newton_rtol": 1e-3}, "noise_ceiling"),
                          ({"newton_rtol": 0.0}, "newton_rtol")):
            with pytest.raises(FemInputError, match=field):
                _rect(pool, lx=0.01, ly=0.01, nx=1, ny=1, **kw)


def test_a_tolerance_below_the_noise_is_cut_above_the_ceiling_and_said_below_it(tmp_path):
    """Asked for 1e-9, which the elements' noise does not allow: Newton stalls and measures the
    noise (the elements re-run on their increments scaled by 1 + 1e-9).

    - With the default ceiling (10 x newton_rtol = 1e-8) the residual, within the noise but
      above the ceiling, is not accepted: the step is cut (issue 37; before, any residual
      within 2 x the noise was accepted), and the half step, no better, fails.
    - With a ceiling above the noise the step is accepted there, as stopped_at_scatter (not
      converged), and said (NoiseWarning, ``warnings``, report.md), its residual in Pa too.
    - With convergence='tolerance' the same step fails and its error names the residual.
    """
    from femcoupling.fem.steps import NewtonFailure
    from femcoupling.coupling.status import NoiseWarning

    fac = PeriodicFactory(n=80, isotropic=True, options={"prep_friction_deg": 0.0})
    kw = dict(lx=0.01, ly=0.01, nx=1, ny=1, confining_pa=100e3, newton_rtol=1e-9,
              tangent="network-elastic")
    with ElementPool.build(2, fac, workers=1) as pool:
        m = _rect(pool, max_newton=12, **kw)
        assert m.noise_ceiling == pytest.approx(1e-8)
        tried = []
        step = m._step
        m._step = lambda point, lf: (tried.append(float(point[0])), step(point, lf))[1]
        with pytest.raises(NewtonFailure, match=r"within the elements' noise .* above the "
                                                r"ceiling noise_ceiling=1e-08.*the step is cut"):
            m.step(top_displacement=-2e-5, max_cuts=1)
        assert tried == [-2e-5, -1e-5]  # cut once, then failed
        assert m.history == [] and m.status == "converged"  # (nothing accepted)
        assert float(m.top_u.value) == 0.0  # the boundary back at the last accepted step
        pool.reject()

        m = _rect(pool, max_newton=12, noise_ceiling=1e-4, out=tmp_path, **kw)
        with pytest.warns(NoiseWarning, match="below the elements' noise"):
            r = m.step(top_displacement=-2e-5)
        assert r.converged_on == "noise" and r.status == "stopped_at_scatter"
        assert m.status == "stopped_at_scatter"
        assert 0 < r.noise_residual and r.residual <= 2.0 * r.noise_residual
        assert 1e-9 < r.residual <= 1e-4
        # in stress units: the relative residual times the largest element stress (of the
        # iterate before the noise probe, which moved it by 7e-6)
        assert r.residual_pa == pytest.approx(r.residual * np.abs(r.element_stresses).max(),
                                              rel=1e-4)
        assert len(m.warnings) == 1 and "stopped_at_scatter, not converged" in m.warnings[0]
        report = (tmp_path / "report.md").read_text()
        assert "Warnings (1)" in report and "below the elements' noise" in report
        assert "| stopped_at_scatter | noise |" in report
        assert "status: **stopped_at_scatter**" in report
        csv = (tmp_path / "steps.csv").read_text().splitlines()
        assert csv[0].endswith(",status,residual_pa,noise_residual_pa")
        assert ",stopped_at_scatter," in csv[1]
        # equilibrium to the noise: the mean lateral stress is the confining pressure
        assert r.mean_stress[0] == pytest.approx(-100e3, rel=2e-3)

        m = _rect(pool, max_newton=6, convergence="tolerance", **kw)
        with pytest.raises(NewtonFailure, match="no convergence in 6 iterations"):
            m.step(top_displacement=-4e-5, max_cuts=0)


def test_records_of_an_earlier_run_are_not_mixed_in(runs, records):
    """A second run into the same folder would append to the first's rows: refused, unless
    asked to replace them."""
    from femcoupling import FemInputError

    with ElementPool.build(2, PeriodicFactory(n=60, same=True), workers=1) as pool:
        with pytest.raises(FemInputError, match="records of an earlier run"):
            _rect(pool, lx=0.01, ly=0.01, nx=1, ny=1, out=records)


def test_secant_update_maps_the_increment_and_stays_positive():
    from femcoupling.materials.element_pool import secant_update

    rng = np.random.default_rng(4)
    for _ in range(20):
        a = rng.normal(size=(3, 3))
        t = a @ a.T + 0.1 * np.eye(3)
        de = rng.normal(size=3)
        ds = t @ de * rng.uniform(0.2, 1.0) + 0.05 * rng.normal(size=3) * np.abs(t @ de).max()
        if ds @ de <= 0:
            assert secant_update(t, de, ds) is None
            continue
        c = secant_update(t, de, ds)
        assert np.allclose(c @ de, ds, rtol=1e-10, atol=1e-12 * np.abs(ds).max())
        assert np.allclose(c, c.T) and np.linalg.eigvalsh(c)[0] > 0
    t = np.diag([3.0, 2.0, 1.0])
    assert secant_update(t, np.zeros(3), np.ones(3)) is None  # no increment
    assert secant_update(t, np.array([1e-3, 0, 0]), np.array([-1.0, 0, 0])) is None  # gave back


def test_the_secant_tangent_reaches_the_network_tangents_solution():
    """A confined element pair sheared in two load steps: Newton with the secant tangent
    converges to the state the network tangent's Newton reaches (within the tolerance), and
    the secant was used; an unknown tangent is refused with the list."""
    from femcoupling import FemInputError

    res = {}
    for tangent in ("network", "secant"):
        with ElementPool.build(2, PeriodicFactory(n=100, stress=100e3, isotropic=True,
                                                  options={"prep_friction_deg": 0.0}),
                               workers=1) as pool:
            m = _rect(pool, lx=0.02, ly=0.02, nx=1, ny=1,
                                        confining_pa=100e3, newton_rtol=1e-3,
                                        tangent=tangent, convergence="tolerance")
            steps = [m.step(top_displacement=-2e-5 * k) for k in (1, 2)]
            res[tangent] = (steps[-1].mean_stress, m.secants_used)
            with pytest.raises(FemInputError, match="'secant'"):
                _rect(pool, lx=0.02, ly=0.02, nx=1, ny=1, tangent="x")
    (s_net, used_net), (s_sec, used_sec) = res["network"], res["secant"]
    assert used_net == 0 and used_sec > 0
    assert np.abs(s_sec - s_net).max() < 5e-3 * np.abs(s_net).max()


def test_quadratic_triangles_three_elements_each_give_the_homogeneous_response():
    """degree=2: P2 triangles with three quadrature points, an element at each (issue 38: no
    volumetric locking). In a homogeneous field every point's element sees the field's
    increment and answers as the stand-alone element; 1 and 2 workers give the same run."""
    def run(workers):
        with ElementPool.build(6, FACTORY, workers=workers) as pool:
            m = _rect(pool, lx=0.01, ly=0.01, nx=1, ny=1, homogeneous=True,
                                        degree=2)
            assert (m.n_cells, m.nq, m.n_points) == (2, 3, 6)
            from femcoupling.fem.bodies import quadrature_points

            assert np.allclose(m.point_coordinates, quadrature_points(0.01, 0.01, 1, 1, 2),
                               rtol=0, atol=1e-15)
            return [m.step(top_displacement=-1e-6 * k, right_displacement=0.5e-6 * k)
                    for k in (1, 2)], m.u.x.array.copy()

    (s1, u1), (s2, u2) = run(1), run(2)
    assert np.array_equal(u1, u2)
    for a, b in zip(s1, s2):
        assert np.array_equal(a.element_stresses, b.element_stresses)
    for r in s2:
        assert r.newton_iterations == 1
        assert np.allclose(r.increments, r.increments[0], rtol=0, atol=1e-3 * 1e-4)
        # (to 4e-4: the diagonal's mid-node is free, and the elements' relaxation to a
        # tolerance moves it, as the interior node of the P1 test above)
        assert r.increments[0][2, 2] == pytest.approx(-1e-6 / 0.01, rel=1e-3)
    for k in range(6):
        el = FACTORY(k)
        for r in s2:
            s = el.apply_strain(r.increments[k])
        assert np.array_equal(fem_stress(s), s2[-1].element_stresses[k])
    from femcoupling import FemInputError

    with ElementPool.build(2, FACTORY, workers=1) as pool:
        with pytest.raises(FemInputError, match="pool: has 2 elements for 6 quadrature"):
            _rect(pool, lx=0.01, ly=0.01, nx=1, ny=1, homogeneous=True,
                                    degree=2)
        with pytest.raises(FemInputError, match="degree=3"):
            _rect(pool, lx=0.01, ly=0.01, nx=1, ny=1, degree=3)


def test_rough_platens_grip_the_ends_and_quadrature_points_are_in_element_order():
    """platens="rough" (issue 38, shear bands): the ends do not slide (u_x = 0 on the top and
    the bottom), the sides carry the confining pressure on both sides and bulge outwards at
    mid-height. ``quadrature_points`` gives the model's points in its elements' order before
    the model is built."""
    from femcoupling import FemInputError
    from femcoupling.fem.bodies import quadrature_points

    fac = PeriodicFactory(n=80, stress=100e3, isotropic=True, same=True,
                          options={"prep_friction_deg": 0.0})
    with ElementPool.build(4, fac, workers=1) as pool:
        m = _rect(pool, lx=0.01, ly=0.02, nx=1, ny=2, confining_pa=100e3,
                                    platens="rough", newton_rtol=5e-3)
        assert np.allclose(m.point_coordinates, quadrature_points(0.01, 0.02, 1, 2, degree=1),
                           rtol=0, atol=1e-15)
        r = m.step(top_displacement=-2e-5)
        assert r.status in ("converged", "stopped_at_scatter")
        x = m.V.tabulate_dof_coordinates()
        ux = m.u.x.array.reshape(-1, 2)[:, 0]
        ends = np.isclose(x[:, 1], 0.0) | np.isclose(x[:, 1], 0.02)
        assert np.all(ux[ends] == 0.0)
        mid = np.isclose(x[:, 1], 0.01)
        left, right = mid & np.isclose(x[:, 0], 0.0), mid & np.isclose(x[:, 0], 0.01)
        assert ux[left].item() < 0 < ux[right].item()  # both sides bulge out
        with pytest.raises(FemInputError, match="platens='sticky'"):
            _rect(pool, lx=0.01, ly=0.02, nx=1, ny=2, confining_pa=1e5,
                                    platens="sticky")
        with pytest.raises(FemInputError, match="platens='rough': needs confining_pa"):
            _rect(pool, lx=0.01, ly=0.02, nx=1, ny=2, platens="rough")
    p2 = quadrature_points(0.02, 0.04, 2, 3, degree=2)
    assert p2.shape == (2 * 2 * 3 * 3, 2)
    assert np.all((p2 > 0) & (p2 < [0.02, 0.04]))


def test_one_model_on_every_body_refuses_what_is_not_one():
    """FemModel takes a body of femcoupling.fem.bodies and a pool; anything else is refused by
    name, and the bodies' own arguments split from the model's."""
    from femcoupling import FemInputError
    from femcoupling.fem.bodies import Box, Cylinder
    from femcoupling.fem.geometry import ReinforcedSoilBody

    with pytest.raises(FemInputError, match="body=<object .*: a femcoupling.fem.geometry.Reinf"):
        FemModel(object(), elements=None)
    soil = ReinforcedSoilBody(width_m=2.0, height_m=1.0, footing_half_width_m=0.5)
    with pytest.raises(FemInputError, match="elements: not an argument of FemModel on the "
                                            "reinforced soil body .it is a body of femcoupling"):
        FemModel(soil, elements=None)
    with pytest.raises(FemInputError, match="soil: not an argument of FemModel on a Rectangle "
                                            ".it is the reinforced soil body's.; its own: "):
        FemModel(Rectangle(lx=1.0, ly=1.0, nx=1, ny=1), elements=None, soil=None)
    with pytest.raises(FemInputError, match="elements: missing"):
        FemModel(Rectangle(lx=1.0, ly=1.0, nx=1, ny=1))
    with pytest.raises(FemInputError, match=r"elements=None: an ElementPool with one element "
                                            r"per quadrature point \(8 quadrature points"):
        FemModel(Rectangle(lx=0.02, ly=0.02, nx=2, ny=2, homogeneous=True), elements=None)
    body, model = split_options(Rectangle, dict(lx=1.0, degree=2, platens="rough",
                                                newton_rtol=1e-4, out="x"))
    assert body == dict(lx=1.0, degree=2, platens="rough")
    assert model == dict(newton_rtol=1e-4, out="x")
    assert split_options(Cylinder, dict(section="full", tangent="network"))[0] == \
        dict(section="full")
    with pytest.raises(FemInputError, match="footing_pressure_pa\\(\\): only on a Rectangle"):
        Box(lx=1.0, ly=1.0, lz=1.0, nx=1, ny=1, nz=1, homogeneous=True).footing_pressure_pa(None)
    with pytest.raises(FemInputError, match="tangent='secant': one of 'network'"):
        FemModel(Box(lx=1.0, ly=1.0, lz=1.0, nx=1, ny=1, nz=1, homogeneous=True),
                 elements=None, tangent="secant")


def test_a_method_of_one_kind_of_body_is_refused_on_the_other():
    """The one model's parts keep to their bodies: a soil-body stage or measure on a model of
    a Rectangle, or step() on the soil body's model, is refused by name, not run on the
    wrong state."""
    from femcoupling import FemInputError
    from femcoupling.fem.geometry import ReinforcedSoilBody

    m = FemModel.__new__(FemModel)  # (the guard reads only the kind and the body)
    m._kind, m.body = "elements", Rectangle(lx=1.0, ly=1.0, nx=1, ny=1)
    for call in (lambda: m.set_geostatic(), lambda: m.load_footing(pressure_pa=1e3),
                 lambda: m.region_stress("a"), lambda: m.set_cell_elements("a", None),
                 lambda: m.sig_n, lambda: m.save_state()):
        with pytest.raises(FemInputError, match=r"a model of the reinforced soil body .* "
                                                r"\(this model's body: Rectangle\(lx=1.0"):
            call()
    m._kind, m.body = "soil", ReinforcedSoilBody(width_m=2.0, height_m=1.0,
                                                 footing_half_width_m=0.5)
    for call in (lambda: m.step(top_displacement=-1e-3), lambda: m.volume_mean_stress(),
                 lambda: m.point_coordinates):
        with pytest.raises(FemInputError, match=r"a model of a body of femcoupling.fem.bodies "
                                                r".* \(this model's body: ReinforcedSoilBody"):
            call()
