"""Scene.shear_kinematics: the relative velocity that grows a sphere–sphere shear spring.

'contact_point' (default): v_j - v_i - (l_j w_j + l_i w_i) x n, l = r - overlap/2.
'yade' (Yade's ScGeom with avoidGranularRatcheting): alpha (v_j - v_i) - (r_j w_j + r_i w_i) x n,
alpha = (r_i + r_j) / (r_i + r_j - overlap).

After the first step of a new contact the linear law's shear force is -k_s dt v_t, v_t the
tangential part of that velocity, so one step checks the formula exactly."""

import os
import subprocess
import sys

import numpy as np
import pytest

import cpp_dem as cd

R1, R2 = 1.0e-3, 1.5e-3  # m (unequal, so the radii and branch lengths differ per side)
OVERLAP = 2.0e-5  # m
DT = 1e-7  # s


def _pair(kinematics, vel_i=(0, 0, 0), vel_j=(0, 0, 0), spin_i=(0, 0, 0), spin_j=(0, 0, 0),
          **parts):
    """Two spheres touching along x with the given velocities (m/s) and spins (rad/s), every
    DOF blocked (they keep them); returns (scene, shear force on j after one step in N, k_s).
    parts: law parts of the material (rolling resistance takes the composed law's path)."""
    s = cd.Scene()
    if kinematics is not None:
        s.shear_kinematics = kinematics
    m = s.add_material(cd.linear_material(density=2650, young=1e8, poisson=0.3,
                                          friction_angle_deg=80.0, **parts))
    s.add_spheres([[0, 0, 0], [R1 + R2 - OVERLAP, 0, 0]], [R1, R2], material=m)
    s.dt = DT
    s.velocities = np.array([vel_i, vel_j], dtype=float)
    s.angular_velocities = np.array([spin_i, spin_j], dtype=float)
    s.block_dofs([0, 1], "all")
    s.run(1)
    c = s.contacts()
    assert len(c["ids"]) == 1
    return s, np.asarray(c["shear_force"][0]), float(c["ks"][0])


def _expected(kinematics, vel_i, vel_j, spin_i, spin_j, ks):
    n = np.array([1.0, 0, 0])
    dv = np.subtract(vel_j, vel_i)
    if kinematics == "yade":
        alpha = (R1 + R2) / (R1 + R2 - OVERLAP)
        rel = alpha * dv - np.cross(R2 * np.asarray(spin_j) + R1 * np.asarray(spin_i), n)
    else:
        li, lj = R1 - 0.5 * OVERLAP, R2 - 0.5 * OVERLAP
        rel = dv - np.cross(lj * np.asarray(spin_j) + li * np.asarray(spin_i), n)
    vt = rel - rel.dot(n) * n
    return -ks * DT * vt


def test_default_is_contact_point():
    assert cd.Scene().shear_kinematics == "contact_point"


def test_translation_is_scaled_by_alpha_only_with_yade_kinematics():
    alpha = (R1 + R2) / (R1 + R2 - OVERLAP)
    kw = dict(vel_i=(0, 0, 2e-4), vel_j=(3e-5, 1e-3, 0))  # tangential and a little normal
    _, f_off, ks = _pair(None, **kw)
    _, f_on, ks_on = _pair("yade", **kw)
    assert ks == ks_on
    vt = np.array([0, 1e-3, -2e-4])
    np.testing.assert_allclose(f_off, -ks * DT * vt, rtol=1e-12, atol=0)
    np.testing.assert_allclose(f_on, -ks * DT * alpha * vt, rtol=1e-12, atol=0)
    # alpha - 1 = overlap / distance = 8e-3: the two differ far beyond round-off.
    ratio = f_on[1] / f_off[1]
    assert ratio == pytest.approx(alpha, rel=1e-13)
    assert abs(ratio - 1) > 7e-3


@pytest.mark.parametrize("parts", [{}, {"rolling_stiffness": 1.0, "rolling_friction": 0.1}],
                         ids=["short-kernel", "composed-law"])
def test_spins_act_on_the_full_radii_with_yade_kinematics(parts):
    kw = dict(vel_i=(0, 2e-4, 0), vel_j=(0, 0, -1e-4), spin_i=(0.1, 0.3, -0.2),
              spin_j=(0.05, -0.4, 0.25))
    for kin in ("contact_point", "yade"):
        _, f, ks = _pair(kin, **kw, **parts)
        np.testing.assert_allclose(f, _expected(kin, ks=ks, **kw), rtol=1e-12, atol=1e-30)
    # Spins alone: the spin term is (r_j w_j + r_i w_i) x n against (l_j w_j + l_i w_i) x n.
    spins = dict(spin_i=(0, 0, 0.3), spin_j=(0, 0, 0.3))
    _, f_off, _ = _pair(None, **spins, **parts)
    _, f_on, _ = _pair("yade", **spins, **parts)
    ratio = f_on[1] / f_off[1]
    assert ratio == pytest.approx((R1 + R2) / (R1 + R2 - OVERLAP), rel=1e-13)


def test_periodic_cell_mean_field_is_scaled_too():
    """In a periodic cell j's mean-field velocity L d is part of v_j - v_i, so Yade's alpha
    scales it as well (its shiftVel is multiplied by alpha)."""
    rate = 2.0  # 1/s, v_y = rate x
    out = {}
    for kin in ("contact_point", "yade"):
        s = cd.Scene()
        s.shear_kinematics = kin
        m = s.add_material(cd.linear_material(density=2650, young=1e8, poisson=0.3,
                                              friction_angle_deg=80.0))
        s.add_spheres([[4e-3, 5e-3, 5e-3], [4e-3 + R1 + R2 - OVERLAP, 5e-3, 5e-3]], [R1, R2],
                      material=m)
        s.set_periodic_cell(np.diag([1e-2, 1e-2, 1e-2]))
        s.mean_spin = False
        s.velocity_gradient = np.array([[0, 0, 0], [rate, 0, 0], [0, 0, 0]])
        s.dt = DT
        s.block_dofs([0, 1], "all")
        s.run(1)
        c = s.contacts()
        out[kin] = (np.asarray(c["shear_force"][0]), float(c["ks"][0]))
    f_off, ks = out["contact_point"]
    f_on, _ = out["yade"]
    vy = rate * (R1 + R2 - OVERLAP)
    assert f_off[1] == pytest.approx(-ks * DT * vy, rel=1e-12)
    assert f_on[1] / f_off[1] == pytest.approx((R1 + R2) / (R1 + R2 - OVERLAP), rel=1e-12)


def _sheared_packing(kinematics, steps=400):
    """A lattice of 125 overlapping spheres with random velocities and spins pushing itself
    apart in a box that just holds it, under gravity (many sliding and rolling contacts);
    returns positions, spins and the contacts after `steps` steps."""
    rng = np.random.default_rng(5)
    s = cd.Scene(local_damping=0.1, gravity=(0, 0, -9.81))
    if kinematics is not None:
        s.shear_kinematics = kinematics
    m = s.add_material(cd.linear_material(density=2650, young=5e7, poisson=0.3,
                                          friction_angle_deg=30.0))
    g = np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing="ij"), -1).reshape(-1, 3)
    centres = 2.0e-3 * (g + 0.5) + rng.uniform(-1e-4, 1e-4, g.shape)
    radii = rng.uniform(1.0e-3, 1.15e-3, len(g))
    s.add_spheres(centres, radii, material=m)
    s.add_box([0, 0, 0], [0.01, 0.01, 0.01], material=m)
    s.velocities = rng.uniform(-0.05, 0.05, (len(g), 3))
    s.angular_velocities = rng.uniform(-20, 20, (len(g), 3))
    s.dt = 0.3 * s.critical_dt()
    s.run(steps)
    c = s.contacts()
    return np.asarray(s.positions), np.asarray(s.angular_velocities), c


def test_default_unchanged_and_yade_differs():
    pos0, w0, c0 = _sheared_packing(None)
    pos1, w1, c1 = _sheared_packing("contact_point")
    # Setting the default explicitly is the default, bitwise.
    assert np.array_equal(pos0, pos1) and np.array_equal(w0, w1)
    assert np.array_equal(np.asarray(c0["shear_force"]), np.asarray(c1["shear_force"]))
    assert len(c0["ids"]) > 20
    # The Yade kinematics change the run (otherwise the tests above would prove little).
    pos2, _, _ = _sheared_packing("yade")
    assert not np.array_equal(pos0, pos2)


def test_switching_back_restores_the_default_path():
    s = cd.Scene()
    s.shear_kinematics = "yade"
    s.shear_kinematics = "contact_point"
    assert s.shear_kinematics == "contact_point"
    with pytest.raises(cd.ParameterError, match="shear_kinematics='Yade'.*contact_point"):
        s.shear_kinematics = "Yade"


def test_kept_in_checkpoints(tmp_path):
    from cpp_dem import checkpoint

    s = cd.Scene()
    s.shear_kinematics = "yade"
    m = s.add_material(cd.linear_material(density=2650, young=1e8, poisson=0.3,
                                          friction_angle_deg=30.0))
    s.add_spheres([[0, 0, 0], [R1 + R2 - OVERLAP, 0, 0]], [R1, R2], material=m)
    s.dt = DT
    s.run(2)
    path = tmp_path / "c.h5"
    checkpoint.save_checkpoint(path, s)
    t = cd.Scene()
    assert t.shear_kinematics == "contact_point"
    checkpoint.load_checkpoint(path, t)
    assert t.shear_kinematics == "yade"


_NARROW = """
import sys
sys.path.insert(0, {tests!r})
import numpy as np
import test_yade_kinematics as t
kw = dict(vel_i=(0, 2e-4, 0), vel_j=(0, 0, -1e-4), spin_i=(0.1, 0.3, -0.2), spin_j=(0.05, -0.4, 0.25))
for kin in ("contact_point", "yade"):
    _, f, ks = t._pair(kin, **kw)
    print(kin, repr(f.tolist()))
"""


def test_both_vector_forms_agree():
    """The pair pass without AVX2 (CPP_DEM_NARROW=1) computes the same forces."""
    code = _NARROW.format(tests=os.path.dirname(__file__))
    outs = []
    for narrow in ("0", "1"):
        env = dict(os.environ, CPP_DEM_NARROW=narrow)
        p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                           text=True, timeout=300)
        assert p.returncode == 0, p.stderr[-2000:]
        outs.append(p.stdout)
    lines = [o.splitlines() for o in outs]
    assert len(lines[0]) == 2
    for a, b in zip(*lines):
        fa = np.array(eval(a.split(" ", 1)[1]))
        fb = np.array(eval(b.split(" ", 1)[1]))
        np.testing.assert_allclose(fa, fb, rtol=1e-12, atol=0)
    assert lines[0][0] != lines[0][1]


def _skip_vec(b, at: int, elem: int) -> int:
    """The offset after the vector at ``at`` of a checkpoint blob (a count, then its records
    of ``elem`` bytes)."""
    import struct

    return at + 8 + struct.unpack_from("<Q", b, at)[0] * elem


def _skip_to_walls(b, at: int, lay: list) -> int:
    """From the pair laws (at ``at``) of a blob of layout ``lay`` without clumps to its walls:
    the body store, the (empty) clump store, the storage order and the broad phase's build."""
    import struct

    real, v3, q = lay[0], lay[2], lay[3]
    at = _skip_vec(b, at, lay[19])  # pair laws
    for elem in (v3,) * 7 + (q, real, real, real, 4, 1, 1, 4, 12, real, real, real, v3, real):
        at = _skip_vec(b, at, elem)  # the body store
    for _ in range(22):
        assert struct.unpack_from("<Q", b, at)[0] == 0
        at = _skip_vec(b, at, 0)  # the clump store, empty
    at = _skip_vec(b, at, 4)  # id_of_slot
    at += 1  # spatial_sort
    at = _skip_vec(b, at, v3)  # pos_at_build
    return _skip_vec(b, at, real)  # radius_at_build


def _format_14(blob: bytes) -> bytes:
    """A blob of format 15 of a scene without clumps rewritten as format 14: the pair contacts'
    cold part for every contact, with its friction dissipation between the rolling moment and
    the viscous dissipation (112 B a record, the layout's size too), where format 15 has a
    flag, the cold part only if the scene keeps one (104 B a record) and the dissipation
    apart; and the pair pass's outputs for every contact (zero where format 15 kept none: a
    loaded scene's next step writes them). Without the cold part, the phys is the hot
    record's model, kn, ks and tan phi."""
    import struct

    b = bytearray(blob)
    assert int.from_bytes(b[8:12], "little") == 15
    b[8:12] = (14).to_bytes(4, "little")
    n_layout = struct.unpack_from("<Q", b, 12)[0]
    lay = list(struct.unpack_from(f"<{n_layout}Q", b, 20))
    real, wall, opening = lay[0], lay[5], lay[20]
    pair, out, cold, cell = lay[6], lay[7], lay[15], lay[16]
    b[20 + 15 * 8:20 + 16 * 8] = struct.pack("<Q", cold + 8)
    at = 20 + 8 * n_layout

    def skip_vec(at, elem):
        return _skip_vec(b, at, elem)

    count = struct.unpack_from("<Q", b, at)[0]  # the materials, by name
    at += 8
    for _ in range(count):
        at = _skip_vec(b, at, 1)  # the law's name
        n_fields = struct.unpack_from("<Q", b, at)[0]
        at += 8
        for _ in range(n_fields):
            at = _skip_vec(b, at, 1) + 8  # a field's name and value
    at = _skip_to_walls(b, at, lay)
    at = skip_vec(at, wall)
    at = skip_vec(at, opening)
    at += cell + real  # the cell, max_radius_at_build
    npairs = struct.unpack_from("<Q", b, at)[0]
    hot = [bytes(b[at + 8 + k * pair:at + 8 + (k + 1) * pair]) for k in range(npairs)]
    at = skip_vec(at, pair)
    start, on = at, b[at]
    at += 1
    ncold = struct.unpack_from("<Q", b, at)[0]
    colds = [bytes(b[at + 8 + k * cold:at + 8 + (k + 1) * cold]) for k in range(ncold)]
    at = skip_vec(at, cold)
    dissip = [bytes(b[at + 8 + 8 * k:at + 16 + 8 * k]) for k in range(npairs)]
    at = skip_vec(at, real)
    nout = struct.unpack_from("<Q", b, at)[0]
    outs = bytes(b[at + 8:at + 8 + nout * out]) if nout == npairs else bytes(npairs * out)
    end = skip_vec(at, out)
    old = []
    for k in range(npairs):
        if on:
            phys, mr, viscous = colds[k][:72], colds[k][72:96], colds[k][96:104]
        else:  # (model byte at 11; kn, ks, tan phi at 16)
            phys = (hot[k][11:12] + bytes(7) + hot[k][16:40] + bytes(5 * 8))
            mr, viscous = bytes(24), bytes(8)
        old.append(phys + mr + dissip[k] + viscous)
    b[start:end] = (struct.pack("<Q", npairs) + b"".join(old) + struct.pack("<Q", npairs)
                    + outs)
    return bytes(b)


def _format_13(blob: bytes) -> bytes:
    """A blob of format 15 rewritten as format 14 (_format_14), then, of a scene without
    cylindrical or mesh walls and without controllers, as format 13: their 12 empty vectors
    and the dropped-contact count (just before the controllers' count, at the end) gone, and
    their three record sizes, the layout's last entries."""
    import struct

    b = bytearray(_format_14(blob))
    assert int.from_bytes(b[8:12], "little") == 14
    b[8:12] = (13).to_bytes(4, "little")
    assert struct.unpack_from("<Q", b, len(b) - 8)[0] == 0  # no controller
    section = b[len(b) - 8 - 13 * 8:len(b) - 8]
    assert bytes(section) == bytes(13 * 8)  # 12 empty vectors and a count of 0
    del b[len(b) - 8 - 13 * 8:len(b) - 8]
    n_layout = struct.unpack_from("<Q", b, 12)[0]
    del b[20 + 8 * (n_layout - 3):20 + 8 * n_layout]
    b[12:20] = struct.pack("<Q", n_layout - 3)
    return bytes(b)


def _format_12(blob: bytes) -> bytes:
    """A blob of format 15 rewritten as format 13 (_format_13), then as format 12: its
    materials as records of the 8 shared parameters (the law's id, 7 bytes of padding, 8
    doubles) instead of names and values, and the record's size in the layout."""
    import struct

    b = bytearray(_format_13(blob))
    assert int.from_bytes(b[8:12], "little") == 13
    b[8:12] = (12).to_bytes(4, "little")
    n_layout = struct.unpack_from("<Q", b, 12)[0]
    assert struct.unpack_from("<Q", b, 20 + 4 * 8)[0] == 0  # (materials by name: no size)
    b[20 + 4 * 8:20 + 5 * 8] = struct.pack("<Q", 8 + 8 * 8)
    at = start = 20 + 8 * n_layout
    laws = [law["name"] for law in cd.contact_laws()]
    order = ("density", "young", "poisson", "friction_angle_deg", "damping_normal",
             "damping_shear", "rolling_stiffness", "rolling_friction")

    def text(at):
        n = struct.unpack_from("<Q", b, at)[0]
        return bytes(b[at + 8:at + 8 + n]).decode(), at + 8 + n

    records = []
    count = struct.unpack_from("<Q", b, at)[0]
    at += 8
    for _ in range(count):
        law, at = text(at)
        values = {}
        n_fields = struct.unpack_from("<Q", b, at)[0]
        at += 8
        for _ in range(n_fields):
            name, at = text(at)
            values[name] = struct.unpack_from("<d", b, at)[0]
            at += 8
        records.append(struct.pack("<B7x8d", laws.index(law), *(values[k] for k in order)))
    b[start:at] = struct.pack("<Q", count) + b"".join(records)
    return bytes(b)


def _format_10(blob: bytes) -> bytes:
    """A blob of format 15 rewritten as format 12 (_format_12), then as format 10: no wall
    openings (their vector, after the walls', and their size, the layout's last entry, gone).
    No clumps, no controller (whose kinds format 12 added)."""
    import struct

    b = bytearray(_format_12(blob))
    assert int.from_bytes(b[8:12], "little") == 12
    b[8:12] = (10).to_bytes(4, "little")
    n_layout = struct.unpack_from("<Q", b, 12)[0]
    lay = list(struct.unpack_from(f"<{n_layout}Q", b, 20))
    wall, opening = lay[5], lay[20]
    at = _skip_vec(b, 20 + 8 * n_layout, lay[4])  # materials
    at = _skip_to_walls(b, at, lay)
    at = _skip_vec(b, at, wall)
    end = _skip_vec(b, at, opening)  # the openings: cut
    del b[at:end]
    del b[20 + 8 * (n_layout - 1):20 + 8 * n_layout]  # the layout's last size
    b[12:20] = struct.pack("<Q", n_layout - 1)
    return bytes(b)


def test_a_checkpoint_of_format_10_loads_with_its_walls_closed():
    """Format 10 had no wall openings: such a blob loads, every wall closed, and runs on as
    the scene it was."""
    from cpp_dem import _core

    s = cd.Scene(gravity=(0, 0, -9.81))
    m = s.add_material(cd.linear_material(density=2650, young=1e8, poisson=0.3,
                                          friction_angle_deg=30.0))
    s.add_spheres([[0, 0, R1], [3 * R1, 0, R1]], [R1, R1], material=m)
    w = s.add_wall(axis=2, position=0.0, sense=1, material=m)
    s.dt = DT
    s.run(2)
    closed = bytes(_core._checkpoint_save(s))
    s.set_wall_opening(w, axis=0, lo=2 * R1, hi=4 * R1)
    opened = bytes(_core._checkpoint_save(s))
    assert len(opened) == len(closed) and opened != closed  # one record per wall, either way
    for blob in (closed, opened):
        t = cd.Scene(gravity=(0, 0, -9.81))
        t.add_material(cd.linear_material(density=2650, young=1e8, poisson=0.3,
                                          friction_angle_deg=30.0))
        _core._checkpoint_load(t, _format_10(blob))
        assert t.wall_opening(0)[0] == -1 and t.step_count == 2
        t.run(3)
    u = cd.Scene()
    _core._checkpoint_load(u, opened)
    assert u.wall_opening(0) == (0, 2 * R1, 4 * R1)
    v = cd.Scene()  # format 13 (before the cylindrical and mesh walls) loads as it was
    _core._checkpoint_load(v, _format_13(opened))
    assert v.wall_opening(0) == (0, 2 * R1, 4 * R1) and v.num_cylinder_walls == 0
    v.run(3)


def _older_format(blob: bytes, nbodies: int, kinematics_at: int, version: int) -> bytes:
    """A blob of format 10 (two bodies, no clump, no controller) rewritten as format 9 (no
    density scaling: its two inertia-factor arrays and its parameters gone, the body store
    one vector smaller in the layout) or 8 (no shear kinematics either)."""
    import struct

    b = bytearray(blob)
    b[8:12] = version.to_bytes(4, "little")
    n_layout = struct.unpack_from("<Q", b, 12)[0]
    lay = list(struct.unpack_from(f"<{n_layout}Q", b, 20))
    b[20 + 8:20 + 16] = struct.pack("<Q", lay[1] - 24)  # sizeof(BodyStore) without one vector
    size = {"Real": lay[0], "Vec3": lay[2], "Quat": lay[3], "Material": lay[4],
            "PairLaw": lay[-1]}
    at = 20 + 8 * n_layout

    def skip_vec(at, elem):
        n = struct.unpack_from("<Q", b, at)[0]
        return at + 8 + n * elem

    at = skip_vec(at, size["Material"])
    at = skip_vec(at, size["PairLaw"])
    v3, q, r = size["Vec3"], size["Quat"], size["Real"]
    for elem in (v3,) * 7 + (q, r, r, r, 4, 1, 1, 4, 12, r, r, r, v3):
        at = skip_vec(at, elem)
    assert struct.unpack_from("<Q", b, at)[0] == nbodies  # the bodies' inertia factors
    cut = [(at, at + 8 + 8 * nbodies)]
    clumps = at + 8 + 8 * nbodies
    cut.append((clumps + 21 * 8, clumps + 22 * 8))  # the clumps' (empty) inertia factors
    tail = 8 + 8 + 4 + 1 + 8 + 8  # step, time, phys version, dirty, builds, no controller
    cut.append((len(b) - tail - 22, len(b) - tail))  # on, target, safety, period, stale
    if version == 8:
        cut.append((kinematics_at, kinematics_at + 1))
    for lo, hi in sorted(cut, reverse=True):
        del b[lo:hi]
    return bytes(b)


def test_checkpoints_of_the_formats_before_still_load():
    """Format 8 had no shear kinematics and 9 no density scaling: such blobs load, with the
    default kinematics (8) and scaling off (8 and 9). (The blobs are written as format 15 and
    rewritten as 14, 13, 12 and 10, then as 9 and 8.)"""
    from cpp_dem import _core

    blobs = {}
    for kin in ("contact_point", "yade"):
        s = cd.Scene()
        s.shear_kinematics = kin
        m = s.add_material(cd.linear_material(density=2650, young=1e8, poisson=0.3,
                                              friction_angle_deg=30.0))
        s.add_spheres([[0, 0, 0], [R1 + R2 - OVERLAP, 0, 0]], [R1, R2], material=m)
        s.dt = DT
        s.run(2)
        blobs[kin] = bytes(_core._checkpoint_save(s))
    assert int.from_bytes(blobs["yade"][8:12], "little") == 15
    a, b = _format_10(blobs["contact_point"]), _format_10(blobs["yade"])
    assert len(a) == len(b)
    diff = [k for k in range(len(a)) if a[k] != b[k]]
    assert len(diff) == 1 and (a[diff[0]], b[diff[0]]) == (0, 1)  # the one byte of the option
    assert int.from_bytes(b[8:12], "little") == 10
    for version, kinematics in ((9, "yade"), (8, "contact_point")):
        t = cd.Scene()
        t.shear_kinematics = "yade" if version == 8 else "contact_point"
        _core._checkpoint_load(t, _older_format(b, 2, diff[0], version))
        assert t.shear_kinematics == kinematics
        assert t.step_count == 2 and not t.density_scaling
        assert t.inertia_scale(0) == 1.0 and t.inertia_scale(1) == 1.0
        t.run(3)  # it runs on
    with pytest.raises(cd.ParameterError, match="version 7"):
        _core._checkpoint_load(t, b[:8] + (7).to_bytes(4, "little") + b[12:])
