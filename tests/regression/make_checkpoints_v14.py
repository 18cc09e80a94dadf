"""Writes checkpoints of the build before the pair contacts' cold part became optional
(format 14) and the state each reaches 300 steps later, for tests/test_pair_cold.py:
``python tests/regression/make_checkpoints_v14.py OUT`` with that build. Its scenes are
tests/test_pair_cold.py's too (``scene``)."""
import sys

import numpy as np

import cpp_dem as dem


def scene(kind: str, extra_damped_material: bool = False, nx: int = 4, nz: int = 5) -> dem.Scene:
    """nx x nx x nz (80) spheres dropped into a box: ``kind`` "linear" (friction), "hertz"
    (Hertz–Mindlin with dashpots and rolling resistance: the composed law) or "hertz_short"
    (without them: the Hertz short kernel); ``extra_damped_material`` adds a damped material
    no body has (it only makes the scene keep the contacts' cold part)."""
    s = dem.Scene(gravity=(0, 0, -9.81))
    if kind == "linear":
        m = s.add_material(dem.linear_material(density=2650, young=5e6, poisson=0.3,
                                               friction_angle_deg=25))
    else:
        parts = {} if kind == "hertz_short" else dict(damping_normal=0.2, damping_shear=0.1,
                                                       rolling_stiffness=0.5,
                                                       rolling_friction=0.1)
        m = s.add_material(dem.hertz_mindlin_material(density=2650, shear_modulus=5e6,
                                                      poisson=0.3, friction_coefficient=0.5,
                                                      **parts))
    if extra_damped_material:
        s.add_material(dem.linear_material(density=2650, young=5e6, poisson=0.3,
                                           friction_angle_deg=25, damping_normal=0.3))
    rng = np.random.default_rng(7)
    g = np.arange(nx) * 0.0105
    pos = np.stack(np.meshgrid(g, g, np.arange(nz) * 0.0105, indexing="ij"), -1).reshape(-1, 3)
    pos = pos + 0.006 + rng.uniform(-5e-4, 5e-4, pos.shape)
    s.add_spheres(pos, np.full(len(pos), 0.005), material=m)
    side = 0.0105 * nx + 0.008  # (0.05 m for 4)
    s.add_box((0, 0, 0), (side, side, 0.0105 * nz + 0.0275), material=m)
    s.dt = 0.5 * s.critical_dt()
    return s


def main(out: str) -> None:
    from cpp_dem import _core

    for kind in ("linear", "hertz"):
        s = scene(kind)
        s.run(3000)
        blob = _core._checkpoint_save(s)
        s.run(300)
        e = s.energies()
        np.savez(f"{out}/pair_cold_{kind}_v14.npz", blob=np.frombuffer(blob, np.uint8),
                 positions=s.positions, velocities=s.velocities, angvel=s.angular_velocities,
                 friction=e["friction"], viscous=e["viscous"], active=s.num_active_contacts)
        print(kind, s.num_active_contacts, e["friction"], e["viscous"], len(blob))


if __name__ == "__main__":
    main(sys.argv[1])
