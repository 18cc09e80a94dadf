"""The core's memory by field (Scene.memory_by_field; issue 63 item 3): every array counted
once, by its capacity, and together they are what a grain costs the process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

import cpp_dem as dem

ROOT = Path(__file__).resolve().parents[1]


def _lattice(k: int) -> dem.Scene:
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    g = np.arange(k) * 0.01
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    s.add_spheres(pos, np.full(len(pos), 0.0051), material=m)
    s.dt = 1e-7
    s.run(2)
    return s


def test_every_field_is_counted_by_its_capacity():
    s = _lattice(8)
    n, c = s.num_bodies, s.num_active_contacts
    f = s.memory_by_field()
    assert c == 3 * 8 * 8 * 7  # (every sphere touches its six neighbours)
    assert all(isinstance(v, int) and v >= 0 for v in f.values())
    for name, size in (("bodies.pos", 24), ("bodies.ori", 32), ("bodies.radius", 8),
                       ("bodies.force", 24)):
        assert f[name] >= n * size, name
    assert f["contacts.pairs"] >= c * 8
    # (one thread, the short kernel: the pass sums into the bodies' forces and keeps no
    # outputs, no slots for them and no scratch sums; the integration's accelerations are a
    # block's, on the stack)
    for name in ("contacts.pair_out", "contacts.pair_cold", "contacts.pair_jslot",
                 "contacts.pair_jadj_off", "scratch.pair_fi", "scratch.pair_ti"):
        assert f[name] == 0, name
    assert not any(k.startswith("scratch.acc") for k in f)
    assert f["bonds.bonds"] == 0 and f["geogrid.links"] == 0  # (none in this scene)
    assert len({k.split(".")[0] for k in f}) >= 8


def test_the_fields_add_up_to_what_a_grain_costs_the_process():
    """bench/memory_per_grain.py on two lattices: the marginal resident memory per grain is
    the fields' sum to within 10 % (measured: 1 283 against 1 250 B/grain between 2.7e4 and
    2.16e5 grains); a field left uncounted, or counted twice, would show here."""
    import json

    out = subprocess.run([sys.executable, str(ROOT / "bench" / "memory_per_grain.py"),
                          "--k", "16", "32"], capture_output=True, text=True, check=True)
    slope = json.loads(out.stdout.strip().splitlines()[-1])
    assert slope["between"] == [16**3, 32**3]
    rss, core = slope["marginal_rss_bytes_per_grain"], slope["marginal_core_bytes_per_grain"]
    assert abs(rss - core) < 0.1 * core, slope
