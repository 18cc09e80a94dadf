"""Bonds between spheres (issue 16): PFC's contact bond and parallel bond.

Verified against analytic beams (a chain of bonded spheres is a discrete beam with
E = k_bar_n L and G = k_bar_s L, L the centre distance), breakage at the strength within one
step's load increment for each mode, the energy balance of a vibrating chain, and the
bookkeeping (pair pass, storage order, threads, checkpoints, errors).
"""

import math

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem import BondParams
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint

R = 1e-3  # sphere radius, m
L = 2 * R  # bond length (centre distance), m
A = math.pi * R**2
I = math.pi * R**4 / 4
J = 2 * I
KBAR = 1e12  # k_bar_n = k_bar_s, Pa/m


def _material():
    return cd.linear_material(density=1000.0, young=1e8, poisson=0.3, friction_angle_deg=30)


def chain(n, params, *, damping=0.7, axis=0, sort=True):
    """n + 1 touching spheres along `axis`, each bonded to the next; sphere 0 fully blocked."""
    s = cd.Scene(local_damping=damping)
    s.spatial_sort = sort
    m = s.add_material(_material())
    c = np.zeros((n + 1, 3))
    c[:, axis] = np.arange(n + 1) * L
    ids = s.add_spheres(c, np.full(n + 1, R), material=m)
    for i in range(n):
        s.add_bond(int(ids[i]), int(ids[i + 1]), params)
    s.block_dofs(int(ids[0]), "all")
    return s, ids


def pb(**kw):
    base = dict(kn=1e5, ks=1e5, friction=0.5, pb_kn=KBAR, pb_ks=KBAR)
    base.update(kw)
    return BondParams(**base)


def settle(s, tip_load, tip_torque=None, rounds=30, steps=20000):
    n = s.num_bodies
    f = np.zeros((n, 3))
    f[-1] = tip_load
    s.external_forces = f
    if tip_torque is not None:
        t = np.zeros((n, 3))
        t[-1] = tip_torque
        s.external_torques = t
    s.dt = 0.5 * s.critical_dt()
    s.run(rounds * steps)


# ---- analytic beams ----------------------------------------------------------------------


def test_axial_bar_is_ea_over_l():
    """Tension carried by the parallel bonds alone (no contact bond): n springs k_bar_n A in
    series, i.e. EA/L_total with E = k_bar_n L."""
    n, p = 10, 5.0
    s, ids = chain(n, pb())
    settle(s, [p, 0, 0], rounds=20)
    u = s.positions[-1, 0] - n * L
    exact = p * n * L / (KBAR * L * A)
    assert u == pytest.approx(exact, rel=1e-6)
    st = s.bond_state()
    np.testing.assert_allclose(st["pb_normal_force"], p, rtol=1e-6)
    assert np.all(st["normal_force"] == 0)  # the linear contact does not act in tension


def test_axial_compression_adds_the_linear_contact():
    n, p = 10, 5.0
    s, ids = chain(n, pb())
    settle(s, [-p, 0, 0], rounds=20)
    u = s.positions[-1, 0] - n * L
    assert u == pytest.approx(-p * n / (KBAR * A + 1e5), rel=1e-6)


def test_cantilever_matches_the_beam():
    """A tip load P on a chain fixed at sphere 0: the discrete chain's statics (rotational
    springs k_bar_n I at the contact points, shear springs k_bar_s A) to 1e-5, and
    Euler–Bernoulli P L^3 / 3 E I within 2 % (here 0.07 %)."""
    n, p = 10, 1e-2
    s, ids = chain(n, pb())
    settle(s, [0, p, 0], rounds=40)
    y = s.positions[-1, 1]
    theta = [p * (n * L - (k + 0.5) * L) / (KBAR * I) for k in range(n)]
    discrete = sum(theta[k] * (n - k - 0.5) * L for k in range(n)) + n * p / (KBAR * A)
    beam = p * (n * L) ** 3 / (3 * KBAR * L * I)
    assert y == pytest.approx(discrete, rel=1e-5)
    assert abs(y / beam - 1) < 0.02
    # The bending moment at the root is P times the arm from the tip to the contact point.
    st = s.bond_state()
    assert abs(st["pb_bending_moment"][0, 2]) == pytest.approx(p * (n - 0.5) * L, rel=1e-4)


def test_torsion_is_gj_over_l():
    n, t = 10, 1e-4
    s, ids = chain(n, pb())
    settle(s, [0, 0, 0], tip_torque=[t, 0, 0], rounds=30)
    # The tip's rotation about x: integrate its spin? Read the twisting moments and the
    # orientation instead.
    q = s.orientations[-1]  # (w, x, y, z)
    phi = 2 * math.atan2(q[1], q[0])
    exact = t * n * L / (KBAR * L * J)
    assert phi == pytest.approx(exact, rel=1e-5)
    np.testing.assert_allclose(s.bond_state()["pb_twisting_moment"], -t, rtol=1e-6)


# ---- breakage ------------------------------------------------------------------------------


def pair(params, *, sort=True):
    """Two touching spheres bonded; both held, so motions can be imposed."""
    s = cd.Scene()
    s.spatial_sort = sort
    m = s.add_material(_material())
    ids = s.add_spheres([[0, 0, 0], [L, 0, 0]], [R, R], material=m)
    s.add_bond(int(ids[0]), int(ids[1]), params)
    s.block_dofs(ids, "all")
    s.dt = 1e-6
    return s, ids


def drive(s, *, vel=(0, 0, 0), spin=(0, 0, 0), max_steps=200000):
    v = np.zeros((2, 3))
    v[1] = vel
    w = np.zeros((2, 3))
    w[1] = spin
    s.velocities = v
    s.angular_velocities = w
    done = 0
    while not s.bond_breaks and done < max_steps:
        s.run(100)
        done += 100
    assert s.bond_breaks, "the bond never broke"
    return s.bond_breaks


@pytest.mark.parametrize(
    "mode, params, motion, per_step",
    [
        # sigma = F_n / A grows by k_bar_n v dt per step.
        ("parallel_tension", dict(pb_tensile=2e6), dict(vel=(0.01, 0, 0)), KBAR * 0.01 * 1e-6),
        # sigma = |M_b| R / I grows by k_bar_n R w dt (the shear it also makes is unbreakable).
        ("parallel_tension", dict(pb_tensile=2e6), dict(spin=(0, 0, 5.0)), KBAR * R * 5.0 * 1e-6),
        # tau = |F_s| / A grows by k_bar_s v dt (rotations held: no bending).
        ("parallel_shear", dict(pb_shear=1e6), dict(vel=(0, 0.01, 0)), KBAR * 0.01 * 1e-6),
        # tau = |M_t| R / J grows by k_bar_s R w dt.
        ("parallel_shear", dict(pb_shear=1e6), dict(spin=(5.0, 0, 0)), KBAR * R * 5.0 * 1e-6),
        # The contact bond: the normal force in tension grows by k_n v dt.
        ("contact_tension", dict(pb_kn=0, contact_bond=True, cb_tensile=0.05),
         dict(vel=(0.01, 0, 0)), 1e5 * 0.01 * 1e-6),
        ("contact_shear", dict(pb_kn=0, contact_bond=True, cb_shear=0.05),
         dict(vel=(0, 0.01, 0)), 1e5 * 0.01 * 1e-6),
    ],
)
def test_breaks_at_the_strength_within_one_step(mode, params, motion, per_step):
    s, ids = pair(pb(**params))
    strength = [v for k, v in params.items() if k in ("pb_tensile", "pb_shear", "cb_tensile",
                                                       "cb_shear")][0]
    ev = drive(s, **motion)
    assert len(ev) == 1
    assert ev[0]["mode"] == mode and ev[0]["bond"] == 0
    assert strength <= ev[0]["value"] < strength + 1.0001 * per_step
    st = s.bond_state()
    if mode.startswith("parallel"):
        assert not st["parallel_bond"][0]
        assert st["pb_sigma"][0] == 0 and st["pb_normal_force"][0] == 0
    else:
        assert not st["contact_bond"][0]
        assert st["normal_force"][0] == 0  # in tension or at zero gap: no force once broken


def test_broken_pair_is_a_frictional_contact():
    """After the contact bond broke in tension, the pair pushes back in compression (k_n) and
    slides at mu F_n, and it never enters the pair pass (no double force)."""
    s, ids = pair(pb(pb_kn=0, contact_bond=True, cb_tensile=0.01))
    drive(s, vel=(0.01, 0, 0))
    # Press the pair together and slide it.
    pos = s.positions
    pos[1] = [L - 1e-6, 0, 0]
    s.positions = pos
    s.velocities = np.array([[0, 0, 0], [0, 0.01, 0]])
    s.run(200)  # 2e-6 m of sliding: the elastic shear reaches mu F_n after 5e-7 m
    st = s.bond_state()
    fn = st["normal_force"][0]
    assert fn == pytest.approx(1e5 * 1e-6, rel=1e-3)  # (the slide opens the gap by 1e-9 m)
    assert np.linalg.norm(st["shear_force"][0]) == pytest.approx(0.5 * fn, rel=1e-9)
    assert s.num_active_contacts == 0  # the pair pass never saw the bonded pair
    np.testing.assert_allclose(s.forces[1], st["force"][0], rtol=1e-12)


def _vibrate(params, dt_fraction, steps):
    n = 12
    s, ids = chain(n, params, damping=0.0, axis=0)
    s.block_dofs(int(ids[0]), "")
    rng = np.random.default_rng(3)
    s.velocities = rng.normal(0, 1e-3, (n + 1, 3))
    s.angular_velocities = rng.normal(0, 1.0, (n + 1, 3))
    s.dt = dt_fraction * s.critical_dt()
    s.track_energy = True
    s.run(1)
    worst = 0.0
    for _ in range(40):
        s.run(steps // 40)
        e = s.energies()
        worst = max(worst, e["balance_error_relative"])
    assert e["elastic"] > 0.05 * e["kinetic"]  # the bonds do work
    return worst


def test_energy_balance_of_a_vibrating_chain():
    """A free chain, contact and parallel bonds intact, undamped, set vibrating in every
    mode: kinetic + bond energy stays constant, to second order in dt (leapfrog)."""
    coarse = _vibrate(pb(contact_bond=True), 0.05, 40000)
    fine = _vibrate(pb(contact_bond=True), 0.025, 80000)
    assert coarse < 1e-3
    assert fine < 0.35 * coarse  # halving dt divides the error by about 4 (measured 3.9)


# ---- bookkeeping ---------------------------------------------------------------------------


def _grid_of_bonds(sort):
    """A 20 x 20 sheet of bonded spheres (760 bonds: the pass runs threaded) with a few
    grains dropped on it."""
    s = cd.Scene(gravity=(0, 0, -9.81), local_damping=0.2)
    s.spatial_sort = sort
    m = s.add_material(_material())
    g = np.array([[i * L, j * L, 0.0] for i in range(20) for j in range(20)])
    ids = s.add_spheres(g, np.full(len(g), R), material=m)
    p = pb(pb_tensile=5e5, pb_shear=5e5)
    for i in range(20):
        for j in range(20):
            k = i * 20 + j
            if i < 19:
                s.add_bond(int(ids[k]), int(ids[k + 20]), p)
            if j < 19:
                s.add_bond(int(ids[k]), int(ids[k + 1]), p)
    edge = [i * 20 + j for i in range(20) for j in range(20) if i in (0, 19) or j in (0, 19)]
    s.block_dofs([int(ids[k]) for k in edge], "all")
    rng = np.random.default_rng(1)
    top = np.column_stack([rng.uniform(5 * L, 14 * L, 30), rng.uniform(5 * L, 14 * L, 30),
                           2.2 * R + np.arange(30) * 2.5 * R])
    s.add_spheres(top, np.full(30, R), material=m)
    s.dt = 0.3 * s.critical_dt()
    return s


def test_storage_order_and_threads_do_not_change_results():
    runs = []
    before = cd.get_num_threads()
    try:
        for sort, threads in ((False, 1), (True, 1), (True, 2)):
            cd.set_num_threads(threads)
            s = _grid_of_bonds(sort)
            s.run(3000)
            runs.append((s.positions.copy(), s.bond_state()["force"].copy(),
                         len(s.bond_breaks)))
    finally:
        cd.set_num_threads(before)
    assert runs[0][0].shape == runs[1][0].shape
    for p, f, nb in runs[1:]:
        assert np.array_equal(p, runs[0][0])
        assert np.array_equal(f, runs[0][1])
        assert nb == runs[0][2]


def test_checkpoint_restart_is_bitwise(tmp_path):
    a = _grid_of_bonds(True)
    a.run(1000)
    save_checkpoint(tmp_path / "ck.h5", a)
    b = _grid_of_bonds(True)
    load_checkpoint(tmp_path / "ck.h5", b)
    a.run(1000)
    b.run(1000)
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.bond_state()["pb_bending_moment"], b.bond_state()["pb_bending_moment"])


@pytest.mark.parametrize("field, value", [("kn", 0.0), ("ks", -1.0), ("pb_kn", -1.0),
                                          ("pb_radius_factor", 0.0), ("pb_tensile", -1.0),
                                          ("cb_shear", float("nan")), ("friction", -0.1)])
def test_bad_parameters_name_the_field(field, value):
    kw = dict(kn=1e5)
    kw[field] = value
    with pytest.raises(cd.ParameterError, match=field):
        BondParams(**kw)


def test_bad_bonds_are_refused():
    s, ids = pair(pb())
    with pytest.raises(cd.ParameterError, match="bonded already"):
        s.add_bond(int(ids[1]), int(ids[0]), pb())
    with pytest.raises(cd.ParameterError, match="must differ"):
        s.add_bond(int(ids[0]), int(ids[0]), pb())
    with pytest.raises(cd.ParameterError):
        s.add_bond(int(ids[0]), 7, pb())
