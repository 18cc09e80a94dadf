"""The bad-input audit of issue 20, kept as tests: every input that was accepted silently or
got a poor message now gets a clear error naming the field, the value and what is allowed.

Run as a script for the figures of docs/reliability.md:

    .venv/bin/python tests/test_reliability.py

(each case is tried and classed: clear = an error naming the field and the value; poor = an
error without them; silent = accepted; crash = the interpreter died.)
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.build import geogrid

ROOT = Path(__file__).resolve().parents[1]


def _scene():
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    return s, m


def _beam(radius=1e-3):
    return dem.BeamParams(young=4e9, poisson=0.3, radius=radius)


def _case(script, *args, tmp=None):
    out = ["--out", str(tmp)] if tmp is not None and "--out" not in args else []
    p = subprocess.run([sys.executable, str(ROOT / "cases" / script), "--smoke", *out, *args],
                       capture_output=True, text=True, timeout=300, cwd=ROOT)
    if p.returncode == 0:
        return "accepted"
    raise RuntimeError(p.stderr.strip().splitlines()[-1] if p.stderr.strip() else p.stdout)


def _truncated_checkpoint(tmp):
    s, m = _scene()
    s.add_spheres([[0.05, 0.05, 0.05]], [0.005], material=m)
    path = tmp / "c.h5"
    dem.save_checkpoint(path, s)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 3])
    return dem.load_checkpoint(path, dem.Scene())


def _random_checkpoint(tmp):
    path = tmp / "r.h5"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    return dem.load_checkpoint(path, dem.Scene())


def _binary_csv(tmp):
    path = tmp / "p.csv"
    path.write_bytes(bytes(range(256)))
    return dem.read_packing_csv(path)


def _fem_sizes():
    from femcoupling.fem.geometry import ReinforcedSoilBody

    return ReinforcedSoilBody(width_m=4, height_m=3, footing_half_width_m=0.5, fine_size_m=2,
                              mesh_size_m=0.5)


#: (name, what the audit found before, call(tmp), regex the message must match)
CASES = [
    # ---- accepted silently before ----
    ("wall velocity NaN", "silent",
     lambda t: _scene()[0].set_wall_velocity(0, (math.nan, 0, 0)),
     r"velocity=\(nan, 0, 0\) of wall 0: must be finite"),
    ("sphere outside the walls", "silent",
     lambda t: (lambda s, m: s.add_spheres([[1, 1, 1]], [0.005], material=m))(*_scene()),
     r"centers\[0\]=\[1\.0, 1\.0, 1\.0\]: behind wall"),
    ("square_grid radius above the spacing", "silent",
     lambda t: (lambda s, m: geogrid.square_grid(
         s, origin=(0, 0, 0.05), length=0.1, width=0.1, nodes_x=6, nodes_y=6,
         params=_beam(0.02), material=m, density=1000))(*_scene()),
     r"params\.radius=0\.02: the members would overlap"),
    ("biaxial_geogrid rib wider than the aperture", "silent",
     lambda t: (lambda s, m: geogrid.biaxial_geogrid(
         s, origin=(0, 0, 0.05), apertures_x=1, apertures_y=1, rib_width=1.0,
         aperture_area=6.4e-3, params=_beam(), material=m, density=1000))(*_scene()),
     r"rib_width=1\.0: must be < the aperture's side"),
    ("negative Verlet margin", "silent",
     lambda t: setattr(_scene()[0], "verlet_margin", -1),
     r"verlet_margin=-1: must be >= 0"),
    ("run(2.7)", "silent", lambda t: _scene()[0].run(2.7),
     r"steps=2\.7: must be a whole number"),
    ("triaxial.py --threads -3", "silent", lambda t: _case("triaxial.py", "--threads", "-3", tmp=t),
     r"--threads=-3: must be >= 0"),
    ("ReinforcedSoilBody fine size above the mesh size", "silent", lambda t: _fem_sizes(),
     r"fine_size_m=2: must be <= mesh_size_m=0\.5"),
    # ---- poor messages before ----
    ("hertz_mindlin_material(poisson=-1.5)", "poor",
     lambda t: dem.hertz_mindlin_material(density=2650, shear_modulus=1e6, poisson=-1.5,
                                          friction_coefficient=0.5),
     r"poisson=-1\.5: must be in \(-1, 0\.5\]"),
    ("NaN grid origin", "poor",
     lambda t: (lambda s, m: geogrid.square_grid(
         s, origin=(math.nan, 0, 0), length=0.1, width=0.1, nodes_x=3, nodes_y=3,
         params=_beam(), material=m, density=1000))(*_scene()),
     r"origin=\(nan, 0, 0\): must be 3 finite numbers"),
    ("string centres", "poor",
     lambda t: (lambda s, m: s.add_spheres([["a", "b", "c"]], [0.005], material=m))(*_scene()),
     r"centers=\[\['a', 'b', 'c'\]\]: must be numbers \(m\)"),
    ("material=0.5", "poor",
     lambda t: _scene()[0].add_spheres([[0.05, 0.05, 0.05]], [0.005], material=0.5),
     r"material=0\.5: must be a whole number"),
    ("linear_material(dampng_normal=...)", "poor",
     lambda t: dem.linear_material(density=2650, young=1e7, poisson=0.3, friction_angle_deg=30,
                                   dampng_normal=0.1),
     r"dampng_normal=0\.1: not a parameter .*did you mean damping_normal"),
    ("nodes_x=3.5", "poor",
     lambda t: (lambda s, m: geogrid.square_grid(
         s, origin=(0, 0, 0.05), length=0.1, width=0.1, nodes_x=3.5, nodes_y=3,
         params=_beam(), material=m, density=1000))(*_scene()),
     r"nodes_x=3\.5: must be a whole number >= 2"),
    ("truncated checkpoint", "poor", _truncated_checkpoint,
     r"c\.h5: not a readable checkpoint"),
    ("random bytes as a checkpoint", "poor", _random_checkpoint,
     r"r\.h5: not a readable checkpoint"),
    ("binary packing CSV", "poor", _binary_csv, r"p\.csv: not a text CSV"),
    ("triaxial.py --grain-scale 50", "poor",
     lambda t: _case("triaxial.py", "--grain-scale", "50", tmp=t),
     r"--grain-scale=50: leaves 0 grains"),
    ("--out naming a file", "poor",
     lambda t: ((t / "f").write_text("x"), _case("triaxial.py", "--out", str(t / "f")))[1],
     r"--out=.*/f: exists and is not a directory"),
]


@pytest.mark.parametrize("name, before, call, pattern", CASES, ids=[c[0] for c in CASES])
def test_bad_input_gets_a_clear_error(tmp_path, name, before, call, pattern):
    with pytest.raises(Exception) as ei:
        call(tmp_path)
    assert re.search(pattern, str(ei.value)), f"{name}: {ei.value}"


def test_auto_timestep_with_period_zero_sets_dt_once():
    """Accepted silently before: period 0 never set dt. Now it sets it once, now."""
    s, m = _scene()
    s.add_spheres([[0.05, 0.05, 0.005], [0.05, 0.05, 0.015]], [0.005, 0.005], material=m)
    before = s.dt
    s.set_auto_timestep(safety=0.5, period=0)
    assert s.dt != before and s.dt == pytest.approx(0.5 * s.critical_dt(), rel=1e-12)
    s.dt = 1e-7
    s.run(200)
    assert s.dt == 1e-7  # not updated during the run


def test_a_full_disk_fails_save_checkpoint_clearly_and_leaves_nothing(tmp_path):
    """(ulimit -f) A file-size limit below the checkpoint: a clear OSError naming the file,
    and neither the checkpoint nor its temporary file is left."""
    code = f"""
import resource, sys
sys.path.insert(0, {str(ROOT / 'tests')!r})
import numpy as np, cpp_dem as dem
resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))
s = dem.Scene()
m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                       friction_angle_deg=30))
g = np.stack(np.meshgrid(*[np.arange(14)] * 3, indexing="ij"), -1).reshape(-1, 3)
s.add_spheres(0.01 * g + 0.005, np.full(len(g), 0.004), material=m)
try:
    dem.save_checkpoint({str(tmp_path / 'big.h5')!r}, s)
except OSError as e:
    print("ERROR", e)
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "ERROR" in p.stdout and "big.h5: the checkpoint could not be written" in p.stdout
    assert not list(tmp_path.iterdir()), list(tmp_path.iterdir())


def audit(tmp: Path) -> dict:
    """Tries every case; counts clear / poor / silent / crash (for docs/reliability.md)."""
    counts = {"tried": 0, "clear": 0, "poor": 0, "silent": 0, "crash": 0}
    for k, (name, _before, call, pattern) in enumerate(CASES):
        d = tmp / f"case{k}"
        d.mkdir()
        counts["tried"] += 1
        try:
            call(d)
            counts["silent"] += 1
        except Exception as e:  # noqa: BLE001
            counts["clear" if re.search(pattern, str(e)) else "poor"] += 1
    return counts


if __name__ == "__main__":
    import tempfile

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory() as tmp:
        c = audit(Path(tmp))
    print("| cases tried | clear | poor | silent | crashes |")
    print("|---|---|---|---|---|")
    print(f"| {c['tried']} | {c['clear']} | {c['poor']} | {c['silent']} | {c['crash']} |")
