"""``DemElement``: a strain-driven DEM element that keeps its state between calls and returns
the homogenised stress and a tangent stiffness (the DEM half of hierarchical FEM x DEM, as in
Guo & Zhao's coupling of a periodic DEM cell at every Gauss point). docs/periodic.md.

Sign convention: this is the FEM's interface, so strains and stresses are **tension
positive** (continuum mechanics), unlike ``measure`` and ``prep`` (compression positive for
soil): ``DemElement.stress()`` = -``Scene.cell_stress()`` symmetrised. Strain increments are
displacement-gradient increments dE (3 x 3, -): the element's boundary moves every point x by
dE x, so the antisymmetric part of dE is a rotation. Tangents are 6 x 6 in Voigt order
(xx, yy, zz, yz, xz, xy) with engineering shear strains (gamma = 2 eps), Pa. SI units.

Two kinds:

- **periodic** (``DemElement.periodic`` or a periodic Scene): any dE (shear and rotation
  included), mixed stress control of every component, and the tangent both from the contact
  network (``cpp_dem.measure.network_tangent``) and by finite differences of cloned states;
- **walls** (a box of six servo walls, ``DemElement.box``): normal strains and normal stresses
  only (a shear or rotation raises ParameterError), and the finite-difference tangent of the
  normal block.

The element's whole state (contacts and their history included) saves to bytes and restores
bitwise (``to_bytes`` / ``from_bytes``), so an increment can be rolled back and an element can
move to another process.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from cpp_dem import _core
from cpp_dem.measure import inertial
from cpp_dem import fixedorder, measure
from cpp_dem.protocols import periodic
from cpp_dem.protocols import prep
from cpp_dem._core import CellController, ParameterError
from cpp_dem.elements import increments, state_format
from cpp_dem.scene import Scene

#: Voigt order of the tangents: (row, column) of each of the 6 components.
VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
#: The kind of a DemElement's bytes (cpp_dem.elements.state_format).
_KIND = "cpp_dem.DemElement"


def voigt_strain(k: int, h: float) -> np.ndarray:
    """The symmetric strain tensor of Voigt component k (0..5) with engineering value h (-):
    eps_aa = h for a normal component, eps_ab = eps_ba = h/2 for a shear one."""
    a, b = VOIGT[k]
    e = np.zeros((3, 3))
    if a == b:
        e[a, a] = h
    else:
        e[a, b] = e[b, a] = 0.5 * h
    return e


def _as_tensor(de, field: str) -> np.ndarray:
    try:
        e = np.asarray(de, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"{field}={de!r}: must be a 3 x 3 array of numbers (-)") from None
    if e.shape != (3, 3) or not np.all(np.isfinite(e)):
        raise ParameterError(f"{field}: must be a finite 3 x 3 array (-), got shape {e.shape}")
    return e


@dataclass
class IncrementReport:
    """What one call of ``apply_strain`` / ``apply_stress`` did."""

    steps: int                 #: loading steps run
    relax_steps: int           #: relaxation steps run after the loading
    unbalanced_force: float    #: at the end, -
    relaxed: bool              #: the unbalanced force went below the asked tolerance
    cpu_s: float               #: wall-clock seconds of the call


#: Significant digits (of the largest entry) of a periodic element's network tangent
#: (``DemElement.network_tangent``). Its sparse LU's dense supernodes call BLAS, whose kernel
#: (picked by the CPU, or ``OPENBLAS_CORETYPE``) rounds in its own order: two kernels gave
#: tangents 2e-16 apart (relative), and a Newton on those Jacobians took other iterates, so
#: the footing's elements followed another path. On a grid of 6 digits an entry moves with
#: a chance of about 1e-10 an evaluation; a Jacobian 1e-6 off its own value costs Newton
#: nothing (docs/fem.md, "The same bits on every CPU").
TANGENT_DIGITS = 6


class DemElement:
    """A DEM element with memory: driven by strain increments or stress targets, it returns
    the homogenised (Love–Weber) stress and a tangent, and keeps its contacts and their
    history between calls. Build it with :meth:`periodic`, :meth:`box`, or from a prepared
    scene."""

    #: what its bytes hold, for cpp_dem.elements.state_format
    STATE_KIND = _KIND

    def __init__(self, scene: Scene, *, walls=(), gain: float = 0.3,
                 max_rate: float | None = None, dt_safety: float = 0.5,
                 _controller=None) -> None:
        self.scene = scene
        self.walls = tuple(int(w) for w in walls)
        if self.walls:
            if len(self.walls) != 6:
                raise ParameterError(f"walls={walls!r}: the six walls of a box (x-, x+, y-, y+, "
                                     "z-, z+) or none for a periodic element")
            self.kind = "walls"
        elif scene.is_periodic:
            self.kind = "periodic"
        else:
            raise ParameterError("scene: neither periodic nor given walls; a DemElement needs "
                                 "a periodic cell (Scene.set_periodic_cell) or the six walls "
                                 "of a box")
        self.gain = float(gain)
        self.dt_safety = float(dt_safety)
        if _controller is not None:
            self.controller = _controller
        else:
            if scene.num_controllers():
                raise ParameterError("scene: has controllers; a DemElement adds its own (call "
                                     "scene.clear_controllers() after the preparation)")
            if self.kind == "periodic":
                rate = max_rate if max_rate is not None else periodic.default_max_rate(scene)
                self.controller = CellController(gain=gain, max_rate=rate)
                # (a cell with bonds, a reinforced one, holds tensile targets: its sheet)
                self.controller.allow_tension = scene.num_bonds > 0
            else:
                speed = max_rate if max_rate is not None else prep.default_max_speed(scene,
                                                                                     self.walls)
                self.controller = _core.TriaxialController(walls=list(self.walls), gain=gain,
                                                           max_speed=speed)
                for a in range(3):
                    self.controller.set_strain_rate(a, 0.0)
                self.controller.reset_strain(scene)  # strains from the box as it is now
            scene.add_controller(self.controller)
        self.controller.enabled = False
        if self.kind == "periodic":
            scene.velocity_gradient = np.zeros((3, 3))
        self.dt_max: float | None = None  # (set by the first _set_dt: the prepared state's)
        self.band_thickness: float | None = None  # (see set_band_thickness)
        self._set_dt()

    def _set_dt(self) -> None:
        """A fixed dt for the next stage (exact strain increments): ``dt_safety`` times the
        critical step of the state as it is, but never more than the step of the element as
        prepared (``dt_max``, s). A state that has lost its contacts (a loose element sheared
        apart) gives a large estimate from its few contacts; once contacts form again in the
        stage, that step is unstable (it stopped an element with BlowUpError)."""
        self.scene.set_auto_timestep(self.dt_safety, 0)
        if self.dt_max is None:
            self.dt_max = float(self.scene.dt)
        elif self.scene.dt > self.dt_max:
            self.scene.dt = self.dt_max

    # ---- construction ------------------------------------------------------------------
    @classmethod
    def periodic(cls, n: int = 400, *, material=None, stress: float = 100e3,
                 radius_mean: float = 1e-3, radius_spread: float = 0.2, seed: int = 1,
                 porosity: float | None = None, prep_friction_deg: float | None = None,
                 damping: float = 0.7, log=None, tol: float = 0.005,
                 unbalanced: float = 1e-4, growth=(0.5, 1e-3),
                 **kw) -> "DemElement":
        """A periodic cube of ``n`` spheres prepared to the isotropic ``stress`` (Pa,
        compression positive) by ``periodic.prepare_periodic`` (``porosity``: REFD to that
        porosity), ending within ``tol`` of the stress with the unbalanced force below
        ``unbalanced`` (a looser equilibrium relaxes later, at fixed strain: at 1e-2 the
        stress of a 300-sphere cell fell by a third when the servo stopped). ``growth`` is
        RadiusGrowth's (gain, max_strain per call). ``prep_friction_deg``: grow the grains
        at this friction angle first (0: a dense packing, as Yade's and PFC's users do), then
        at the material's; without it the packing grows at the material's friction and is
        loose (it can lose all its contacts under a small isochoric shear:
        docs/coupling_hierarchical.md).
        ``material``: a Material (default: a linear law, E = 100 MPa, k_s/k_n 0.3, 30 deg,
        2650 kg/m^3)."""
        if material is None:
            material = default_material()
        scene = periodic.prepare_periodic(n, material=material, stress=stress,
                                          radius_mean=radius_mean, radius_spread=radius_spread,
                                          seed=seed, porosity=porosity,
                                          prep_friction_deg=prep_friction_deg, damping=damping,
                                          tol=tol, unbalanced=unbalanced,
                                          growth_gain=growth[0],
                                          growth_max_strain=growth[1], log=log)
        return cls(scene, **kw)

    @classmethod
    def box(cls, n: int = 400, *, material=None, stress: float = 100e3,
            radius_mean: float = 1e-3, radius_spread: float = 0.2, seed: int = 1,
            damping: float = 0.7, tol: float = 0.005, unbalanced: float = 1e-4,
            growth=(0.5, 1e-3), **kw) -> "DemElement":
        """A box of six frictionless walls around ``n`` spheres, compacted isotropically to
        ``stress`` (Pa) by radius growth and servo walls, ending within ``tol`` of the stress
        with the unbalanced force below ``unbalanced``. ``growth`` is RadiusGrowth's (gain,
        max_strain per call): the growth in a box feels the stress only at the walls, so fast
        growth overshoots and leaves a denser core than a cell grown alike (docs/periodic.md).
        """
        if material is None:
            material = default_material()
        centers, radii, edge = periodic.cube_cloud(n, radius_mean, radius_spread, seed, 0.25)
        scene = Scene(local_damping=damping)
        m = scene.add_material(material)
        wm = scene.add_material(material.replace(  # (the grains' elastic law, frictionless)
            friction_angle_deg=0.0, damping_normal=0.0, damping_shear=0.0,
            rolling_stiffness=0.0, rolling_friction=0.0))
        walls = scene.add_box((0, 0, 0), (edge, edge, edge), material=wm)
        scene.add_spheres(centers, radii, material=m)
        scene.set_auto_timestep(0.5, 500)
        # (to equilibrium by growth alone, as the cell: a long servo-wall stage after a loose
        # growth compacts the box further, from its walls)
        prep.grow_to_stress(scene, walls, stress, gain=growth[0], max_strain=growth[1],
                            tol=tol, unbalanced=unbalanced)
        r = prep.compact_isotropic(scene, walls, stress, tol=tol, unbalanced=unbalanced)
        if not r.converged:
            raise RuntimeError(f"DemElement.box: the box did not settle at {stress} Pa")
        scene.clear_controllers()
        return cls(scene, walls=walls, **kw)

    # ---- state -----------------------------------------------------------------------------
    def volume(self) -> float:
        """Current volume of the cell or box, m^3."""
        return measure.box_volume(self.scene, self.walls)

    def _raw_stress(self) -> np.ndarray:
        """Love–Weber stress, Pa, compression positive, not symmetrised."""
        if self.kind == "periodic":
            return np.asarray(self.scene.cell_stress())
        return measure.love_weber_stress(self.scene, self.volume())

    def stress(self) -> np.ndarray:
        """The homogenised stress (Love–Weber), Pa, **tension positive**, symmetrised, 3 x 3.
        With a band thickness (:meth:`set_band_thickness`), the band's stress: the grains'
        part as it is, the bonds' part times the cell's height over the band's thickness."""
        s = -self._raw_stress()
        if self.band_thickness is not None:
            s = s - (periodic.cell_height(self.scene) / self.band_thickness - 1.0) * \
                periodic.bond_stress(self.scene)
        return 0.5 * (s + s.T)

    def set_band_thickness(self, thickness: float | None) -> None:
        """The element stands for a band of soil ``thickness`` m thick holding one sheet (a
        continuum's geogrid band; None: the cell itself, the default). A reinforced cell of
        height h holds one sheet per h, so its bonds' stress is the sheet's force per metre
        over h; as a band of thickness t the same force is spread over t. :meth:`stress` then
        gives the grains' part unchanged and the bonds' part times h / t (h the cell's height
        now, ``periodic.cell_height``): the band's force per metre along x is t sigma_xx.
        Everything that reads :meth:`stress` follows (``apply_strain``'s answer,
        ``fd_tangent``); the DEM and its servo are unchanged, so :meth:`apply_stress` is
        refused. Kept by ``to_bytes``. A cell without bonds is refused."""
        if thickness is not None:
            if self.kind != "periodic" or not self.scene.num_bonds:
                raise ParameterError(f"thickness={thickness!r}: a band thickness needs a "
                                     "periodic element with bonds (a reinforced cell, "
                                     "cpp_dem.elements.reinforced); this one has "
                                     f"{self.scene.num_bonds} bonds")
            if not (isinstance(thickness, (int, float)) and math.isfinite(thickness)
                    and thickness > 0):
                raise ParameterError(f"thickness={thickness!r}: must be > 0 (m) or None")
            thickness = float(thickness)
        self.band_thickness = thickness

    def stress_asymmetry(self) -> float:
        """|skew(sigma)| / |sigma| of the Love–Weber sum (-): zero in equilibrium; reported,
        not hidden, since ``stress`` symmetrises."""
        s = self._raw_stress()
        k = 0.5 * (s - s.T)
        n = math.sqrt(fixedorder.sum_squares(s))
        return math.sqrt(fixedorder.sum_squares(k)) / n if n > 0 else 0.0

    def strain(self) -> np.ndarray:
        """Small strain since the element was set up (-, tension positive): for a periodic
        element sym(F) - I of the cell's deformation gradient; for a box the normal strains
        of the box dimensions."""
        if self.kind == "periodic":
            return periodic.small_strain(self.scene)
        l0 = np.asarray(self.controller.reference_lengths)
        return np.diag(measure.box_size(self.scene, self.walls) / l0 - 1.0)

    def contact_count(self) -> int:
        return int(self.scene.num_active_contacts)

    def stress_scatter(self, *, n_boot: int = 64, seed: int = 0) -> np.ndarray:
        """The element's own scatter of its homogenised stress, Pa (3 x 3, symmetric):
        ``measure.stress_scatter``, the bootstrap of its contacts' Love–Weber terms. How far
        the stress of a sample of this size is from the mean of samples like it; the noise
        floor of a coupled loop (docs/coupling_newton.md)."""
        return measure.stress_scatter(self.scene, self.volume(), n_boot=n_boot, seed=seed)

    # ---- driving ---------------------------------------------------------------------------
    def _steps_for(self, de: np.ndarray, steps: int | None, max_strain_per_step: float) -> int:
        if steps is not None:
            if int(steps) < 1:
                raise ParameterError(f"steps={steps}: must be >= 1")
            return int(steps)
        return max(10, int(math.ceil(float(np.abs(de).max()) / max_strain_per_step)))

    def _relax(self, unbalanced: float, max_steps: int, check_every: int = 100) -> tuple[int, float, bool]:
        if self.kind == "periodic":
            self.scene.velocity_gradient = np.zeros((3, 3))
        else:
            for a in range(3):
                self.controller.set_strain_rate(a, 0.0)
        run = 0
        u = float(self.scene.unbalanced_force())
        while run < max_steps and not (u < unbalanced):
            k = min(check_every, max_steps - run)
            self.scene.run(k)
            run += k
            u = float(self.scene.unbalanced_force())
        return run, u, bool(u < unbalanced)

    def apply_strain(self, de, *, steps: int | None = None, max_strain_per_step: float = 2e-6,
                     unbalanced: float = 1e-3, max_relax_steps: int = 20_000,
                     max_increment: float = increments.MAX_STRAIN_INCREMENT) -> np.ndarray:
        """Deforms the element by the displacement-gradient increment ``de`` (3 x 3, -,
        tension positive; shear and rotation included for a periodic element) over ``steps``
        steps (default: at most ``max_strain_per_step`` per step), then relaxes with the
        boundary held until the unbalanced force is below ``unbalanced`` (at most
        ``max_relax_steps``). Returns the stress (Pa, tension positive); ``last_report`` says
        what ran. Bad arguments, and a principal stretch change above ``max_increment`` in
        one call, are refused by name; an increment that opens every contact warns
        (``cpp_dem.elements.increments``)."""
        t0 = time.perf_counter()
        e = _as_tensor(de, "de")
        increments.check_strain_call(e, steps=steps, max_strain_per_step=max_strain_per_step,
                                     unbalanced=unbalanced, max_relax_steps=max_relax_steps,
                                     max_increment=max_increment)
        before = self.contact_count()
        n = self._steps_for(e, steps, max_strain_per_step)
        self._set_dt()
        dt = float(self.scene.dt)
        if self.kind == "periodic":
            # (the strain rate: the symmetric part of L; a rigid rotation strains nothing)
            lg = _rate_for(e, n, dt)
            self._check_rate(float(np.abs(0.5 * (lg + lg.T)).max()))
        else:
            self._check_rate(float(np.abs(e).max()) / (n * dt))
        self.controller.enabled = self.kind == "walls"
        if self.kind == "periodic":
            self.scene.velocity_gradient = lg
            self.scene.run(n)
            self.scene.velocity_gradient = np.zeros((3, 3))
        else:
            if np.abs(e - np.diag(np.diag(e))).max() > 0:
                raise ParameterError("de: a wall-bounded element takes normal strains only "
                                     "(the off-diagonal part is not zero); use a periodic "
                                     "element for shear and rotation")
            l0 = np.asarray(self.controller.reference_lengths)
            size = measure.box_size(self.scene, self.walls)
            for a in range(3):
                # engineering strain (L0 - L)/L0, compression positive, at a constant rate
                self.controller.set_strain_rate(a, -e[a, a] * size[a] / l0[a] / (n * dt))
            self.scene.run(n)
        relax, u, ok = self._relax(unbalanced, max_relax_steps)
        self.last_report = IncrementReport(n, relax, u, ok, time.perf_counter() - t0)
        increments.report_contact_loss(self, e, before)
        return self.stress()

    def _check_rate(self, rate: float) -> None:
        """Warns (cpp_dem.InertialNumberWarning) when a strain increment at ``rate`` (1/s,
        the largest component over the steps) is not quasi-static: I = rate d /
        sqrt(p / rho), d the mean grain diameter, p the grains' mean stress now (in a
        reinforced cell, without its bonds' part), rho the grains' density (their mass over
        their volume). Once per element object (a coupled run
        calls it for every increment and iteration)."""
        if self.__dict__.get("_rate_warned"):
            return
        sc = self.scene
        grains = measure.sphere_mask(sc)
        r = np.asarray(sc.radii)[grains]
        raw = self._raw_stress()
        if self.kind == "periodic" and sc.num_bonds:  # (the grains' own: a sheet's tension
            raw = raw - periodic.bond_stress(sc)   # is not the grains' confinement)
        p = abs(float(np.trace(raw))) / 3.0
        if not (rate > 0 and p > 0 and len(r)):
            return
        rho = float(np.asarray(sc.masses)[grains].sum()
                    / (4.0 / 3.0 * math.pi * np.sum(fixedorder.powers(r, 3))))
        if not (math.isfinite(rho) and rho > 0):
            return  # (members of clumps carry no mass of their own)
        d = float(2.0 * r.mean())
        self.__dict__["_rate_warned"] = inertial.check_quasi_static(
            inertial.inertial_number(rate, d, p, rho),
            f"DemElement ({self.kind}) strain increment (this element's later increments are "
            "not reported)", rate=rate, diameter=d, pressure=p, density=rho, stacklevel=3)

    def apply_stress(self, sigma, *, components=VOIGT, tol: float = 0.005,
                     unbalanced: float = 1e-3, max_steps: int = 200_000) -> np.ndarray:
        """Servo-controls the listed ``components`` ((r, c) pairs; default all six symmetric
        ones; a box: normal ones only) of the stress to ``sigma`` (3 x 3, Pa, tension
        positive) until within ``tol`` (relative to max(|target|, 1 kPa)) and in equilibrium
        (unbalanced force); the other components are held at zero strain rate. Returns the
        stress (Pa, tension positive)."""
        t0 = time.perf_counter()
        s = _as_tensor(sigma, "sigma")
        if self.band_thickness is not None:
            raise ParameterError(f"apply_stress: this element stands for a band of "
                                 f"{self.band_thickness} m (set_band_thickness), whose stress "
                                 "is not the cell's its servo holds; set_band_thickness(None) "
                                 "first")
        self._set_dt()
        comps = [tuple(int(i) for i in c) for c in components]
        if self.kind == "walls":
            if any(a != b for a, b in comps):
                raise ParameterError("components: a wall-bounded element controls normal "
                                     "stresses only")
            for a in range(3):
                if (a, a) in comps:
                    self.controller.set_stress(a, float(-s[a, a]))
                else:
                    self.controller.set_strain_rate(a, 0.0)
            self.controller.enabled = True
            start = self.scene.step_count
            ok = False
            while self.scene.step_count - start < max_steps and not ok:
                self.scene.run(200)
                got = self.stress()
                ok = all(abs(got[a, a] - s[a, a]) <= tol * max(abs(s[a, a]), 1e3)
                         for a, _ in comps) and float(self.scene.unbalanced_force()) < unbalanced
            n = self.scene.step_count - start
        else:
            targets = {c: float(-s[c]) for c in comps}
            self.controller.enabled = True
            res = periodic.drive_cell(self.scene, stress=targets, tol=tol,
                                      unbalanced=unbalanced, max_steps=max_steps,
                                      gain=self.gain)
            ok, n = res.converged, res.steps
            self.controller.enabled = False
            self.scene.velocity_gradient = np.zeros((3, 3))
        if not ok:
            raise RuntimeError(f"apply_stress: the element did not reach the targets in "
                               f"{max_steps} steps (stress now {self.stress().tolist()} Pa)")
        self.last_report = IncrementReport(n, 0, float(self.scene.unbalanced_force()), True,
                                           time.perf_counter() - t0)
        return self.stress()

    # ---- tangents --------------------------------------------------------------------------
    def network_tangent(self, *, sliding: str = "plastic", geometric: bool = True,
                        rotations: bool = True) -> tuple[np.ndarray, dict]:
        """The tangent from the contact network (Kruyt–Rothenburg type stiffness assembly,
        ``cpp_dem.measure.network_tangent.network_tangent``): 6 x 6 Voigt, Pa, tension
        positive, on the grid of :data:`TANGENT_DIGITS` significant digits of its largest
        entry (the same bits on every CPU), and its info dict. Periodic elements only.

        A reinforced cell's bonds (its sheet) are in the network: each bond a spring pair
        along and across its normal, in tension too, that does not slide, with its parallel
        bond's bending and twisting springs. With a band thickness
        (:meth:`set_band_thickness`) the tangent is the band's stress's: the bonds' rows
        count h / t times, and h / t grows with the strain normal to the sheet (d ln h =
        n . dE n, n the normal of the cell's x–y face), which adds h / t times the bonds'
        stress to that column."""
        if self.kind != "periodic":
            raise ParameterError("network_tangent: needs a periodic element (the assembly "
                                 "takes the periodic branch vectors); use fd_tangent")
        from cpp_dem.measure import network_tangent as tangent

        d, info = tangent.network_tangent(**self.network_data(), sliding=sliding,
                                          geometric=geometric, rotations=rotations)
        if self.band_thickness is not None:
            h = np.asarray(self.scene.cell_matrix)
            normal = np.cross(h[:, 0], h[:, 1])
            normal /= fixedorder.norm(normal)
            ratio = periodic.cell_height(self.scene) / self.band_thickness
            d = d + np.einsum("ij,k,m->ijkm", -ratio * periodic.bond_stress(self.scene),
                              normal, normal)
        # (on a grid: the sparse LU's supernodes go through BLAS, whose kernel, picked by the
        # CPU, rounds in its own order, and a last bit of a Newton's Jacobian changes its
        # iterates, and so the elements' path)
        return fixedorder.on_grid(tangent.to_voigt(d), TANGENT_DIGITS), info

    def network_data(self) -> dict:
        """The active pair contacts, and a reinforced cell's bonds after them, as the arrays
        ``tangent.network_tangent`` takes (with ``bonded``, ``k_bend``, ``k_twist`` and
        ``weights``: 1, and h / t for the bonds' rows of a band, :meth:`network_tangent`)."""
        c = self.scene.contacts()
        ids = np.asarray(c["ids"])
        pair = ids[:, 1] >= 0
        r = np.asarray(self.scene.radii)
        i, j = ids[pair, 0], ids[pair, 1]
        ov = np.asarray(c["overlap"])[pair]
        npair = int(pair.sum())
        rows = dict(i=i, j=j, branch=np.asarray(c["branch"])[pair].reshape(-1, 3),
                    normal=np.asarray(c["normal"])[pair].reshape(-1, 3), li=r[i] - 0.5 * ov,
                    lj=r[j] - 0.5 * ov, kn=np.asarray(c["kn"])[pair],
                    ks=np.asarray(c["ks"])[pair], fn=np.asarray(c["normal_force"])[pair],
                    fs=np.asarray(c["shear_force"])[pair].reshape(-1, 3),
                    tan_phi=np.asarray(c["tan_phi"])[pair], bonded=np.zeros(npair, bool),
                    k_bend=np.zeros(npair), k_twist=np.zeros(npair), weights=np.ones(npair))
        if self.scene.num_bonds:
            rows = {k: np.concatenate([v, self._bond_rows()[k]]) for k, v in rows.items()}
        return dict(rows, volume=self.volume(), n_bodies=int(self.scene.num_bodies))

    def _bond_rows(self) -> dict:
        """The bonds as network rows: a -> b's nearest image (``periodic.bond_branches``),
        the contact point in the middle of the gap, the total force on b split into its
        normal part (repulsive positive) and its shear part."""
        st = self.scene.bond_state()
        ab = np.asarray(self.scene.bond_spheres, dtype=int).reshape(-1, 2)
        d = periodic.bond_branches(self.scene)
        r = np.asarray(self.scene.radii)
        gap = np.linalg.norm(d, axis=1) - r[ab[:, 0]] - r[ab[:, 1]]
        n = np.asarray(st["normal"]).reshape(-1, 3)
        f = np.asarray(st["force"]).reshape(-1, 3)
        fn = np.einsum("ci,ci->c", f, n)
        bonded = np.asarray(st["contact_bond"], bool) | np.asarray(st["parallel_bond"], bool)
        return dict(i=ab[:, 0], j=ab[:, 1], branch=d, normal=n, li=r[ab[:, 0]] + 0.5 * gap,
                    lj=r[ab[:, 1]] + 0.5 * gap, kn=np.asarray(st["normal_stiffness"]),
                    ks=np.asarray(st["shear_stiffness"]), fn=fn, fs=f - fn[:, None] * n,
                    tan_phi=np.asarray(st["friction"]), bonded=bonded,
                    k_bend=np.asarray(st["bending_stiffness"]),
                    k_twist=np.asarray(st["twisting_stiffness"]),
                    weights=np.full(len(ab), 1.0 if self.band_thickness is None else
                                    periodic.cell_height(self.scene) / self.band_thickness))

    def fd_tangent(self, *, h: float = 1e-5, components=range(6), central: bool = True,
                   **strain_kw) -> np.ndarray:
        """The tangent by finite differences: for each Voigt component, a clone of the element
        takes the strain +h (and -h if ``central``) with ``apply_strain`` (relaxed), and the
        stress difference over the strain is the column (Pa). A box: the three normal
        components only (the others are NaN). The element itself is not changed."""
        if not (math.isfinite(h) and h > 0):
            raise ParameterError(f"h={h}: must be > 0 (-)")
        out = np.full((6, 6), np.nan)
        blob = self.to_bytes()
        base = None if central else _voigt(self.stress())
        for k in components:
            if self.kind == "walls" and k > 2:
                continue
            plus = _voigt(DemElement.from_bytes(blob).apply_strain(voigt_strain(k, h),
                                                                   **strain_kw))
            if central:
                minus = _voigt(DemElement.from_bytes(blob).apply_strain(voigt_strain(k, -h),
                                                                        **strain_kw))
                out[:, k] = (plus - minus) / (2 * h)
            else:
                out[:, k] = (plus - base) / h
        return out

    # ---- save / restore ----------------------------------------------------------------
    def to_bytes(self) -> bytes:
        """The whole state (scene, contacts with history, controller, element settings) as
        bytes of cpp_dem's element format (``cpp_dem.elements.state_format``: the settings as
        JSON, the scene's checkpoint blob, a SHA-256 checksum; nothing pickled);
        ``from_bytes`` restores it bitwise."""
        ctl = self.controller
        if self.kind == "periodic":
            cfg = {"gain": float(ctl.gain), "max_rate": float(ctl.max_rate),
                   "allow_tension": bool(ctl.allow_tension),
                   "modes": [[str(ctl.mode(r, c)) for c in range(3)] for r in range(3)],
                   "goals": [[float(ctl.goal(r, c)) for c in range(3)] for r in range(3)]}
        else:
            cfg = {"gain": float(ctl.gain), "max_speed": float(ctl.max_speed)}
        fields = {"kind": self.kind, "walls": [int(w) for w in self.walls],
                  "gain": float(self.gain), "dt_safety": float(self.dt_safety),
                  "dt_max": None if self.dt_max is None else float(self.dt_max),
                  "controller": cfg}
        if self.band_thickness is not None:  # (absent otherwise)
            fields["band_thickness"] = float(self.band_thickness)
        return state_format.pack(_KIND, fields,
                                 {"scene": bytes(_core._checkpoint_save(self.scene))})

    @classmethod
    def from_bytes(cls, data: bytes) -> "DemElement":
        """An element restored from ``to_bytes``: running it on gives bitwise what the saved
        element would have given. Bytes of another format (a pickle of an older version
        included), changed after they were written, or holding values the element's setters
        refuse raise a ParameterError naming ``data``; nothing in them is executed."""
        d, parts = state_format.unpack(data, _KIND)
        try:
            kind, cfg = d["kind"], d["controller"]
            if kind not in ("periodic", "walls"):
                raise ValueError(f"kind={kind!r}, allowed 'periodic' or 'walls'")
            walls = tuple(int(w) for w in d["walls"])
            gain, dt_safety = float(d["gain"]), float(d["dt_safety"])
            dt_max = None if d.get("dt_max") is None else float(d["dt_max"])
            band = None if d.get("band_thickness") is None else float(d["band_thickness"])
            blob = parts["scene"]
            scene = Scene()
            if kind == "periodic":
                ctl = CellController(gain=float(cfg["gain"]), max_rate=float(cfg["max_rate"]))
                ctl.allow_tension = bool(cfg["allow_tension"])
                for r in range(3):
                    for c in range(3):
                        mode, goal = cfg["modes"][r][c], float(cfg["goals"][r][c])
                        if mode == "stress":
                            ctl.set_stress(r, c, goal)
                        elif mode == "rate":
                            ctl.set_rate(r, c, goal)
                        else:
                            raise ValueError(f"controller mode {mode!r}, allowed 'stress' or "
                                             "'rate'")
            else:
                ctl = _core.TriaxialController(walls=list(walls), gain=float(cfg["gain"]),
                                               max_speed=float(cfg["max_speed"]))
        except KeyError as e:
            raise ParameterError(f"data: a saved DemElement without its field {e}") from None
        except (TypeError, ValueError, IndexError) as e:
            raise ParameterError(f"data: a saved DemElement with a malformed field: {e}") \
                from None
        scene.add_controller(ctl)
        _core._checkpoint_load(scene, blob)
        el = cls.__new__(cls)
        el.scene, el.walls, el.kind = scene, walls, kind
        el.gain, el.dt_safety, el.controller = gain, dt_safety, ctl
        el.dt_max = dt_max
        el.band_thickness = band
        return el

    def clone(self) -> "DemElement":
        """An independent copy (through ``to_bytes``)."""
        return DemElement.from_bytes(self.to_bytes())


def default_material():
    """The elements' default grains: a linear law, E = 100 MPa, k_s/k_n 0.3, 30 deg,
    2650 kg/m^3."""
    from cpp_dem.scene import linear_material

    return linear_material(density=2650.0, young=100e6, poisson=0.3, friction_angle_deg=30.0)


def _voigt(s: np.ndarray) -> np.ndarray:
    return np.array([s[a, b] for a, b in VOIGT])


def _rate_for(de: np.ndarray, n: int, dt: float) -> np.ndarray:
    """The constant velocity gradient L (1/s) whose n steps of the cell's map (Cayley's form,
    ``PeriodicCell::step_map``) give exactly F = I + de: A = (I + de)^(1/n) and
    L dt = 2 (A - I)(A + I)^-1 (``cpp_dem.fixedorder.cayley_rate``: in a fixed order, so
    the same bits on every CPU and BLAS kernel)."""
    f = np.eye(3) + de
    if not fixedorder.det3(f) > 0:
        raise ParameterError("de: I + de must have a positive determinant (the increment "
                             "would turn the cell inside out)")
    return fixedorder.cayley_rate(f, n) / dt


__all__ = ["DemElement", "IncrementReport", "VOIGT", "voigt_strain"]
