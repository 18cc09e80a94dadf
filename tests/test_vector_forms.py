"""The pair pass and the reduction exist in two forms with the same arithmetic: 3-vectors in
4-lane registers where the CPU has AVX2, Eigen's Vector3d elsewhere (docs/core.md, "Determinism
and threads"). CI machines have AVX2, so the narrow form is forced with CPP_DEM_NARROW=1 (read
when the module loads, hence subprocesses). Both must give the same physics to round-off, and
each must be bitwise independent of the thread count."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np

SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import cpp_dem as dem
    out, threads = sys.argv[1], int(sys.argv[2])
    dem.set_num_threads(threads)
    rng = np.random.default_rng(11)
    s = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.1)
    lin = s.add_material(dem.linear_material(density=2600, young=1e7, poisson=0.3,
                                             friction_angle_deg=30))
    # A second material with viscous damping: its contacts take the general law.
    vis = s.add_material(dem.linear_material(density=2600, young=1e7, poisson=0.3,
                                             friction_angle_deg=30, damping_normal=0.2))
    # A compressed simple cubic lattice in a box (overlaps 0.5 % of R with every neighbour
    # and wall), shaken by small random velocities: contacts everywhere, no chaos.
    n, r, h = 6, 0.005, 0.00995
    s.add_box((0, 0, 0), (n * h,) * 3, material=lin)
    g = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    s.add_spheres(0.5 * h + h * g, np.full(len(g), r), material=lin)
    for b in range(0, len(g), 5):
        s.set_body_material(b, vis)
    s.velocities = rng.normal(0, 0.01, (len(g), 3))
    s.angular_velocities = rng.normal(0, 1.0, (len(g), 3))
    s.dt = 2e-5
    s.run(500)
    np.savez(out, x=s.positions, v=s.velocities, w=s.angular_velocities, f=s.forces,
             walls=s.wall_forces, contacts=s.num_active_contacts)
""")


def run(tmp_path, narrow: bool, threads: int) -> dict:
    out = tmp_path / f"n{int(narrow)}_t{threads}.npz"
    env = dict(os.environ, CPP_DEM_NARROW="1" if narrow else "0")
    subprocess.run([sys.executable, "-c", SCRIPT, str(out), str(threads)], env=env,
                   check=True, timeout=300)
    return dict(np.load(out))


def test_narrow_and_wide_forms_agree_and_are_thread_independent(tmp_path):
    wide1, wide2 = run(tmp_path, False, 1), run(tmp_path, False, 2)
    narrow1, narrow2 = run(tmp_path, True, 1), run(tmp_path, True, 2)
    for a, b in ((wide1, wide2), (narrow1, narrow2)):
        for key in a:
            assert np.array_equal(a[key], b[key]), key
    assert int(wide1["contacts"]) > 100  # the run exercises contacts
    # The same physics to round-off: the forms round differently, and the differences grow
    # from 1e-16 (first step) by stick-slip and spin (measured after 500 steps: 6e-17 m,
    # 4e-13 m/s, 8e-11 rad/s, 5e-12 N, against 0.06 m, 0.04 m/s, 1 rad/s and 1.4 N at start).
    for key, tol in (("x", 1e-14), ("v", 1e-11), ("w", 1e-9), ("f", 1e-10)):
        assert np.abs(wide1[key] - narrow1[key]).max() < tol, key
    assert int(wide1["contacts"]) == int(narrow1["contacts"])
