"""Verification of the sphere DEM core against analytic solutions. Tolerances are stated."""

import math

import numpy as np
import pytest

import cpp_dem as dem
from conftest import sphere_mass

G = 9.81
RHO = 2600.0
E = 1e7


def two_spheres(mat, r1=0.01, r2=0.01, gap=0.0, v=1.0):
    """Sphere 0 at rest, sphere 1 approaching along -x at speed v (m/s); touching after gap."""
    s = dem.Scene()
    m = s.add_material(mat)
    s.add_spheres([[0, 0, 0], [r1 + r2 + gap, 0, 0]], [r1, r2], material=m)
    s.velocities = np.array([[0, 0, 0], [-v, 0, 0]], float)
    return s


def run_collision(s, max_steps):
    """Runs until the contact has opened again; returns (steps in contact, speeds after)."""
    in_contact = 0
    started = False
    for _ in range(max_steps):
        s.run(1)
        if s.num_active_contacts:
            started = True
            in_contact += 1
        elif started:
            break
    return in_contact, s.velocities


def test_free_fall_matches_leapfrog_exactly_and_analytic_within_dt():
    s = dem.Scene(gravity=(0, 0, -G))
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_spheres([[0, 0, 10.0]], [0.01], material=m)
    dt = 1e-3
    s.dt = dt
    n = 1000
    s.run(n)
    t = n * dt
    z = s.positions[0, 2]
    vz = s.velocities[0, 2]
    # Leapfrog with v(-dt/2) = 0: v_(n+1/2) = -g (n+1) dt and z_n = z0 - g dt^2 n (n+1) / 2.
    assert vz == pytest.approx(-G * n * dt, rel=1e-12)
    assert z == pytest.approx(10.0 - G * dt**2 * n * (n + 1) / 2, rel=1e-12)
    # Continuous solution: differs by the half-step offset g t dt / 2 at most.
    assert abs(z - (10.0 - 0.5 * G * t**2)) <= 0.5 * G * t * dt * (1 + 1e-9)


def test_linear_contact_duration_and_elastic_rebound():
    mat = dem.linear_material(density=RHO, young=E, poisson=0.3, friction_angle_deg=30)
    r1, r2 = 0.01, 0.015
    s = two_spheres(mat, r1, r2, gap=1e-6, v=0.5)
    m1, m2 = sphere_mass(RHO, r1), sphere_mass(RHO, r2)
    m_eff = m1 * m2 / (m1 + m2)
    kn = 2 * E * r1 * E * r2 / (E * r1 + E * r2)  # 000 eq (4)
    t_an = math.pi * math.sqrt(m_eff / kn)
    s.dt = t_an / 2000
    steps, v = run_collision(s, 20000)
    # Duration resolved to one step: tolerance 2 dt.
    assert abs(steps * s.dt - t_an) <= 2 * s.dt
    # Elastic: momentum and kinetic energy conserved (1e-3 for the discrete contact start/end).
    p = m1 * v[0] + m2 * v[1]
    np.testing.assert_allclose(p, [-m2 * 0.5, 0, 0], atol=1e-12)
    ke = 0.5 * m1 * v[0] @ v[0] + 0.5 * m2 * v[1] @ v[1]
    assert ke == pytest.approx(0.5 * m2 * 0.25, rel=1e-3)


@pytest.mark.parametrize("beta", [0.05, 0.2, 0.5])
def test_restitution_with_viscous_damping(beta):
    mat = dem.linear_material(density=RHO, young=E, poisson=0.3, friction_angle_deg=30,
                              damping_normal=beta)
    s = two_spheres(mat, gap=1e-6, v=1.0)
    m_eff = sphere_mass(RHO, 0.01) / 2
    kn = E * 0.01
    s.dt = math.pi * math.sqrt(m_eff / kn) / 2000
    _, v = run_collision(s, 40000)
    e_num = (v[1, 0] - v[0, 0]) / (0 - (-1.0))
    # Linear spring–dashpot, contact ending at zero overlap.
    e_an = math.exp(-beta * math.pi / math.sqrt(1 - beta**2))
    assert e_num == pytest.approx(e_an, rel=5e-3)


def test_hertz_contact_duration():
    G_mod, nu = 3e8, 0.25
    mat = dem.hertz_mindlin_material(density=RHO, shear_modulus=G_mod, poisson=nu,
                                     friction_coefficient=0.8)
    r, v0 = 0.01, 0.3
    s = two_spheres(mat, r, r, gap=1e-7, v=v0)
    m_eff = sphere_mass(RHO, r) / 2
    young = 2 * G_mod * (1 + nu)
    e_star = young / (2 * (1 - nu**2))
    r_star = r / 2
    k = 4 / 3 * e_star * math.sqrt(r_star)
    delta_max = (5 * m_eff * v0**2 / (4 * k)) ** 0.4
    # t_c = 2 (delta_max / v0) int_0^1 dx / sqrt(1 - x^(5/2)) = 2.9432 delta_max / v0.
    integral = math.sqrt(math.pi) * math.gamma(7 / 5) / math.gamma(9 / 10)
    t_an = 2 * delta_max / v0 * integral
    s.dt = t_an / 2000
    steps, v = run_collision(s, 20000)
    assert abs(steps * s.dt - t_an) <= 2 * s.dt
    assert v[1, 0] - v[0, 0] == pytest.approx(v0, rel=1e-3)  # elastic


def test_two_sphere_force_equals_000_eqs_1_to_6():
    """One step of two overlapping spheres with a tangential velocity: the normal force is
    k_n u_n (eqs 1, 4), the shear force k_s u_s_dot dt (eqs 2, 5), the moment (R - d/2) n x F
    (eq 6), to round-off."""
    e1, e2, nu1, nu2 = 2e7, 5e6, 0.3, 0.2
    r1, r2 = 0.01, 0.02
    s = dem.Scene()
    ma = s.add_material(dem.linear_material(density=RHO, young=e1, poisson=nu1,
                                            friction_angle_deg=40))
    mb = s.add_material(dem.linear_material(density=RHO, young=e2, poisson=nu2,
                                            friction_angle_deg=30))
    delta = 1e-4
    s.add_spheres([[0, 0, 0]], [r1], material=ma)
    s.add_spheres([[r1 + r2 - delta, 0, 0]], [r2], material=mb)
    vt = 0.01
    s.velocities = np.array([[0, 0, 0], [0, vt, 0]], float)
    s.dt = 1e-6
    s.run(1)
    kn = 2 * e1 * r1 * e2 * r2 / (e1 * r1 + e2 * r2)
    ks = 2 * e1 * r1 * nu1 * e2 * r2 * nu2 / (e1 * r1 * nu1 + e2 * r2 * nu2)
    c = s.contacts()
    f = c["force"][0]  # on sphere 1 (the second body)
    np.testing.assert_allclose(f[0], kn * delta, rtol=1e-12)
    np.testing.assert_allclose(f[1], -ks * vt * s.dt, rtol=1e-12)
    assert abs(f[2]) < 1e-15
    assert abs(f[1]) < math.tan(math.radians(30)) * kn * delta  # below the Coulomb cap
    # Moments, eq (6): tau_i = (R_i - d/2) n x F_i with F_0 = -f, n from 0 to 1.
    n = np.array([1.0, 0, 0])
    t = s.torques
    np.testing.assert_allclose(t[0], (r1 - delta / 2) * np.cross(n, -f), rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(t[1], (r2 - delta / 2) * np.cross(-n, f), rtol=1e-12, atol=1e-20)
    # Mixing with the smaller friction angle; the contact parameters are exposed.
    phys = dem.mix_materials(s.material(ma), s.material(mb), r1, r2, 1.0, 2.0)
    assert phys.kn == pytest.approx(kn, rel=1e-14)
    assert phys.ks == pytest.approx(ks, rel=1e-14)
    assert phys.tan_phi == pytest.approx(math.tan(math.radians(30)), rel=1e-14)


def test_coulomb_cap_during_sliding():
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=25))
    delta = 1e-4
    s.add_spheres([[0, 0, 0], [0.02 - delta, 0, 0]], [0.01, 0.01], material=m)
    s.block_dofs([0, 1], "all")
    s.velocities = np.array([[0, 0, 0], [0, 0.5, 0]], float)
    s.dt = 1e-5
    s.run(200)
    c = s.contacts()
    f, n, fn = c["force"][0], c["normal"][0], c["normal_force"][0]
    assert f @ n == pytest.approx(fn, rel=1e-12)
    ft = f - (f @ n) * n
    assert np.linalg.norm(ft) == pytest.approx(math.tan(math.radians(25)) * fn, rel=1e-12)
    assert ft[1] < 0  # opposes the sliding of sphere 1 along +y


def incline_run(theta_deg, phi_deg, steps=20000):
    th = math.radians(theta_deg)
    s = dem.Scene(gravity=(G * math.sin(th), 0, -G * math.cos(th)))
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=phi_deg, damping_normal=0.3,
                                           damping_shear=0.3))
    r = 0.01
    s.add_wall(axis=2, position=0.0, sense=1, material=m)
    s.add_spheres([[0, 0, r]], [r], material=m)
    s.block_dofs(0, "rot")  # a non-rolling body: slides when tan(theta) > tan(phi)
    s.set_auto_timestep(safety=0.3, period=10)
    s.run(steps)
    return s


@pytest.mark.parametrize("phi", [20.0, 30.0])
def test_incline_slides_at_tan_phi(phi):
    rest = incline_run(phi - 1.0, phi)
    x0 = rest.positions[0, 0]
    rest.run(5000)
    assert abs(rest.positions[0, 0] - x0) < 1e-9  # stuck just below phi (m)
    slide = incline_run(phi + 1.0, phi)
    th = math.radians(phi + 1.0)
    a_an = G * (math.sin(th) - math.tan(math.radians(phi)) * math.cos(th))
    v0 = slide.velocities[0, 0]
    slide.run(5000)
    a_num = (slide.velocities[0, 0] - v0) / (5000 * slide.dt)
    assert a_num == pytest.approx(a_an, rel=1e-2)


def test_sliding_sphere_rolls_at_five_sevenths():
    s = dem.Scene(gravity=(0, 0, -G))
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30, damping_normal=0.5,
                                           damping_shear=0.5))
    r, v0 = 0.01, 1.0
    s.add_wall(axis=2, position=0.0, sense=1, material=m)
    s.add_spheres([[0, 0, r - sphere_mass(RHO, r) * G / (E * r)]], [r], material=m)
    s.velocities = np.array([[v0, 0, 0]])
    s.set_auto_timestep(safety=0.3, period=10)
    s.run(60000)
    vx = s.velocities[0, 0]
    wy = s.angular_velocities[0, 1]
    assert vx == pytest.approx(5 / 7 * v0, rel=2e-3)
    assert wy * r == pytest.approx(vx, rel=2e-3)  # rolling without slip


def test_sphere_at_rest_on_floor_weight_and_box_walls():
    s = dem.Scene(gravity=(0, 0, -G), local_damping=0.3)
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30))
    walls = s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    s.add_spheres([[0.05, 0.05, 0.0105], [0.03, 0.03, 0.05]], [0.01, 0.012], material=m)
    s.set_auto_timestep(safety=0.5, period=10)
    s.run(20000)
    wf = s.wall_forces
    weight = G * s.masses.sum()
    assert wf[walls[4], 2] == pytest.approx(-weight, rel=1e-6)  # floor pushed down
    assert np.abs(np.delete(wf, walls[4], axis=0)).max() < 1e-9 * weight
    np.testing.assert_allclose(s.positions[:, 2], s.radii - s.masses * G / (E * s.radii),
                               rtol=1e-6)


def test_moving_wall_compresses_and_reports_force():
    s = dem.Scene(local_damping=0.5)
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_wall(axis=2, position=0.0, sense=1, material=m)
    top = s.add_wall(axis=2, position=0.02, sense=-1, material=m)
    s.add_spheres([[0, 0, 0.01]], [0.01], material=m)
    s.set_wall_velocity(top, [0, 0, -1e-3])
    s.dt = 1e-5
    s.run(100)  # wall moves 1e-6 m
    assert s.wall_positions[top] == pytest.approx(0.02 - 1e-6, rel=1e-12)
    s.set_wall_velocity(top, [0, 0, 0])
    s.run(20000)
    # Two springs E R in series across the sphere: force = (E R / 2) * total overlap.
    f = s.wall_forces[top, 2]
    assert f == pytest.approx(E * 0.01 / 2 * 1e-6, rel=1e-4)


def test_rolling_resistance_decelerates_at_the_capped_moment():
    """A sphere rolling without slip on a floor, rolling resistance capped at
    |M_r| = eta R* F_n (R* = r against a wall): a = -M_r / (1.4 m r) = -eta g / 1.4."""
    s = dem.Scene(gravity=(0, 0, -G))
    eta = 0.1
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30, rolling_stiffness=1.0,
                                           rolling_friction=eta, damping_normal=0.5,
                                           damping_shear=0.5))
    r, v0 = 0.01, 0.2
    s.add_wall(axis=2, position=0.0, sense=1, material=m)
    s.add_spheres([[0, 0, r - sphere_mass(RHO, r) * G / (E * r)]], [r], material=m)
    s.velocities = np.array([[v0, 0, 0]])
    s.angular_velocities = np.array([[0, v0 / r, 0]])
    s.set_auto_timestep(safety=0.3, period=10)
    s.run(500)  # let the rolling spring reach its cap
    v1, t1 = s.velocities[0, 0], s.time
    s.run(int(0.1 / s.dt))
    a_num = (s.velocities[0, 0] - v1) / (s.time - t1)
    assert a_num == pytest.approx(-eta * G / 1.4, rel=2e-2)
    s.run(int(0.5 / s.dt))  # stops (v0 / a = 0.29 s)
    assert abs(s.velocities[0, 0]) < 1e-3


def grains_in_box(rng, n_side, first, spacing, jitter, r_range, box, damping_normal=0.0,
                  **scene_kw):
    """n_side^3 frictional grains (radii uniform in r_range, m) on a jittered lattice
    (first + spacing * index +- jitter, m) in a box [0, box] of six walls."""
    s = dem.Scene(**scene_kw)
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30, damping_normal=damping_normal))
    s.add_box((0, 0, 0), box, material=m)
    g = np.stack(np.meshgrid(*[np.arange(n_side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    c = first + spacing * g + rng.uniform(-jitter, jitter, g.shape)
    s.add_spheres(c, rng.uniform(*r_range, len(c)), material=m)
    return s


def test_energy_balance_undamped_over_1e5_steps():
    """Frictional spheres bouncing in a box under gravity, no damping: the energy balance
    (kinetic + elastic + potential + friction dissipation) drifts by < 1e-3 relative."""
    rng = np.random.default_rng(3)
    s = grains_in_box(rng, 3, 0.012, 0.018, 0.002, (0.004, 0.006), (0.06, 0.06, 0.06),
                      gravity=(0, 0, -G))
    s.velocities = rng.normal(0, 0.3, (s.num_bodies, 3))
    s.track_energy = True
    # Each contact resolved in about 30 steps: the per-collision error of leapfrog (from the
    # force jumping on at contact entry) scales with (omega dt)^2 and adds up as a random walk.
    s.set_auto_timestep(safety=0.05, period=100)
    s.run(100_000)
    e = s.energies()
    assert e["friction"] > 0  # the test exercises slip
    assert e["balance_error_relative"] < 1e-3, e


@pytest.mark.parametrize("energy", [False, True])  # the two integration paths
def test_one_and_two_threads_bitwise_identical(energy):
    def run(threads):
        dem.set_num_threads(threads)
        s = grains_in_box(np.random.default_rng(7), 8, 0.008, 0.012, 0.001, (0.004, 0.0055),
                          (0.1, 0.1, 0.2), damping_normal=0.1, gravity=(0, 0, -G),
                          local_damping=0.1)
        s.track_energy = energy
        s.set_auto_timestep(safety=0.5, period=50)
        s.run(3000)
        return s.positions, s.velocities, s.forces, s.wall_forces, s.energies()

    before = dem.get_num_threads()
    try:
        a = run(1)
        b = run(2)
    finally:
        dem.set_num_threads(before)
    for x, y in zip(a[:4], b[:4]):
        assert np.array_equal(x, y)
    assert a[4] == b[4]


def test_energy_bookkeeping_does_not_change_the_trajectory():
    # With track_energy the integration runs body by body (plus the energy terms), without it
    # in vectorised blocks: the same arithmetic, so positions and velocities are bitwise
    # equal; the orientations may differ in the last bits (docs/core.md, Time integration).
    def run(energy):
        s = grains_in_box(np.random.default_rng(3), 8, 0.008, 0.012, 0.001, (0.004, 0.0055),
                          (0.1, 0.1, 0.2), gravity=(0, 0, -G), local_damping=0.2)
        s.block_dofs(0, "xyz")  # one body on the blocked-DOF path
        s.track_energy = energy
        s.dt = 2e-5
        s.run(3000)
        return s.positions, s.velocities, s.angular_velocities, s.orientations

    a, b = run(False), run(True)
    assert np.abs(a[2]).max() > 0  # the grains spin
    for x, y in zip(a[:3], b[:3]):
        assert np.array_equal(x, y)
    assert np.abs(a[3] - b[3]).max() < 1e-14


def test_blow_up_raises_naming_step_and_body():
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_spheres([[0, 0, 0], [0.0199, 0, 0]], [0.01, 0.01], material=m)
    s.velocities = np.array([[0, 0, 0], [-50.0, 0, 0]])
    s.dt = 1e-4  # the sphere crosses half a radius within one step
    with pytest.raises(dem.BlowUpError, match=r"blow-up at step \d+: bodies 0 and 1 overlap"):
        s.run(100)
    # The state stays finite (the step stopped before moving anything).
    assert np.isfinite(s.positions).all()


def test_critical_dt_estimates():
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.5,
                                           friction_angle_deg=30))
    r = 0.01
    s.add_spheres([[0, 0, 0], [2 * r - 1e-5, 0, 0]], [r, r], material=m)
    assert s.critical_dt() == pytest.approx(r * math.sqrt(RHO / E), rel=1e-12)  # p-wave
    s.dt = 1e-7
    s.run(1)
    mass = sphere_mass(RHO, r)
    kn = E * r
    ks = 0.5 * kn
    expected = min(math.sqrt(2 * mass / kn),
                   math.sqrt(2 * 0.4 * mass * r**2 / (ks * (r - 0.5e-5) ** 2)))
    assert s.critical_dt() == pytest.approx(expected, rel=1e-9)


def test_hertz_sphere_resting_on_wall_static_overlap():
    """Hertz against a flat wall (R* = R): m g = 4/3 E* sqrt(R) d^1.5 at rest."""
    g_mod, nu, r = 1e8, 0.3, 0.01
    s = dem.Scene(gravity=(0, 0, -G), local_damping=0.5)
    m = s.add_material(dem.hertz_mindlin_material(density=RHO, shear_modulus=g_mod, poisson=nu,
                                                  friction_coefficient=0.5))
    s.add_wall(axis=2, position=0.0, sense=1, material=m)
    s.add_spheres([[0, 0, r]], [r], material=m)
    s.set_auto_timestep(safety=0.5, period=10)
    s.run(20000)
    young = 2 * g_mod * (1 + nu)
    e_star = young / (2 * (1 - nu**2))
    d = (sphere_mass(RHO, r) * G / (4 / 3 * e_star * math.sqrt(r))) ** (2 / 3)
    assert r - s.positions[0, 2] == pytest.approx(d, rel=1e-6)


def test_mindlin_tangential_stiffness_one_step():
    """One step of a tangential velocity on a Hertz contact: F_s = 8 G* sqrt(R* d) v dt."""
    g_mod, nu, r = 1e8, 0.25, 0.01
    s = dem.Scene()
    m = s.add_material(dem.hertz_mindlin_material(density=RHO, shear_modulus=g_mod, poisson=nu,
                                                  friction_coefficient=0.8))
    d = 1e-5
    s.add_spheres([[0, 0, 0], [2 * r - d, 0, 0]], [r, r], material=m)
    s.velocities = np.array([[0, 0, 0], [0, 0, 0.01]])
    s.dt = 1e-6
    s.run(1)
    g_star = 1 / (2 * (2 - nu) / g_mod)
    r_star = r / 2
    f = s.contacts()["force"][0]
    young = 2 * g_mod * (1 + nu)
    e_star = young / (2 * (1 - nu**2))
    assert f[0] == pytest.approx(4 / 3 * e_star * math.sqrt(r_star) * d**1.5, rel=1e-12)
    assert f[2] == pytest.approx(-8 * g_star * math.sqrt(r_star * d) * 0.01 * 1e-6, rel=1e-12)


def test_free_spin_orientation_matches_the_exact_rotation():
    """A free sphere spinning at constant w: after n steps its orientation is the rotation by
    |w| n dt about w (1e-9), both for small steps (series) and large ones (sin/cos)."""
    for w_mag, dt in ((3.0, 1e-4), (400.0, 5e-4)):
        sc = dem.Scene(dt=dt)
        m = sc.add_material(dem.linear_material(density=1000, young=1e7, poisson=0.3,
                                                friction_angle_deg=30))
        sc.add_spheres([[0, 0, 0]], [0.01], material=m)
        axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
        sc.angular_velocities = (w_mag * axis)[None, :]
        sc.run(2000)
        ang = w_mag * 2000 * dt
        q = np.concatenate([[np.cos(ang / 2)], np.sin(ang / 2) * axis])
        got = np.asarray(sc.orientations)[0]
        assert min(np.abs(got - q).max(), np.abs(got + q).max()) < 1e-9
        # Renormalised every 64 steps only: 2000 = 31 x 64 + 16, |q| still 1 to round-off.
        assert abs(np.linalg.norm(got) - 1) < 1e-14


def test_spins_in_and_out_of_the_series_range_in_one_block():
    # 70 free spheres (two blocks of the integration pass): the first block holds one sphere
    # spinning beyond the series range, so that block takes the per-body path with sin/cos;
    # the second block is all slow and takes the vectorised series. Every sphere matches the
    # exact rotation.
    dt, n = 5e-4, 70
    sc = dem.Scene(dt=dt, gravity=(0, 0, 0))
    m = sc.add_material(dem.linear_material(density=1000, young=1e7, poisson=0.3,
                                            friction_angle_deg=30))
    sc.spatial_sort = False  # keep ids = slots, so the blocks are known
    sc.add_spheres(np.c_[np.arange(n) * 0.1, np.zeros(n), np.zeros(n)], np.full(n, 0.01),
                   material=m)
    rng = np.random.default_rng(5)
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    w_mag = np.full(n, 3.0)
    w_mag[10] = 400.0  # |w| dt / 2 = 0.1: beyond the series range (0.05)
    sc.angular_velocities = w_mag[:, None] * axes
    sc.run(500)
    got = np.asarray(sc.orientations)
    for b in range(n):
        ang = w_mag[b] * 500 * dt
        q = np.concatenate([[np.cos(ang / 2)], np.sin(ang / 2) * axes[b]])
        assert min(np.abs(got[b] - q).max(), np.abs(got[b] + q).max()) < 1e-9, b
