"""Bonds in a periodic cell (issue 38, the reinforced-soil RVE's first part): a bond joins its
sphere to the nearest image of the other, keeps that image while the spheres cross the cell's
faces and are wrapped, takes the mean field's velocity, and counts in the cell stress.

Verified on a ring of bonded spheres closed through the x face: stretched by the cell, its
tension is the parallel bond's k_bar_n A times the extension, and the cell stress is that
tension times the bond length per cell volume (the sheet's stiffness per metre); moved
rigidly through the face, it carries nothing.
"""

import math

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem import BondParams
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint

R = 1e-3          # sphere radius, m
L = 2 * R         # bond length (centre distance), m
N = 8             # spheres (and bonds) in the ring
KBAR = 1e12       # parallel bond's k_bar_n = k_bar_s, Pa/m
A = math.pi * R**2
CELL = np.diag([N * L, 10 * R, 10 * R])   # the ring closes through the x face


def ring(offset=0.3 * L, damping=0.0):
    """N touching spheres along x at y = z = 5 R, shifted by ``offset`` so the ring's closing
    bond (sphere N-1 to sphere 0) crosses the x face; bonded neighbour to neighbour."""
    s = cd.Scene(local_damping=damping, dt=1e-7)
    m = s.add_material(cd.linear_material(density=1000.0, young=1e8, poisson=0.3,
                                          friction_angle_deg=30))
    x = np.zeros((N, 3))
    x[:, 0] = offset + np.arange(N) * L
    x[:, 1:] = 5 * R
    ids = s.add_spheres(x, np.full(N, R), material=m)
    s.set_periodic_cell(CELL)
    p = BondParams(kn=1e5, ks=1e5, friction=0.5, pb_kn=KBAR, pb_ks=KBAR)
    for k in range(N):
        s.add_bond(int(ids[k]), int(ids[(k + 1) % N]), p)
    return s


def test_the_closing_bond_joins_the_nearest_image():
    s = ring()
    s.run(1)
    st = s.bond_state()
    # Every bond is unloaded at its own length: the closing one too, across the face (with
    # its far end at the image, not a cell length away).
    assert np.allclose(st["force"], 0.0, atol=1e-9)
    assert np.allclose(st["reference_gap"], 0.0, atol=1e-12)


def test_a_stretched_ring_is_k_bar_a_times_its_extension():
    s = ring()
    rate = 10.0  # 1/s along x
    s.velocity_gradient = np.diag([rate, 0.0, 0.0])
    s.run(199)
    # (A bond's force is incremental: the last step's force is that of the extension at its
    # start, the cell of one step before.)
    eps = np.asarray(s.cell_matrix)[0, 0] / CELL[0, 0] - 1.0
    s.run(1)
    h = np.asarray(s.cell_matrix)
    assert eps > 1e-5
    st = s.bond_state()
    tension = k_bar_a_extension = KBAR * A * L * eps
    # each bond carries it (pulling b back towards a: -x on b, wherever b lies)
    fx = np.asarray(st["force"])[:, 0]
    assert np.allclose(fx, -tension, rtol=1e-5), (fx, tension)
    assert np.allclose(st["pb_normal_force"], tension, rtol=1e-5)
    # the cell stress: N bonds of tension T and length L(1 + eps) over the volume,
    # compression positive: sigma_xx = -N T L (1 + eps) / V, i.e. the ring's stiffness per
    # area of the cell's y-z face, as a sheet's tension per metre over its spacing.
    sig = np.asarray(s.cell_stress())
    v = float(np.linalg.det(h))
    assert sig[0, 0] == pytest.approx(-N * k_bar_a_extension * L * (1 + eps) / v, rel=1e-5)
    assert abs(sig[1, 1]) < 1e-9 * abs(sig[0, 0]) and abs(sig[0, 1]) < 1e-9 * abs(sig[0, 0])


def test_a_ring_moved_through_the_face_carries_nothing():
    # A rigid drift along x: every sphere crosses the x face several times and is wrapped;
    # the bonds follow their images and stay unloaded.
    s = ring()
    speed = 20.0  # m/s: 2 um a step
    s.velocities = np.tile([speed, 0.0, 0.0], (N, 1))
    steps = int(round(3.2 * CELL[0, 0] / speed / 1e-7))  # 3.2 cell lengths
    s.run(steps)
    img = np.asarray(s.images)
    assert img[:, 0].min() >= 3  # wrapped at least 3 times each
    x = np.asarray(s.positions)
    assert x[:, 0].min() >= 0 and x[:, 0].max() < CELL[0, 0] + 2 * R
    st = s.bond_state()
    assert np.all(st["parallel_bond"])
    # (round-off only: an extension of 1e-9 L would give 6e-6 N; a bond that saw the wrong
    # image would be a cell length long)
    assert np.max(np.abs(st["force"])) < 1e-6


def test_restart_through_a_checkpoint_is_bitwise(tmp_path):
    a = ring(damping=0.2)
    a.velocity_gradient = np.array([[5.0, 2.0, 0.0], [0.0, -3.0, 0.0], [0.0, 0.0, 0.0]])
    v = np.zeros((N, 3))
    v[::2, 1] = 0.05   # a transverse wave: the ring bends and twists
    a.velocities = v
    a.run(300)
    save_checkpoint(tmp_path / "c.h5", a)
    a.run(300)
    b = ring(damping=0.2)
    load_checkpoint(tmp_path / "c.h5", b)
    b.run(300)
    assert np.array_equal(np.asarray(a.positions), np.asarray(b.positions))
    assert np.array_equal(np.asarray(a.bond_state()["force"]),
                          np.asarray(b.bond_state()["force"]))
    assert np.array_equal(np.asarray(a.cell_stress()), np.asarray(b.cell_stress()))
