"""ParaView state files beside a run's VTK series: open a run's grains, grid and walls in one go.

:func:`write_states` looks at the ``.pvd`` series and the lone ``.vtp`` files of a folder,
groups them by run (the file's stem without its role word: ``detailed_PRS_s1_spheres.pvd``
and ``detailed_PRS_s1_box.pvd`` are the run ``detailed_PRS_s1``; ``spheres.pvd`` and
``box.pvd`` the folder's only run), and writes one Python state file per run,
``<run>_view.py`` (``view.py`` for the unnamed run). ParaView opens it with *File → Load
State* (a Python state file) or ``paraview --script=<file>``; ``pvpython <file>`` builds the
same pipeline without a window. Each file's role is read from the arrays it holds, not from
its name:

- **grains** (point arrays ``velocity``, ``id``, ``kind``; cpp_dem.io.write_vtk_spheres):
  a Threshold on ``kind`` 0–1 (the grains, not the grid's bodies), sphere glyphs scaled by
  ``radius`` x 2 (a unit glyph has diameter 1), sand-coloured;
- **woven grid** (cell array ``tension``; cpp_dem.measure.grid_soil.write_vtk_woven): its
  bonds as lines coloured by ``tension`` (N), its spheres as grey glyphs;
- **beam / PFacet grid** (cell array ``axial_force``; cpp_dem.build.geogrid): coloured by
  ``axial_force`` (N);
- **walls** (cell array ``wall``; cpp_dem.io.write_vtk_box): a black wireframe;
- **contacts** (cell array ``normal_force``; cpp_dem.io.write_vtk_contacts): lines coloured by
  ``normal_force`` (N), hidden at first (eye icon in the Pipeline Browser);
- anything else: shown as it is.

The state names the files relative to its own folder (so a moved run folder still opens),
with the folder it was written in as the fallback where ParaView gives a state no
``__file__``. Writing is plain text: no ``vtk`` or ParaView is needed to write it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

#: Role words stripped from a file's stem to name its run.
ROLE_WORDS = ("spheres", "box", "walls", "geogrid", "grid", "contacts")


def vtp_arrays(path: Path) -> dict:
    """The point and cell array names of a ``.vtp`` file: {'points': [...], 'cells': [...]}
    (empty lists for a file that cannot be read)."""
    out = {"points": [], "cells": []}
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return out
    for key, tag in (("points", "PointData"), ("cells", "CellData")):
        for node in root.iter(tag):
            out[key] += [a.get("Name") for a in node.findall("DataArray") if a.get("Name")]
    return out


def role(arrays: dict) -> str:
    """The role of a file from its arrays (:func:`vtp_arrays`): grains, woven_grid,
    beam_grid, walls, contacts, or other."""
    pts, cells = set(arrays["points"]), set(arrays["cells"])
    if "normal_force" in cells:
        return "contacts"
    if "wall" in cells:
        return "walls"
    if "tension" in cells:
        return "woven_grid"
    if "axial_force" in cells:
        return "beam_grid"
    if {"velocity", "id", "kind", "radius"} <= pts:
        return "grains"
    return "other"


def _pvd_files(pvd: Path) -> list[Path]:
    try:
        root = ET.parse(pvd).getroot()
    except (ET.ParseError, OSError):
        return []
    return [pvd.parent / d.get("file") for d in root.iter("DataSet") if d.get("file")]


def run_name(stem: str) -> str:
    """A file's run: its stem without its role word ('' when nothing is left)."""
    parts = stem.split("_")
    for w in ROLE_WORDS:
        if w in parts:
            k = parts.index(w)
            parts = parts[:k] + parts[k + 1:]
            break
    while parts and parts[-1].isdigit():  # (a numbered snapshot: spheres_0003)
        parts.pop()
    return "_".join(parts)


def series(folder: Path) -> dict:
    """{run: [(path, role, arrays)]} for the ``.pvd`` series of ``folder`` and its ``.vtp``
    files that no series lists; a series' role and arrays are its first file's."""
    folder = Path(folder)
    listed: set[Path] = set()
    found: dict[str, list] = {}
    for pvd in sorted(folder.glob("*.pvd")):
        files = [f for f in _pvd_files(pvd) if f.exists()]
        listed |= {f.resolve() for f in files}
        if files:
            arr = vtp_arrays(files[-1])
            found.setdefault(run_name(pvd.stem), []).append((pvd, role(arr), arr))
    for vtp in sorted(folder.glob("*.vtp")):
        if vtp.resolve() in listed:
            continue
        arr = vtp_arrays(vtp)
        found.setdefault(run_name(vtp.stem), []).append((vtp, role(arr), arr))
    return found


_HEAD = '''# ParaView state (Python) for the run {run!r}: written by cpp_dem.io.paraview_state.
# Open it in ParaView with File > Load State, or: paraview --script={name}
# Roles are read from the files' arrays (docs/output.md, "A ParaView state").
import os

from paraview.simple import *  # noqa: F401,F403

try:
    HERE = os.path.dirname(os.path.abspath(__file__))
except NameError:  # (ParaView may run a state without __file__)
    HERE = {folder!r}
view = GetActiveViewOrCreate("RenderView")


def _open(name):
    path = os.path.join(HERE, name)
    if name.endswith(".pvd"):
        return PVDReader(registrationName=name, FileName=path)
    return XMLPolyDataReader(registrationName=name, FileName=[path])


def _between(source, array, lo, hi):
    t = Threshold(Input=source)
    t.Scalars = ["POINTS", array]
    try:  # (ParaView 5.10 and later)
        t.LowerThreshold, t.UpperThreshold = lo, hi
    except AttributeError:
        t.ThresholdRange = [lo, hi]
    return t


def _spheres(source, scale_array="radius"):
    g = Glyph(Input=source, GlyphType="Sphere")
    g.ScaleArray = ["POINTS", scale_array]
    g.ScaleFactor = 2.0
    g.GlyphMode = "All Points"
    return g


def _colour(display, where, array, solid=None):
    if solid is not None:
        display.ColorArrayName = ["POINTS", ""]  # (no array: one colour)
        display.AmbientColor = display.DiffuseColor = solid
        return
    ColorBy(display, (where, array))
    display.RescaleTransferFunctionToDataRange(True, False)
    display.SetScalarBarVisibility(view, True)

'''

_ROLE_CODE = {
    "grains": '''
src = _open({name!r})
grains = _between(src, "kind", 0, 1)
d = Show(_spheres(grains), view)
_colour(d, "POINTS", None, solid=[0.85, 0.72, 0.5])
''',
    "woven_grid": '''
src = _open({name!r})
d = Show(src, view)
d.SetRepresentationType("Wireframe")
d.LineWidth = 4.0
_colour(d, "CELLS", "tension")
d = Show(_spheres(src), view)
_colour(d, "POINTS", None, solid=[0.35, 0.35, 0.35])
d.Opacity = 0.4
''',
    "beam_grid": '''
src = _open({name!r})
d = Show(src, view)
d.LineWidth = 4.0
_colour(d, "CELLS", "axial_force")
''',
    "walls": '''
src = _open({name!r})
d = Show(src, view)
d.SetRepresentationType("Wireframe")
_colour(d, "CELLS", None, solid=[0.0, 0.0, 0.0])
''',
    "contacts": '''
src = _open({name!r})
d = Show(src, view)
_colour(d, "CELLS", "normal_force")
Hide(src, view)
''',
    "other": '''
src = _open({name!r})
Show(src, view)
''',
}

_TAIL = '''
view.ResetCamera()
camera = GetActiveCamera()  # (from above and aside: the grid shows between the grains)
camera.Elevation(30)
camera.Azimuth(30)
view.ResetCamera()
Render()
'''


def state_text(folder: Path, run: str, files: list) -> str:
    """The Python state of one run (:func:`series`'s list for it)."""
    name = f"{run}_view.py" if run else "view.py"
    text = _HEAD.format(run=run, name=name, folder=str(Path(folder).resolve()))
    for path, r, _arr in files:
        text += f"\n# {path.name}: {r.replace('_', ' ')}" + _ROLE_CODE[r].format(name=path.name)
    return text + _TAIL


def write_states(folder: Path) -> list[Path]:
    """Writes ``<run>_view.py`` (``view.py`` for an unnamed run) into ``folder`` for every run
    of its VTK files (:func:`series`); returns the paths written (none without VTK files)."""
    folder = Path(folder)
    written = []
    for run, files in series(folder).items():
        path = folder / (f"{run}_view.py" if run else "view.py")
        tmp = path.with_suffix(".py.tmp")
        tmp.write_text(state_text(folder, run, files))
        tmp.replace(path)
        written.append(path)
    return written


__all__ = ["ROLE_WORDS", "vtp_arrays", "role", "run_name", "series", "state_text",
           "write_states"]
