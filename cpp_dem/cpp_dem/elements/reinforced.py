"""The reinforced-soil RVE (issue 38; docs/periodic.md "A reinforced-soil RVE"): a periodic
cell holding an endless woven geogrid of bonded spheres and grains around it, as a
``DemElement``.

The cell is periodic along x, y and z. The sheet (cpp_dem.build.woven, ``periodic=True``) lies
in the plane z = height / 2 and closes through the x and y faces, so it is continuous through
the cell's images: the cell stands for a stack of sheets ``height`` apart. Its x and y edges
are whole numbers of the grid's pitch. A prestress (PRS) is locked in by stretching the cell
along the longitudinal (x) members by T_p / J, J the sheet's series stiffness per metre
(woven.series_stiffness_per_metre).

``reinforced_element`` adds the grains: a loose cloud above and below the sheet, grown (the
grains alone, counting their own contacts: RadiusGrowth.grown_only) to the target stress p in
the fixed cell; then (``hold_sheet``) the cell's x and y edges follow the sheet until it
carries T_p along x and nothing along y, while the grains keep their mean stress at p and the
cell servo holds sigma_zz at p. The element's stress is the whole cell's: the homogenised
reinforced layer.

SI units; stresses compression positive in the scene, tension positive from the element.
"""

from __future__ import annotations

import math

import numpy as np

from cpp_dem import fixedorder
from cpp_dem._core import ParameterError
from cpp_dem.build import woven
from cpp_dem.build.packing import loose_cloud
from cpp_dem.elements.periodic import DemElement, default_material
from cpp_dem.protocols import periodic
from cpp_dem.protocols.periodic import bond_stress, cell_height
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


def sheet_tension_per_metre(scene, height: float | None = None) -> tuple[float, float]:
    """The sheet's tension per metre of width along x and along y, N/m (tension positive):
    minus its bonds' Love–Weber stress (``bond_stress``) times the cell's ``height`` (m), the
    spacing of the sheets in the stack (default: the cell's now, its volume over its x–y
    face)."""
    s = bond_stress(scene)
    if height is None:
        height = cell_height(scene)
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


def reinforced_element(n: int = 150, *, stress: float = 50e3, prestress: float = 0.0,
                       preset: str | None = "detailed", apertures=(1, 1),
                       height: float | None = None, radius_mean: float | None = None,
                       radius_spread: float = 0.2, seed: int = 1, material=None,
                       damping: float = 0.7, tol: float = 0.005, unbalanced: float = 1e-4,
                       growth=(0.5, 1e-3), max_steps: int = 200_000, log=None,
                       prep_friction_deg: float | None = None,
                       **element_kw) -> DemElement:
    """A reinforced-soil RVE: a ``DemElement`` whose periodic cell holds the woven sheet of
    ``sheet_cell(preset, apertures, height, prestress)`` and ``n`` grains of ``material``
    (default: the soil element's, periodic.default_material) at the isotropic ``stress``
    (Pa, compression positive), the sheet at ``prestress`` (N/m along x).

    The grains: radii uniform in radius_mean (1 +- radius_spread) (m; seeded), half of them
    as a loose cloud below the sheet and half above it (cpp_dem.build.packing.loose_cloud);
    without ``radius_mean`` they fill a quarter of the cell's volume beside the sheet's
    layer; with it, and no ``height``, the cell is made taller than its default where the
    clouds would fill more than a quarter of it. They grow in the fixed cell to ``stress``
    counting their own contacts only (periodic.grow_grains; ``growth`` is RadiusGrowth's
    (gain, max_strain per call)); then ``hold_sheet`` brings the sheet to ``prestress`` along x and 0 along y, the grains' mean
    stress and the cell's sigma_zz to ``stress``, within ``tol`` and with the unbalanced
    force below ``unbalanced``. At rest the cell's sigma_xx and sigma_yy are the grains'
    (their split is theirs) less the sheet's prestress / height along x.

    ``preset=None``: no sheet, the soil alone: the soil element's cube of ``n`` grains
    (periodic.cube_cloud, ``radius_mean`` default 1 mm) by its stages (periodic.settle_grains)
    with the growth counting the grains' own contacts: bitwise ``DemElement.periodic`` with
    the same arguments. ``prep_friction_deg``: the grains grow at this friction angle
    first (0: dense, as the soil element's ``DemElement.periodic(prep_friction_deg=0)``),
    then at their material's; without it they grow at their material's and are loose
    (80 of the footing's 3 mm grains at 12 kPa: porosity 0.47 beside the sheet, against
    0.36 for the soil element grown frictionless). ``element_kw`` go to ``DemElement``."""
    if int(n) != n or n < 2:
        raise ParameterError(f"n={n}: the number of grains, a whole number >= 2")
    n = int(n)
    if not (math.isfinite(stress) and stress > 0):
        raise ParameterError(f"stress={stress}: must be > 0 (Pa, compression positive)")
    if not (0 < radius_spread < 1):
        raise ParameterError(f"radius_spread={radius_spread}: must be in (0, 1)")
    if radius_mean is not None and not (math.isfinite(radius_mean) and radius_mean > 0):
        raise ParameterError(f"radius_mean={radius_mean}: must be > 0 (m) or None")
    if material is None:
        material = default_material()
    gain, max_strain = growth
    if prep_friction_deg is not None and not (math.isfinite(prep_friction_deg)
                                              and 0 <= prep_friction_deg < 90):
        raise ParameterError(f"prep_friction_deg={prep_friction_deg}: must be in [0, 90) "
                             "(deg) or None")
    stages = dict(tol=tol, unbalanced=unbalanced, max_steps=max_steps, growth_gain=gain,
                  growth_max_strain=max_strain, log=log, prep_friction_deg=prep_friction_deg)
    if preset is None:
        if prestress != 0:
            raise ParameterError(f"prestress={prestress}: there is no sheet (preset=None) to "
                                 "hold it; give a preset ('detailed' or 'standard')")
        centers, radii, edge = periodic.cube_cloud(
            n, 1e-3 if radius_mean is None else radius_mean, radius_spread, seed, 0.25)
        s = periodic.periodic_scene(centers, radii, periodic.cube_cell(edge),
                                    material=material, damping=damping)
        periodic.settle_grains(s, stress=stress, grains=np.arange(n), **stages)
        return DemElement(s, **element_kw)
    if height is None and radius_mean is not None:
        # (the loose clouds of given radii need room: a quarter of it filled, as without
        # radius_mean; random sequential addition jams from about 0.3)
        px, py = woven.preset_pitch(preset)
        room = n * 4.0 / 3.0 * math.pi * radius_mean**3 * (1.0 + radius_spread**2)
        need = room / (0.25 * int(apertures[0]) * px * int(apertures[1]) * py) \
            + 2.0 * woven.PRESETS[preset]["sphere_radius"]
        if need > 0.5 * (int(apertures[0]) * px + int(apertures[1]) * py):
            height = need
    s, _, _, ms, _ = sheet_cell(preset=preset, apertures=apertures, height=height,
                                 prestress=prestress, damping=damping,
                                 grain_material=material, log=log)
    centers, radii = _grains_beside_sheet(s, n, woven.PRESETS[preset]["sphere_radius"], radius_mean,
                                          radius_spread, seed)
    ids = s.add_spheres(centers, radii, material=ms)
    s.set_auto_timestep(0.5, 500)
    periodic.grow_grains(s, stress=stress, grains=ids, grain_material=ms, **stages)
    hold_sheet(s, ids, stress=stress, prestress=prestress,
               stiffness=woven.series_stiffness_per_metre(preset), tol=tol,
               unbalanced=unbalanced, max_steps=max_steps, log=log)
    return DemElement(s, **element_kw)


def hold_sheet(scene, grains, *, stress: float, prestress: float, stiffness: float,
               tol: float = 0.005, unbalanced: float = 1e-4, max_steps: int = 200_000,
               check_every: int = 200, checks: int = 5, gain: float = 0.3, log=None) -> int:
    """The last stage of a reinforced cell: together until all hold,
    - the ``grains`` keep growing (slowly) to their mean normal stress ``stress`` (Pa),
      counting their own contacts (RadiusGrowth.grown_only);
    - the cell servo holds the cell's sigma_zz at ``stress``;
    - the cell's x and y edges follow the sheet: every ``check_every`` steps the rate of each
      is set to take the sheet's tension per metre (``sheet_tension_per_metre``) to
      ``prestress`` along x and 0 along y, a ``gain`` of the miss over the sheet's
      ``stiffness`` per metre (N/m) per check, capped as the servo;
    within ``tol`` x ``stress`` (x the height for the tensions) and with the unbalanced force
    below ``unbalanced``, at ``checks`` checks in a row (a loose packing passes one check in
    passing and creeps on: 0.5 % of its stress in 20 000 steps after one). The grains' own
    split between x and y is left free. The controllers are removed at the end; returns the
    steps run."""
    from cpp_dem import _core

    ids = [int(b) for b in grains]
    growth = _core.RadiusGrowth(walls=[], bodies=ids, target_stress=stress, gain=0.2,
                                max_strain=1e-4, grown_only=True)
    scene.add_controller(growth)
    servo = periodic.cell_controller(scene)
    servo.allow_tension = True
    servo.set_stress(2, 2, stress)
    servo.enabled = True
    start = scene.step_count
    ok, passed = False, 0
    while not ok and scene.step_count - start < max_steps:
        height = cell_height(scene)
        span = check_every * float(scene.dt)
        miss = np.array(sheet_tension_per_metre(scene)) - (prestress, 0.0)
        for a in (0, 1):
            rate = -gain * float(miss[a]) / (stiffness * span)
            servo.set_rate(a, a, float(np.clip(rate, -servo.max_rate, servo.max_rate)))
        scene.run(check_every)
        band = tol * stress
        held = (np.all(np.abs(np.array(sheet_tension_per_metre(scene)) - (prestress, 0.0))
                       <= band * height)
                and abs(growth.measured_stress - stress) <= band
                and abs(float(np.asarray(scene.cell_stress())[2, 2]) - stress) <= band
                and float(scene.unbalanced_force()) < unbalanced)
        passed = passed + 1 if held else 0
        ok = passed >= checks
    tx, ty = sheet_tension_per_metre(scene)
    if log:
        log(f"sheet held: {tx:.4g}, {ty:.4g} N/m (x, y), the grains at "
            f"{growth.measured_stress:.4g} Pa, in {scene.step_count - start} steps")
    if not ok:
        raise RuntimeError(f"reinforced_element: the cell did not settle in {max_steps} steps: "
                           f"the sheet at {tx:.4g}, {ty:.4g} N/m (targets {prestress:.4g}, 0),"
                           f" the grains at {growth.measured_stress:.4g} Pa and sigma_zz at "
                           f"{float(np.asarray(scene.cell_stress())[2, 2]):.4g} Pa (target "
                           f"{stress:.4g}), unbalanced {float(scene.unbalanced_force()):.3g}; "
                           "raise max_steps or loosen tol")
    scene.clear_controllers()
    scene.velocity_gradient = np.zeros((3, 3))
    return scene.step_count - start


def _grains_beside_sheet(scene, n: int, sheet_radius: float, radius_mean, spread: float,
                         seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n radii uniform in radius_mean (1 +- spread) (m, seeded; without radius_mean scaled to
    fill 0.25 of the room beside the sheet) as two loose clouds, below and above the sheet's
    layer (z = height / 2 +- sheet_radius) of the scene's cell (diagonal, m)."""
    lx, ly, lz = np.diag(np.asarray(scene.cell_matrix))
    below, above = 0.5 * lz - sheet_radius, 0.5 * lz + sheet_radius
    rng = np.random.default_rng(seed)
    radii = 1.0 + spread * (2.0 * rng.random(n) - 1.0)
    room = lx * ly * (lz - 2 * sheet_radius)
    if radius_mean is None:
        radii *= math.pow(0.25 * room / float(np.sum(4.0 / 3.0 * np.pi
                                                     * fixedorder.powers(radii, 3))), 1.0 / 3.0)
    else:
        radii *= radius_mean
    seeds = rng.integers(0, 2**31, size=2)
    c1, r1 = loose_cloud(radii[0::2], (0.0, 0.0, 0.0), (lx, ly, below), seed=int(seeds[0]))
    c2, r2 = loose_cloud(radii[1::2], (0.0, 0.0, above), (lx, ly, lz), seed=int(seeds[1]))
    return np.vstack([c1, c2]), np.concatenate([r1, r2])


__all__ = ["bond_stress", "cell_height", "hold_sheet", "reinforced_element", "sheet_cell",
           "sheet_tension_per_metre", "stretch_x"]
