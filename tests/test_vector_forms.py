"""The pair pass and the reduction exist in two forms with the same arithmetic: 3-vectors in
4-lane registers where the CPU has AVX2, Eigen's Vector3d elsewhere (docs/core.md, "Determinism
and threads"). CI machines have AVX2, so the narrow form is forced with CPP_DEM_NARROW=1 (read
when the module loads, hence subprocesses). The core is built without fused multiply-adds
(``-ffp-contract=off``), so both forms, and the hot loops' AVX-512, AVX2 and baseline clones,
do the same IEEE operations in the same order: the same bits on every CPU, and each bitwise
independent of the thread count. (With fused multiply-adds in the AVX clones the forms
differed in the last bits, and a chaotic packing grew that into another sample: a verdict of
002's smoke changed with the CPU.)"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from conftest import load_bench
from cpp_dem.dispatch import cpu_dispatch

SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import cpp_dem as dem
    out, threads, viscous = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
    dem.set_num_threads(threads)
    rng = np.random.default_rng(11)
    s = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.1)
    lin = s.add_material(dem.linear_material(density=2600, young=1e7, poisson=0.3,
                                             friction_angle_deg=30))
    # A second material with viscous damping: its contacts take the general law, and the
    # pass keeps its outputs (without it each thread sums its own bodies, pair_cross_).
    vis = s.add_material(dem.linear_material(density=2600, young=1e7, poisson=0.3,
                                             friction_angle_deg=30, damping_normal=0.2))
    # A compressed simple cubic lattice in a box (overlaps 0.5 % of R with every neighbour
    # and wall), shaken by small random velocities: contacts everywhere, no chaos.
    n, r, h = 6, 0.005, 0.00995
    s.add_box((0, 0, 0), (n * h,) * 3, material=lin)
    g = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    s.add_spheres(0.5 * h + h * g, np.full(len(g), r), material=lin)
    for b in range(0, len(g), 5 if viscous else len(g) + 1):
        s.set_body_material(b, vis)
    s.velocities = rng.normal(0, 0.01, (len(g), 3))
    s.angular_velocities = rng.normal(0, 1.0, (len(g), 3))
    s.dt = 2e-5
    s.run(500)
    np.savez(out, x=s.positions, v=s.velocities, w=s.angular_velocities, f=s.forces,
             walls=s.wall_forces, contacts=s.num_active_contacts)
""")


def run(tmp_path, narrow: bool, threads: int, viscous: bool) -> dict:
    out = tmp_path / f"n{int(narrow)}_t{threads}_v{int(viscous)}.npz"
    env = dict(os.environ, CPP_DEM_NARROW="1" if narrow else "0")
    subprocess.run([sys.executable, "-c", SCRIPT, str(out), str(threads), str(int(viscous))],
                   env=env, check=True, timeout=300)
    return dict(np.load(out))


@pytest.mark.parametrize("viscous", [True, False], ids=["outputs", "direct"])
def test_narrow_and_wide_forms_agree_and_are_thread_independent(tmp_path, viscous):
    wide1, wide2 = run(tmp_path, False, 1, viscous), run(tmp_path, False, 2, viscous)
    narrow1, narrow2 = run(tmp_path, True, 1, viscous), run(tmp_path, True, 2, viscous)
    for a, b in ((wide1, wide2), (narrow1, narrow2)):
        for key in a:
            assert np.array_equal(a[key], b[key]), key
    assert int(wide1["contacts"]) > 100  # the run exercises contacts
    # The same bits: no fused multiply-adds in any clone (before: 6e-17 m, 4e-13 m/s, 8e-11
    # rad/s and 5e-12 N apart after 500 steps).
    for key in wide1:
        assert np.array_equal(wide1[key], narrow1[key]), key


def _hash(ab, scene: str, n: int, steps: int, narrow: bool, tmp: Path) -> str:
    cfg = {"scene": scene, "n": n, "threads": 1, "warmup": 0, "steps": steps, "overlay": "",
           "variant": "narrow" if narrow else "wide", "dump": str(tmp / f"{scene}_{narrow}.npy")}
    return ab.run_block(cfg, env_add={"CPP_DEM_NARROW": "1" if narrow else "0"})["state_sha256"]


@pytest.mark.skipif(cpu_dispatch()["dem_simd"]["ops"] != "wide",
                    reason="this CPU runs the narrow form only (no AVX2 + FMA)")
@pytest.mark.parametrize("scene, n, steps", [
    ("spheres", 400, 400),   # the linear law's short kernel, plane walls
    ("general", 400, 400),   # the composed law: viscous damping, rolling resistance
    ("hertz", 400, 400),     # Hertz-Mindlin
    ("clumps", 200, 400),    # clumps settling under gravity
    ("bonds", 300, 300),     # contact and parallel bonds
    ("geogrid", 3000, 100),   # beams, grain-cylinder and grain-PFacet contacts
])
def test_the_wide_and_the_narrow_form_step_to_the_same_bits(scene, n, steps, tmp_path):
    ab = load_bench("ab_build")
    assert _hash(ab, scene, n, steps, False, tmp_path) == _hash(ab, scene, n, steps, True,
                                                                tmp_path)


# The direct pass below the prefetch's size runs its active linear contacts eight at a time
# (cpp_dem/src/passes/pair_batch.hpp, a second writing of the linear short kernel) and adds
# every share afterwards in the loop's order. These scenes take it through each of its
# branches: contacts forming and opening as a loose cloud falls (they leave the batch for a
# step), Hertz-Mindlin contacts between them in the same rows (their shares kept apart, in
# order), slip (friction 0.2), both shear kinematics, one sphere whose row holds more
# candidates than a block (kBatchRow: it runs alone), two threads (cross pairs), and a
# periodic cell under a velocity gradient (images, the mean field's velocity and spin).
BATCH_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import cpp_dem as dem
    out, threads, kinematics, cell = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    dem.set_num_threads(threads)
    rng = np.random.default_rng(5)
    periodic = cell == "periodic"
    s = dem.Scene(gravity=(0, 0, 0 if periodic else -9.81),
                  local_damping=0.05 if periodic else 0.4)
    s.shear_kinematics = kinematics
    lin = s.add_material(dem.linear_material(density=2600, young=5e6, poisson=0.3,
                                             friction_angle_deg=11.3))
    hm = s.add_material(dem.hertz_mindlin_material(density=2600, shear_modulus=2e6,
                                                   poisson=0.25, friction_coefficient=0.2))
    def lattice(n, h, z0=0.0, jitter=2e-4):
        g = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1).reshape(-1, 3)
        return h * (g + 0.5) + [0, 0, z0] + rng.uniform(-jitter, jitter, (len(g), 3))
    if periodic:
        # a loose lattice that the cell compresses and shears into a packing
        x = lattice((10, 10, 10), 0.0036)
        s.set_periodic_cell(np.diag([0.036, 0.036, 0.036]))
        s.add_spheres(x, rng.uniform(0.0012, 0.0017, len(x)), material=lin)
        s.velocity_gradient = [[-4.0, 2.0, 0], [0, -4.0, 0], [0, 0, -4.0]]
    else:
        side = 0.08
        s.add_box((0, 0, 0), (side, side, 0.08), material=lin)
        # body 0: a large sphere on the floor with 300 small ones touching it, all in its row
        # (Fibonacci points on its surface); five layers of small spheres fall on them
        k = np.arange(300) + 0.5
        polar, azimuth = np.arccos(1 - 2 * k / 300), np.pi * (1 + 5 ** 0.5) * k
        shell = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                          np.cos(polar)], -1)
        centre = np.array([side / 2, side / 2, 0.0125])
        x = np.vstack([centre + (0.01 + 0.001 - 1e-5) * shell,
                       lattice((14, 14, 5), 0.0055, z0=0.042)])
        s.add_spheres(np.vstack([centre, x]),
                      np.r_[0.01, np.full(300, 0.001), rng.uniform(0.0015, 0.0025, len(x) - 300)],
                      material=lin)
    for b in range(1, len(x) + 1, 7):
        s.set_body_material(b, hm)
    s.dt = 1e-5 if periodic else 2e-5
    s.run(1)
    big = int(np.sum(s.contacts()["ids"] == 0))
    batched = 0
    for k in range(50):
        if periodic and k == 34:
            s.velocity_gradient = [[0, 4.0, 0], [0, 0, 0], [0, 0, 0]]  # then shear alone
        s.run(200 if periodic else 300)
        batched = max(batched, s._pair_batched())
    np.savez(out, x=s.positions, v=s.velocities, w=s.angular_velocities, f=s.forces,
             t=s.torques, contacts=s.num_active_contacts,
             walls=np.zeros(0) if periodic else s.wall_forces,
             big=big,
             batched=batched)
""")


@pytest.mark.skipif(not cpu_dispatch()["dem_simd"]["linear_batch"],
                    reason="this CPU runs no batch of linear contacts (it needs AVX-512)")
@pytest.mark.parametrize("kinematics, cell", [("contact_point", "walls"), ("yade", "walls"),
                                              ("contact_point", "periodic")])
def test_the_linear_batch_gives_the_narrow_forms_bits_on_each_branch(tmp_path, kinematics,
                                                                     cell):
    def run(narrow: bool, threads: int) -> dict:
        out = tmp_path / f"b{int(narrow)}_{threads}.npz"
        env = dict(os.environ, CPP_DEM_NARROW="1" if narrow else "0")
        subprocess.run([sys.executable, "-c", BATCH_SCRIPT, str(out), str(threads), kinematics,
                        cell], env=env, check=True, timeout=300)
        return dict(np.load(out))

    narrow, wide1, wide2 = run(True, 1), run(False, 1), run(False, 2)
    assert int(narrow["contacts"]) > 600  # a packing: contacts everywhere
    assert int(narrow["batched"]) == 0    # (the Eigen form has no batch)
    assert int(wide1["batched"]) > 300    # ... the 4-lane form ran one
    if cell == "walls":
        assert int(narrow["big"]) > 128   # the large sphere's row was longer than a block
    for key in narrow:
        if key != "batched":
            assert np.array_equal(wide1[key], narrow[key]), key
            assert np.array_equal(wide2[key], narrow[key]), key


OVERLAP_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import cpp_dem as dem
    out = sys.argv[1]
    dem.set_num_threads(1)
    rng = np.random.default_rng(5)
    s = dem.Scene(local_damping=0.1)
    lin = s.add_material(dem.linear_material(density=2600, young=1e7, poisson=0.3,
                                             friction_angle_deg=30))
    # a compressed lattice of uneven spheres: overlaps of many sizes
    n, h = 7, 0.00995
    s.add_box((0, 0, 0), (n * h,) * 3, material=lin)
    g = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    s.add_spheres(0.5 * h + h * g, rng.uniform(0.00499, 0.00512, len(g)), material=lin)
    s.dt = 2e-5
    s.run(200)
    batched = s._pair_batched()
    c = s.contacts()
    sphere = c["ids"][:, 1] >= 0
    ratio = c["overlap"][sphere] / 0.00499
    # the limit below 3 % of the contacts' overlaps: the next step stops on one of them
    s.max_overlap_ratio = float(np.quantile(ratio, 0.97))
    try:
        s.run(1)
        message = ""
    except dem.BlowUpError as e:
        message = str(e)
    c = s.contacts()
    np.savez(out, message=message, batched=batched, f=s.forces, t=s.torques,
             **{"c_" + k: v for k, v in c.items()})
""")


@pytest.mark.skipif(not cpu_dispatch()["dem_simd"]["linear_batch"],
                    reason="this CPU runs no batch of linear contacts (it needs AVX-512)")
def test_the_batchs_overlap_check_stops_the_step_as_the_per_contact_loop_does(tmp_path):
    """The batch takes the square root, the overlap and the check against max_overlap_ratio
    of its contacts (pair_batch_kernel.inc): a contact beyond the limit stops the step with the
    per-contact loop's error (the first such candidate), keeps its record, and gives no
    force, to the bit of the narrow form, which has no batch."""
    def run(narrow: bool) -> dict:
        out = tmp_path / f"o{int(narrow)}.npz"
        env = dict(os.environ, CPP_DEM_NARROW="1" if narrow else "0")
        subprocess.run([sys.executable, "-c", OVERLAP_SCRIPT, str(out)], env=env, check=True,
                       timeout=300)
        return dict(np.load(out))

    narrow, wide = run(True), run(False)
    assert int(wide["batched"]) > 300 and int(narrow["batched"]) == 0
    assert str(wide["message"]).startswith("blow-up at step 200: bodies ")
    assert "of the smaller radius (max_overlap_ratio=" in str(wide["message"])
    for key in narrow:
        if key != "batched":
            assert np.array_equal(wide[key], narrow[key]), key
