"""Regression references of the contact laws: one small scene per law (a few bodies, a few
hundred steps), its final state compared with a stored reference (``ref_<law>.json`` beside
this file) at an explicit tolerance. One test file per law calls :func:`check`.

Regenerate on purpose (after a deliberate change of a law's arithmetic, saying why in the
commit)::

    .venv/bin/python tests/regression/driver.py --regenerate            # every law
    .venv/bin/python tests/regression/driver.py --regenerate hertz_mindlin

Tolerance: relative 1e-9 of each quantity's largest magnitude. The same build on the same
machine gives the same bits (tests/test_vector_forms.py and the thread tests check that); the
slack covers builds whose arithmetic differs in the last bits (the x86-64 baseline against the
AVX2/FMA variants of the hot loops), which over these few hundred steps stays below 1e-12
relative, and is far below any change of a law (a changed stiffness, cap or frame rotation
moves these states at 1e-6 or more).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RTOL = 1e-9
STEPS = 400


def _material(kind: str):
    import cpp_dem as dem

    if kind == "hertz_mindlin":
        return dem.hertz_mindlin_material(density=2650.0, shear_modulus=4e6, poisson=0.25,
                                          friction_coefficient=0.5)
    parts = {}
    if kind == "linear_parts":
        parts = dict(damping_normal=0.3, damping_shear=0.2, rolling_stiffness=0.5,
                     rolling_friction=0.1)
    return dem.linear_material(density=2650.0, young=1e7, poisson=0.3, friction_angle_deg=30.0,
                               **parts)


def _grains(scene, mat: int) -> None:
    """Six grains in a 4 cm box, touching with small overlaps: resting on the floor and on
    each other, one against a wall, two sliding and one spinning, so that contacts are
    open, sticking and slipping during the run and still closed at its end."""
    d = 2e-7  # m, overlap of each resting contact (about the static one under gravity)
    c = np.array([[0.010, 0.010, 0.005 - d],                 # on the floor
                  [0.020 - d, 0.010, 0.005 - d],             # beside grain 0
                  [0.015, 0.025, 0.0052 - d],                # spinning on the floor
                  [0.010, 0.010, 0.015 - 2 * d],             # on top of grain 0
                  [0.035 + d, 0.030, 0.005 - d],             # against the wall x = 0.04 m
                  [0.025, 0.032, 0.005 - d]])                # sliding on the floor
    r = np.array([0.005, 0.005, 0.0052, 0.005, 0.005, 0.005])
    scene.add_spheres(c, r, material=mat)
    v = np.zeros((6, 3))
    v[4] = (0.05, 0.0, 0.0)     # m/s, into the wall
    v[5] = (0.02, 0.03, 0.0)    # sliding on the floor
    w = np.zeros((6, 3))
    w[2] = (0.0, 20.0, 5.0)     # rad/s, spinning on the floor
    w[3] = (3.0, 0.0, 0.0)
    scene.velocities = v
    scene.angular_velocities = w


def build(law: str):
    """The scene of `law`: linear, linear_parts, hertz_mindlin, geogrid_contact, beam."""
    import cpp_dem as dem
    from cpp_dem.build import geogrid

    s = dem.Scene(gravity=(0.0, 0.0, -9.81))
    s.spatial_sort = False
    if law in ("linear", "linear_parts", "hertz_mindlin"):
        m = s.add_material(_material(law))
        s.add_box((0, 0, 0), (0.04, 0.04, 0.04), material=m)
        _grains(s, m)
        s.dt = 2e-5
    elif law == "geogrid_contact":
        sand = s.add_material(_material("linear"))
        gm = s.add_material(dem.linear_material(density=1000.0, young=4e9, poisson=0.3,
                                                friction_angle_deg=20.0))
        s.add_box((0, 0, 0), (0.04, 0.04, 0.04), material=sand)
        g = geogrid.square_grid(s, origin=(0.005, 0.005, 0.01), length=0.03, width=0.03,
                                nodes_x=4, nodes_y=4, params=dem.BeamParams(young=4e9, poisson=0.3,
                                                                            radius=1e-3),
                                material=gm, density=1000.0, node_density_scale=100.0)
        # Grains resting on a node, on a cylinder and on a crossing: gravity presses them on.
        z = 0.01 + 0.001 + 0.005 - 1.5e-7  # about the static overlap under the weight
        s.add_spheres([[0.015, 0.015, z], [0.020, 0.025, z], [0.030, 0.010, z]],
                      [0.005, 0.005, 0.005], material=sand)
        # The grid held still (the beam law has its own file): the node forces are the
        # virtual spheres' forces split by the weights (000 eq 19).
        s.block_dofs([int(n) for n in g.nodes], "all")
        s.dt = 2e-5  # s (the third grain wedges into an aperture: four stiff contacts)
    elif law == "beam":
        gm = s.add_material(dem.linear_material(density=1000.0, young=4e9, poisson=0.3,
                                                friction_angle_deg=20.0))
        s.gravity = (0.0, 0.0, 0.0)
        pts = np.array([[0.01 * k, 0.0, 0.0] for k in range(6)])
        line = geogrid.polyline(s, pts, params=dem.BeamParams(young=4e9, poisson=0.3, radius=1e-3),
                                material=gm, density=1000.0)
        s.block_dofs(int(line.nodes[0]), "xyz rx ry rz")
        f = np.zeros((s.num_bodies, 3))
        f[int(line.nodes[-1])] = (0.3, 0.0, -0.02)  # N: tension and bending
        s.external_forces = f
        t = np.zeros((s.num_bodies, 3))
        t[int(line.nodes[-1])] = (2e-5, 0.0, 0.0)  # N m: torsion
        s.external_torques = t
        s.dt = 0.5 * s.critical_dt()
    else:
        raise ValueError(f"law={law!r}: no regression scene")
    return s


def state(law: str) -> dict[str, np.ndarray]:
    s = build(law)
    s.run(STEPS)
    out = {"positions": s.positions, "velocities": s.velocities,
           "angular_velocities": s.angular_velocities, "forces": s.forces,
           "torques": s.torques, "wall_forces": s.wall_forces}
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


def ref_path(law: str) -> Path:
    return HERE / f"ref_{law}.json"


def regenerate(law: str) -> None:
    st = state(law)
    ref_path(law).write_text(json.dumps({"law": law, "steps": STEPS,
                                         **{k: v.tolist() for k, v in st.items()}}, indent=0)
                             + "\n")


def check(law: str) -> None:
    """Asserts the law's scene ends where its reference says, within RTOL."""
    ref = json.loads(ref_path(law).read_text())
    assert ref["steps"] == STEPS
    st = state(law)
    for key, got in st.items():
        want = np.asarray(ref[key], dtype=float)
        if want.size == 0:
            want = want.reshape(got.shape) if got.size == 0 else want
        assert got.shape == want.shape, f"{law}: {key} has shape {got.shape}, ref {want.shape}"
        if want.size == 0:
            continue
        scale = max(float(np.max(np.abs(want))), 1e-300)
        err = float(np.max(np.abs(got - want)))
        assert err <= RTOL * scale, (f"{law}: {key} differs from the reference by {err:.3e} "
                                     f"(tolerance {RTOL:g} x {scale:.3e}); if the law changed on "
                                     "purpose, regenerate (tests/regression/driver.py)")


LAWS = ("linear", "linear_parts", "hertz_mindlin", "geogrid_contact", "beam")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--regenerate", action="store_true", help="rewrite the references")
    ap.add_argument("laws", nargs="*", default=list(LAWS))
    a = ap.parse_args(argv)
    for law in a.laws:
        if law not in LAWS:
            ap.error(f"law={law!r}: must be one of {', '.join(LAWS)}")
        if a.regenerate:
            regenerate(law)
            print(f"wrote {ref_path(law)}")
        else:
            check(law)
            print(f"{law}: matches {ref_path(law).name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
