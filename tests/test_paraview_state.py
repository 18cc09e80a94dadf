"""ParaView state files beside a run's VTK series (cpp_dem.io.paraview_state, issue 64 item 8):
one per run, each file's role read from its arrays, and every file, filter array and colour
array the state names present in the files. ParaView is not installed here: the state runs
against a stand-in ``paraview.simple`` that records the pipeline."""

import os
import shutil
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem.build import woven
from cpp_dem.io import PvdWriter, write_vtk_box, write_vtk_contacts, write_vtk_spheres
from cpp_dem.io import paraview_state as pvs
from cpp_dem.measure.grid_soil import write_vtk_woven


def _scene():
    s = cd.Scene()
    m = s.add_material(cd.linear_material(density=2600, young=1e7, poisson=0.3,
                                          friction_angle_deg=30))
    s.add_spheres(np.array([[0.0, 0.0, 0.01], [0.0, 0.0, 0.0285], [0.02, 0.0, 0.01]]),
                  np.full(3, 0.01), material=m)
    gm = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, -0.02), apertures_x=1, apertures_y=1, material=gm)
    s.dt = 0.5 * s.critical_dt()
    s.run(1)
    return s, g


def _write_run(folder: Path, prefix: str, s, g) -> None:
    pv = {k: PvdWriter(folder / f"{prefix}{k}.pvd", overwrite=True) for k in ("spheres", "box")}
    for step in range(2):
        pv["spheres"].add(float(step), write_vtk_spheres(
            folder / f"{prefix}spheres_{step}.vtp", s).name)
        pv["box"].add(float(step), write_vtk_box(
            folder / f"{prefix}box_{step}.vtp", (-0.05,) * 3, (0.05,) * 3).name)
    write_vtk_contacts(folder / f"{prefix}contacts.vtp", s)
    write_vtk_woven(folder / f"{prefix}geogrid.vtp", s, g)


class _Proxy:
    def __init__(self, kind, **kw):
        self.kind = kind
        self.__dict__.update(kw)

    def __getattr__(self, name):  # (display methods: recorded, no effect)
        if name.startswith("__"):
            raise AttributeError(name)
        return lambda *a, **k: None


def _fake_paraview(calls: list):
    simple = types.ModuleType("paraview.simple")

    def reader(kind):
        def make(registrationName, FileName):
            f = FileName if isinstance(FileName, str) else FileName[0]
            calls.append(("open", f))
            return _Proxy(kind, file=Path(f))
        return make

    simple.PVDReader = reader("pvd")
    simple.XMLPolyDataReader = reader("vtp")
    simple.Threshold = lambda Input: _Proxy("threshold", Input=Input)
    simple.Glyph = lambda Input, GlyphType: _Proxy("glyph", Input=Input)
    simple.GetActiveViewOrCreate = lambda name: _Proxy("view")
    simple.GetActiveCamera = lambda: _Proxy("camera")
    simple.Show = lambda src, view=None: _Proxy("display", source=src)
    simple.Hide = lambda src, view=None: calls.append(("hide", src))
    simple.ColorBy = lambda d, spec: calls.append(("color", d.source, spec))
    simple.Render = lambda: calls.append(("render",))
    simple.__all__ = [k for k in vars(simple) if not k.startswith("_")]
    pkg = types.ModuleType("paraview")
    pkg.simple = simple
    return pkg, simple


def _arrays_of(proxy) -> dict:
    while not hasattr(proxy, "file"):
        proxy = proxy.Input
    f = proxy.file
    if f.suffix == ".pvd":
        f = pvs._pvd_files(f)[0]
    return pvs.vtp_arrays(f)


def _run_state(path: Path, monkeypatch) -> list:
    calls: list = []
    pkg, simple = _fake_paraview(calls)
    monkeypatch.setitem(sys.modules, "paraview", pkg)
    monkeypatch.setitem(sys.modules, "paraview.simple", simple)
    ns = {"__file__": str(path), "__name__": "__state__"}
    exec(compile(path.read_text(), str(path), "exec"), ns)
    return calls, ns


def test_one_state_per_run_whose_files_and_arrays_exist(tmp_path, monkeypatch):
    s, g = _scene()
    _write_run(tmp_path, "a_", s, g)
    _write_run(tmp_path, "b_", s, g)
    written = pvs.write_states(tmp_path)
    assert sorted(p.name for p in written) == ["a_view.py", "b_view.py"]
    roles = {p.name: r for p, r, _ in pvs.series(tmp_path)["a"]}
    assert roles == {"a_spheres.pvd": "grains", "a_box.pvd": "walls",
                     "a_contacts.vtp": "contacts", "a_geogrid.vtp": "woven_grid"}
    calls, ns = _run_state(tmp_path / "a_view.py", monkeypatch)
    opened = sorted(Path(c[1]).name for c in calls if c[0] == "open")
    assert opened == ["a_box.pvd", "a_contacts.vtp", "a_geogrid.vtp", "a_spheres.pvd"]
    assert all(Path(c[1]).exists() for c in calls if c[0] == "open")
    coloured = [(c[1], c[2]) for c in calls if c[0] == "color" and c[2] is not None]
    assert {spec[1] for _, spec in coloured} == {"tension", "normal_force"}
    for src, (where, array) in coloured:
        assert array in _arrays_of(src)["cells" if where == "CELLS" else "points"]
    assert ("render",) in calls
    # The grains' filters read arrays that the spheres file has.
    pts = pvs.vtp_arrays(tmp_path / "a_spheres_0.vtp")["points"]
    assert {"kind", "radius"} <= set(pts)
    # A state moved with its folder opens the files beside it.
    moved = tmp_path / "moved"
    moved.mkdir()
    for f in tmp_path.iterdir():
        if f.is_file():
            (moved / f.name).write_bytes(f.read_bytes())
    calls, _ = _run_state(moved / "a_view.py", monkeypatch)
    assert all(Path(c[1]).parent == moved for c in calls if c[0] == "open")


def test_roles_come_from_the_arrays_and_unknown_files_are_shown_as_they_are(tmp_path):
    s, g = _scene()
    # (named like a box, holding spheres: the arrays decide)
    write_vtk_spheres(tmp_path / "box.vtp", s)
    from cpp_dem.io.vtk import write_vtp

    write_vtp(tmp_path / "mesh.vtp", np.zeros((2, 3)), lines=np.array([[0, 1]]),
              point_data={"u": np.zeros(2)})
    found = pvs.series(tmp_path)
    assert {r for _, r, _ in found[""]} == {"grains"}
    assert [r for _, r, _ in found["mesh"]] == ["other"]
    assert pvs.run_name("detailed_PRS_s1_spheres") == "detailed_PRS_s1"
    assert pvs.run_name("spheres_0003") == ""


def test_a_finished_case_leaves_a_state_beside_its_series(tmp_path):
    from geogrid_dem.rundir import run_main

    s, g = _scene()

    def work(out):
        (out / "vtk").mkdir()
        _write_run(out / "vtk", "", s, g)

    assert run_main("paraview_state_test", tmp_path / "r", work) == 0
    assert (tmp_path / "r" / "vtk" / "view.py").exists()


def test_a_folder_without_vtk_gets_no_state(tmp_path):
    (tmp_path / "x.csv").write_text("a\n1\n")
    assert pvs.write_states(tmp_path) == []
    with pytest.raises(KeyError):
        pvs._ROLE_CODE["nothing"]


@pytest.mark.skipif(shutil.which("pvbatch") is None or shutil.which("xvfb-run") is None,
                    reason="ParaView's pvbatch (and xvfb-run) not installed")
def test_paraview_itself_opens_the_state_and_draws_it(tmp_path):
    """With ParaView installed (``apt-get install paraview xvfb``; not part of the set-up),
    pvbatch runs the state and saves a picture of it."""
    import subprocess

    s, g = _scene()
    _write_run(tmp_path, "a_", s, g)
    (state,) = [p for p in pvs.write_states(tmp_path) if p.name == "a_view.py"]
    shot = tmp_path / "shot.py"
    shot.write_text("import runpy, sys\nrunpy.run_path(sys.argv[1], run_name='__state__')\n"
                    "from paraview.simple import GetActiveView, SaveScreenshot\n"
                    "SaveScreenshot(sys.argv[2], GetActiveView(), ImageResolution=[320, 240])\n")
    png = tmp_path / "a.png"
    # (ParaView's own Python: none of this venv's paths)
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    for _attempt in range(3):  # (a busy machine: Xvfb not yet accepting connections)
        p = subprocess.run(["xvfb-run", "-a", "pvbatch", str(shot), str(state), str(png)],
                           capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
        if "bad X server connection" not in p.stdout + p.stderr:
            break
    (tmp_path / "pv.log").write_text(p.stdout + p.stderr)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    assert png.stat().st_size > 1000
