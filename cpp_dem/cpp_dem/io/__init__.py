"""cpp_dem.io — result files: VTK PolyData for ParaView, a PVD time-series index, and HDF5 / CSV recorders.

Everything is plain NumPy and text/HDF5 writing (no ``vtk`` package needed). SI units
throughout: m, s, kg, N, J, rad.

VTK (XML PolyData, ``.vtp``; open in ParaView, see ``docs/output.md``):

- :func:`write_vtk_spheres` — one point per sphere (centre, m) with point data ``radius`` (m),
  ``velocity`` (m/s), ``angular_velocity`` (rad/s), ``force`` (N), ``orientation`` (quaternion
  w, x, y, z), ``id`` and ``kind`` (:data:`SPHERE_KINDS`: 0 grain sphere, 1 clump member,
  2 geogrid node, 3 bonded sphere; :func:`sphere_kinds`); render with the Glyph filter (sphere glyph, scale by ``radius``,
  scale factor 2 since a glyph of size 1 has diameter 1).
- :func:`write_vtk_contacts` — the contact force network: one line per active sphere–sphere
  contact (between the two centres), cell data ``normal_force`` (N), ``force`` (N, on the
  second sphere), ``normal``, ``overlap`` (m).
- :func:`write_vtk_box` — the six faces of an axis-aligned box (walls), optionally with the
  wall forces (N) as cell data; a ``.pvd`` of them over time is the box as it moves.
- :func:`write_vtk_walls` — the cylindrical and triangle-mesh walls where they are now.
- :class:`PvdWriter` — a ``.pvd`` collection (time → file) rewritten atomically after every
  entry, so a crashed run leaves a valid index of the files written so far.

Recorders (append as the run goes, flush after every record):

- :class:`H5Recorder` — extendable HDF5 datasets of scalar or fixed-shape series under
  ``/series/<name>`` (``units`` attribute on each), snapshots of per-body arrays under
  ``/snapshots/NNNNNN``, run parameters as root attributes.
- :class:`CsvRecorder` — the same series as CSV rows.
- :func:`standard_series` — the usual scene series (time, step, energies, unbalanced force,
  wall forces) with their units; :func:`read_h5_series`, :func:`read_h5_snapshot`,
  :func:`read_csv_series` read the files back.

A write that fails (a full disk, a file-size limit) raises :class:`ResultWriteError` (an
``OSError``) naming the file and closes it; :func:`close_all_writers` flushes and closes the
recorders still open (what an interrupted case run does before it exits).
"""

from . import foreign  # noqa: F401  (Yade, LIGGGHTS, PFC packing files)
from .csvfile import CsvRecorder, read_csv_series
from .hdf5 import H5Recorder, read_h5_series, read_h5_snapshot
from .series import SNAPSHOT_FIELDS, NonFiniteValueError, standard_series
from ._files import ResultWriteError, close_all_writers
from .figures import save_figure
from .foreign import (read_liggghts_box, read_liggghts_data, read_pfc_balls, read_yade_text,
                      write_liggghts_data, write_pfc_balls, write_yade_text)
from .vtk import (SPHERE_KINDS, PvdWriter, sphere_kinds, write_vtk_box, write_vtk_contacts,
                  write_vtk_spheres, write_vtk_walls, write_vtp)

__all__ = [
    "SNAPSHOT_FIELDS",
    "SPHERE_KINDS",
    "NonFiniteValueError",
    "CsvRecorder",
    "H5Recorder",
    "PvdWriter",
    "ResultWriteError",
    "close_all_writers",
    "read_csv_series",
    "read_liggghts_box",
    "read_liggghts_data",
    "read_pfc_balls",
    "read_yade_text",
    "save_figure",
    "write_liggghts_data",
    "write_pfc_balls",
    "write_yade_text",
    "read_h5_series",
    "read_h5_snapshot",
    "sphere_kinds",
    "standard_series",
    "write_vtk_box",
    "write_vtk_contacts",
    "write_vtk_spheres",
    "write_vtk_walls",
    "write_vtp",
]
