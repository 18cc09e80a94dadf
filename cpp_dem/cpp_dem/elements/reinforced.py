"""The reinforced-soil RVE's sheet (issue 38, first part; docs/periodic.md "A woven sheet in
a periodic cell"): an endless woven geogrid of bonded spheres in a periodic cell.

The cell is periodic along x, y and z. The sheet (cpp_dem.build.woven, ``periodic=True``) lies
in the plane z = height / 2 and closes through the x and y faces, so it is continuous through
the cell's images: the cell stands for a stack of sheets ``height`` apart. Its x and y edges
are whole numbers of the grid's pitch. A prestress (PRS) is locked in by stretching the cell
along the longitudinal (x) members by T_p / J, J the sheet's series stiffness per metre
(woven.series_stiffness_per_metre).

Not yet: the grains around it. Grown or servoed with the sheet in the cell, the preparation's
controllers stall: their stiffness estimate counts the sheet's stiff bonds, so once the grains
lose contact the growth rate and the cell's strain rate fall to nothing (docs/periodic.md).

SI units; stresses compression positive in the scene.
"""

from __future__ import annotations

import math

import numpy as np

from cpp_dem._core import ParameterError
from cpp_dem.build import woven
from cpp_dem.scene import Scene


def stretch_x(scene, strain: float, steps: int) -> None:
    """Stretches the cell along x by ``strain`` (-) in ``steps`` steps at a constant rate, then
    relaxes the bodies at that size."""
    if strain == 0:
        return
    rate = math.log1p(strain) / (steps * scene.dt)
    scene.velocity_gradient = np.diag([rate, 0.0, 0.0])
    scene.run(steps)
    scene.velocity_gradient = np.zeros((3, 3))
    scene.run(4 * steps)


def sheet_tension_per_metre(scene, height: float) -> tuple[float, float]:
    """The sheet's tension per metre of width along x and along y, N/m (tension positive):
    minus its bonds' Love–Weber stress (the sum over the bonds of force x branch over the cell
    volume) times the cell's ``height`` (m), the spacing of the sheets in the stack."""
    f = np.asarray(scene.bond_state()["force"])
    ab = np.asarray(scene.bond_spheres)
    # the branch a -> b, to b's nearest image (bonds are shorter than half the cell)
    x = np.asarray(scene.positions)
    h = np.asarray(scene.cell_matrix)
    d = x[ab[:, 1]] - x[ab[:, 0]]
    d -= np.round(np.linalg.solve(h, d.T).T) @ h.T
    s = np.einsum("ki,kj->ij", f, d) / float(np.linalg.det(h))
    return -float(s[0, 0]) * height, -float(s[1, 1]) * height


def sheet_cell(*, preset: str = "detailed", apertures=(1, 1), height: float | None = None,
               prestress: float = 0.0, damping: float = 0.7, convention: str = "series",
               grain_material=None, log=None):
    """The RVE's cell with its sheet alone: a periodic Scene of x, y edges ``apertures`` x the
    preset's pitch and z edge ``height`` (m; default the mean of the x and y edges), the woven
    sheet at mid-height (woven_geogrid(periodic=True)), its ``prestress`` (N/m along x) locked
    in by stretching the cell along x by prestress / J. With ``grain_material`` (a Material)
    it is added and 002's grain–grid law set (woven.set_grid_laws). Returns (scene, grid,
    grid material index, grain material index or None, height)."""
    ax, ay = (int(a) for a in apertures)
    if ax < 1 or ay < 1:
        raise ParameterError(f"apertures={apertures!r}: two whole numbers >= 1 (x, y)")
    if not (math.isfinite(prestress) and prestress >= 0):
        raise ParameterError(f"prestress={prestress}: must be >= 0 (N/m)")
    px, py = woven.preset_pitch(preset)
    lx, ly = ax * px, ay * py
    lz = float(height) if height is not None else 0.5 * (lx + ly)
    if not (math.isfinite(lz) and lz > 0):
        raise ParameterError(f"height={height}: must be > 0 (m)")
    s = Scene(local_damping=damping)
    mg = s.add_material(woven.woven_material(preset))
    ms = s.add_material(grain_material) if grain_material is not None else None
    woven.set_grid_laws(s, mg, ms, preset=preset, convention=convention)
    s.set_periodic_cell(np.diag([lx, ly, lz]))
    g = woven.woven_geogrid(s, origin=(0.25 * px, 0.25 * py, 0.5 * lz), apertures_x=ax,
                            apertures_y=ay, material=mg, preset=preset, convention=convention,
                            periodic=True)
    s.dt = 0.5 * s.critical_dt()
    if prestress > 0:
        eps = prestress / woven.series_stiffness_per_metre(preset, convention=convention)
        stretch_x(s, eps, 4000)
        if log:
            log(f"sheet prestressed to {sheet_tension_per_metre(s, lz)[0]:.4g} N/m (target "
                f"{prestress:.4g}): cell stretched by {eps:.3g} along x")
    return s, g, mg, ms, lz


__all__ = ["sheet_cell", "sheet_tension_per_metre", "stretch_x"]
