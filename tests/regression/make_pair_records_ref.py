"""Writes the states that the build before the pair records were split from the candidates
(every candidate pair with a 104-byte record) reached in three scenes where contacts form
and open between broad-phase builds, for tests/test_pair_records.py:
``python tests/regression/make_pair_records_ref.py OUT`` with that build. Its scenes are the
test's too (``scene``)."""
import sys
from pathlib import Path

import numpy as np

import cpp_dem as dem
from cpp_dem import periodic

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_checkpoints_v14 import scene as dropped  # noqa: E402

STEPS = {"drop_linear": 4000, "drop_hertz": 4000, "cell": 4000}


def cell(n: int = 300) -> dem.Scene:
    """n grains (R 0.7-1.0 mm) on a jittered lattice in a periodic cube of 16 mm, compressed
    and sheared by a velocity gradient: contacts form across the cell's faces between
    builds."""
    s = dem.Scene(dt=2e-6)
    m = s.add_material(dem.linear_material(density=2650, young=1e8, poisson=0.3,
                                           friction_angle_deg=30))
    rng = np.random.default_rng(11)
    side = 0.016
    g = (np.arange(7) + 0.5) * side / 7
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)[:n]
    pos = pos + rng.uniform(-1e-4, 1e-4, pos.shape)
    s.add_spheres(pos, rng.uniform(0.7e-3, 1.0e-3, len(pos)), material=m)
    s.set_periodic_cell(periodic.cube_cell(side))
    s.velocity_gradient = np.array([[-45.0, 5.0, 0.0], [0.0, -45.0, 0.0], [0.0, 0.0, -45.0]])
    return s


def scene(kind: str) -> dem.Scene:
    if kind == "drop_linear":
        return dropped("linear")
    if kind == "drop_hertz":
        return dropped("hertz_short")
    return cell()


def state(s: dem.Scene) -> dict:
    c = s.contacts()
    e = s.energies()
    return dict(positions=s.positions, velocities=s.velocities, angvel=s.angular_velocities,
                friction=e["friction"], active=s.num_active_contacts,
                builds=s.collider_stats()["builds"], contact_force=np.asarray(c["force"]))


def main(out: str) -> None:
    for kind, steps in STEPS.items():
        s = scene(kind)
        s.run(steps)
        st = state(s)
        np.savez(f"{out}/pair_records_{kind}.npz", **st)
        print(kind, st["active"], st["builds"], st["friction"])


if __name__ == "__main__":
    main(sys.argv[1])
