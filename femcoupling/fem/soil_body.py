"""The part of :class:`femcoupling.fem.model.FemModel` for the reinforced soil body: the
continuum outer domain solved in dolfinx (plane strain or 3D).

``FemModel(ReinforcedSoilBody(...), soil=...)`` holds the mesh of a :class:`~femcoupling.fem.geometry.ReinforcedSoilBody`,
P2 (default) displacements, and a stress history at the quadrature points (a quadrature
space; the return mapping is the NumPy kernel
:func:`femcoupling.materials.continuum.drucker_prager_return`). Loading is incremental with a full
Newton iteration on the consistent tangent at each step (LU: PETSc's own,
``femcoupling.fem.quadrature.SERIAL_LU`` on one rank and ``PARALLEL_LU`` on more).

Stages (each one a sequence of equilibrium steps):

1. :meth:`femcoupling.fem.model.FemModel.set_geostatic` -- a K0 initial state from the self-weight:
   sigma_zz = -gamma (H - z), sigma_xx = sigma_yy = K0 sigma_zz (tension positive), in
   equilibrium with the body force (no displacement results).
2. :meth:`femcoupling.fem.model.FemModel.apply_prestress` -- prestressed geogrid layers (PRS, 002): the initial
   tensile stress T_p / t along x is added in the layers' bands, and the body is brought to
   equilibrium (the band shortens and compresses the soil around it).
3. :meth:`femcoupling.fem.model.FemModel.load_footing` -- a footing pressure (load control) or a footing
   settlement (displacement control, smooth footing) in steps.

Boundary conditions: bottom fixed; x = 0 (symmetry) and x = width rollers (u_x = 0);
3D: y = 0 and y = length rollers (u_y = 0); the top is free apart from the footing.

Extraction: :meth:`femcoupling.fem.model.FemModel.region_stress` (volume average over a tagged region) and
:meth:`femcoupling.fem.model.FemModel.point_stress` (from a local L2 projection onto DG1) return NumPy 3x3
tensors ordered (x, y, z), **tension positive** (in 2D y is the out-of-plane direction).
Every method is collective under MPI and returns the same values on every rank.

The class is split by role: this module (:class:`SoilPart`) holds the mesh, the spaces, the
material arrays, Newton and the state; :mod:`femcoupling.fem.soil_loading` the load stages,
:mod:`femcoupling.fem.soil_regions` the regions with a material or DEM element of their own,
:mod:`femcoupling.fem.soil_measures` what the model gives out (settlement, stresses, forces,
XDMF). A step's record is :class:`femcoupling.fem.steps.LoadStep`, its failure
:class:`~femcoupling.fem.steps.NewtonFailure`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from cpp_dem.fixedorder import dot, eigvalsh3_batch, sum_squares

from femcoupling import _dolfinx
from femcoupling._checks import (FemInputError, _choice, _max_cuts, _max_newton,
                                 _newton_rtol)
from femcoupling.fem import geometry as geo
from femcoupling.fem.quadrature import (NewtonRules, QuadratureSystem, check_material, lu_package,
                                        newton_solve)
from femcoupling.fem.soil_regions import RegionPoints
from femcoupling.fem.solver import SOIL_ONLY, body_kind
from femcoupling.fem.steps import LoadStep, NewtonFailure
from femcoupling.materials.continuum import GeogridLayerMaterial, LinearElastic, mandel_to_tensor

__all__ = ["SoilPart"]

SQRT2 = math.sqrt(2.0)


@body_kind("soil", SOIL_ONLY)
class SoilPart:
    """The part of ``FemModel`` for a reinforced soil body in dolfinx; see the module doc
    (its arguments: ``FemModel``'s). Collective on ``comm``."""

    def _build_soil(self, body: geo.ReinforcedSoilBody, *, soil: LinearElastic,
                    layers: Sequence[GeogridLayerMaterial] = (),
                    region_materials: Mapping[str, LinearElastic] | None = None,
                    unit_weight_n_m3: float = 0.0, degree: int = 2, newton_rtol: float = 1e-8,
                    max_newton: int = 25, max_cuts: int = 6, comm: Any = None) -> None:
        """The model of the reinforced soil ``body`` (``FemModel``'s arguments: the body
        (tags in :mod:`femcoupling.fem.geometry`), ``soil``, ``layers``, ``region_materials``,
        ``unit_weight_n_m3``, ``degree``, ``newton_rtol`` (|R| <= newton_rtol |F_int| over
        the free dofs), ``max_newton``, ``max_cuts``, ``comm`` (default COMM_WORLD))."""
        if not isinstance(soil, LinearElastic):
            raise FemInputError(f"soil={soil!r}: must be a LinearElastic or DruckerPrager")
        layers = tuple(layers)
        if len(layers) != len(body.layers):
            raise FemInputError(f"layers: {len(layers)} materials given for "
                                f"{len(body.layers)} geogrid layers")
        for i, lm in enumerate(layers):
            if not isinstance(lm, GeogridLayerMaterial):
                raise FemInputError(f"layers[{i}]={lm!r}: must be a GeogridLayerMaterial")
        region_materials = dict(region_materials or {})
        for name, mat in region_materials.items():
            body.region_tag(name)
            if not isinstance(mat, LinearElastic):
                raise FemInputError(f"region_materials[{name!r}]={mat!r}: must be a material")
        gamma = geo._real("unit_weight_n_m3", unit_weight_n_m3)
        if gamma < 0:
            raise FemInputError(f"unit_weight_n_m3={gamma!r}: must be >= 0")
        _choice("degree", degree, (1, 2), "1 or 2")
        _newton_rtol(newton_rtol)
        _max_newton(max_newton)
        _max_cuts(max_cuts)

        fx = self._fx = _dolfinx.load()
        fem, ufl = fx.fem, fx.ufl
        self.body, self.soil, self.layers = body, soil, layers
        self.region_materials = region_materials
        #: DEM elements as materials, by region (``set_region_element``) or by region cell
        #: (``set_cell_elements``: "<region>/<cell>")
        self.region_elements: dict = {}
        self._element_points: dict = {}
        #: with region elements, where Newton stalls (femcoupling.fem.quadrature.newton_solve): a
        #: step within ``noise_factor`` times the elements' measured noise and within
        #: ``noise_ceiling`` of the DEM regions' own internal force (not the body's: a 0.1 m
        #: region in a 4 x 3 m body carries a small share of it) is stopped_at_scatter. 1e-2:
        #: the equilibrium the region elements are relaxed to (their unbalanced-force ratio,
        #: 1e-2 in the region elements of this package)
        self._solver_options(newton_rtol=newton_rtol, max_newton=max_newton,
                             noise_factor=2.0, noise_ceiling=1e-2)
        self.last_failure = ""  #: why the last failed Newton failed
        self._step_end: dict = {}
        self._region_form = None  # the DEM regions' internal force (built on demand)
        self.unit_weight_n_m3, self.degree = gamma, degree
        self.max_cuts = max_cuts
        self.comm = comm if comm is not None else fx.MPI.COMM_WORLD

        mb = geo.build_mesh(body, comm=self.comm)
        self.mesh, self.cell_tags, self.facet_tags = mb.mesh, mb.cell_tags, mb.facet_tags
        msh = self.mesh
        tdim = self.tdim = msh.topology.dim
        self.ncomp = 4 if tdim == 2 else 6
        self.zc = tdim - 1  # index of the vertical coordinate
        msh.topology.create_connectivity(tdim - 1, tdim)
        cmap = msh.topology.index_map(tdim)
        self.n_owned = cmap.size_local
        self.n_cells = cmap.size_local + cmap.num_ghosts

        # --- spaces, forms and solver (femcoupling.fem.quadrature.QuadratureSystem) ---
        qdeg = max(1, 2 * (degree - 1))
        self.qdeg = qdeg
        st = fx.PETSc.ScalarType
        self.traction = fem.Constant(msh, np.zeros(tdim, dtype=st))
        grav = np.zeros(tdim, dtype=st)
        grav[self.zc] = -gamma
        self.body_force = fem.Constant(msh, grav)
        ds = ufl.Measure("ds", domain=msh, subdomain_data=self.facet_tags)
        dx = ufl.Measure("dx", domain=msh)
        self._eps = self._mandel_strain
        sysq = self.system = QuadratureSystem(
            msh, degree=degree, qdeg=qdeg, ncomp=self.ncomp, strain=self._eps,
            lu=lu_package(self.comm),
            loads=lambda v: (ufl.dot(self.body_force, v) * dx,
                             ufl.dot(self.traction, v) * ds(geo.FOOTING)))
        self.V, self.Wv, self.Wt, self.dxq = sysq.V, sysq.Wv, sysq.Wt, sysq.dxq
        self.qpoints, self.qweights = sysq.qpoints, sysq.qweights
        self.nq = len(self.qweights)
        self._qdofs = self.Wv.dofmap.list.reshape(-1)  # (cell, q) -> quadrature dof (block)
        self._qdofs_t = self.Wt.dofmap.list.reshape(-1)
        self.u, self.u_n, self.du = sysq.u, sysq.u_n, sysq.du
        self.u.name = "displacement"
        self.sig_q, self.tan_q = sysq.sig_q, sysq.tan_q  # stress and tangent at the points
        n_qp = self.n_cells * self.nq
        self.sig_cur = np.zeros((n_qp, self.ncomp))  # the last trial's stress, (cell, q)
        self.dlam = np.zeros(n_qp)

        # --- the materials at the quadrature points (femcoupling.fem.quadrature) ---
        self.cell_tag_of = np.full(self.n_cells, geo.SOIL_TAG, dtype=np.int32)
        self.cell_tag_of[self.cell_tags.indices] = self.cell_tags.values
        self._point_sets: list = []
        self._set_point_materials(np.zeros((n_qp, self.ncomp)))

        # --- forms ---
        v = ufl.TestFunction(self.V)
        f_body = ufl.dot(self.body_force, v) * dx
        self.form_res, self.form_jac = sysq.form_res, sysq.form_jac
        self.form_react = fem.form(sysq.f_int - f_body)
        self.expr_eps = fem.Expression(self._eps(self.u), self.qpoints)
        one = fem.Constant(msh, st(1.0))
        self.footing_area = self.comm.allreduce(
            fem.assemble_scalar(fem.form(one * ds(geo.FOOTING))), op=fx.MPI.SUM)
        self.form_settle = fem.form(-self.u[self.zc] * ds(geo.FOOTING))
        dg0 = fem.functionspace(msh, ("DG", 0))
        self.cell_volume = fem.assemble_vector(
            fem.form(ufl.TestFunction(dg0) * dx)).array[: self.n_cells].copy()

        # --- boundary conditions ---
        fdim = tdim - 1
        ft = self.facet_tags
        zero = st(0.0)
        self.bcs = []
        bottom = ft.find(geo.BOTTOM)
        for c in range(tdim):
            dofs = fem.locate_dofs_topological(self.V.sub(c), fdim, bottom)
            self.bcs.append(fem.dirichletbc(zero, dofs, self.V.sub(c)))
        rollers = [(geo.X_MIN, 0), (geo.X_MAX, 0)]
        if tdim == 3:
            rollers += [(geo.Y_MIN, 1), (geo.Y_MAX, 1)]
        for tag, c in rollers:
            dofs = fem.locate_dofs_topological(self.V.sub(c), fdim, ft.find(tag))
            self.bcs.append(fem.dirichletbc(zero, dofs, self.V.sub(c)))
        self.footing_dofs = fem.locate_dofs_topological(self.V.sub(self.zc), fdim,
                                                        ft.find(geo.FOOTING))
        self.footing_u = fem.Constant(msh, zero)
        self.footing_bc = fem.dirichletbc(self.footing_u, self.footing_dofs, self.V.sub(self.zc))
        self._displacement_control = False

        self.A, self.b, self.ksp = sysq.A, sysq.b, sysq.ksp
        self._update_tangent_and_stress(np.zeros((n_qp, self.ncomp)))

    # ---- helpers -------------------------------------------------------------------------

    def _mandel_strain(self, w: Any) -> Any:
        ufl = self._fx.ufl
        e = ufl.sym(ufl.grad(w))
        if self.tdim == 2:
            return ufl.as_vector([e[0, 0], e[1, 1], 0.0, SQRT2 * e[0, 1]])
        return ufl.as_vector([e[0, 0], e[1, 1], e[2, 2], SQRT2 * e[1, 2], SQRT2 * e[0, 2],
                              SQRT2 * e[0, 1]])

    def material_of_tag(self, tag: int) -> LinearElastic:
        """The material of the cells with tag ``tag``."""
        if tag == geo.SOIL_TAG:
            return self.soil
        if geo.LAYER_TAG0 <= tag < geo.REGION_TAG0:
            i = tag - geo.LAYER_TAG0
            return self.layers[i].band(self.body.layers[i].thickness_m)
        name = self.body.regions[tag - geo.REGION_TAG0].name
        return self.region_materials.get(name, self.soil)

    def _set_point_materials(self, stress_pa: np.ndarray | None = None) -> None:
        """The quadrature points' materials (``femcoupling.fem.quadrature.QuadratureMaterial``):
        the points of each cell tag without a region element take their tag's material
        (``material_of_tag(tag).at_points``); the points of a region element, its
        :class:`~femcoupling.fem.soil_regions.RegionPoints`. The committed stress carries over
        (``stress_pa`` where given)."""
        sig = self.sig_n if stress_pa is None else stress_pa
        taken = self._region_points()
        sets = []
        for tag in np.unique(self.cell_tag_of):
            sel = np.repeat(self.cell_tag_of == tag, self.nq) & ~taken
            idx = np.flatnonzero(sel)
            if idx.size:
                sets.append((idx, check_material(
                    self.material_of_tag(int(tag)).at_points(sig[idx]),
                    f"the material of cell tag {int(tag)}", "mandel")))
        for key, (sel, w) in self._element_points.items():
            idx = np.flatnonzero(sel)
            sets.append((idx, RegionPoints(self.region_elements[key], w, sig[idx],
                                           self.ncomp, key)))
        self._point_sets = sets

    @property
    def sig_n(self) -> np.ndarray:
        """The committed stress at every quadrature point, (cell, q) order, Mandel, Pa (a
        copy: set it whole)."""
        out = np.zeros((self.n_cells * self.nq, self.ncomp))
        for idx, m in self._point_sets:
            out[idx] = m.stress_n
        return out

    @sig_n.setter
    def sig_n(self, value: np.ndarray) -> None:
        value = np.asarray(value, float)
        for idx, m in self._point_sets:
            m.set_state(value[idx])

    def _to_q(self, func: Any, values: np.ndarray, dofs: np.ndarray, size: int) -> None:
        func.x.array.reshape(-1, size)[dofs] = values.reshape(-1, size)
        func.x.scatter_forward()

    def _update_tangent_and_stress(self, deps: np.ndarray) -> None:
        """Every point set's trial for the strain increments ``deps`` (n_qp, ncomp); the
        members of one DEM pool (``trial_many``) at once."""
        n = len(deps)
        sig = np.empty((n, self.ncomp))
        tan = np.empty((n, self.ncomp, self.ncomp))
        dl = np.zeros(n)
        region = []
        for idx, m in self._point_sets:
            if isinstance(m, RegionPoints):
                region.append((idx, m))
                continue
            sig[idx], tan[idx] = m.trial(deps[idx])
            dl[idx] = m.plastic
        if region:
            RegionPoints.trial_all(region, deps, sig, tan, self.comm)
        self.sig_cur, self.dlam = sig, dl
        self._to_q(self.sig_q, sig, self._qdofs, self.ncomp)
        self._to_q(self.tan_q, tan.reshape(len(tan), -1), self._qdofs_t, self.ncomp**2)

    def _strain_increment(self) -> np.ndarray:
        cells = np.arange(self.n_cells, dtype=np.int32)
        eps = self.expr_eps.eval(self.mesh, cells).reshape(-1, self.ncomp)
        self.u_n.x.scatter_forward()
        # increment = eps(u) - eps(u_n): evaluate eps(u_n) by swapping arrays (no 2nd Expression)
        saved = self.u.x.array.copy()
        self.u.x.array[:] = self.u_n.x.array
        eps_n = self.expr_eps.eval(self.mesh, cells).reshape(-1, self.ncomp)
        self.u.x.array[:] = saved
        return eps - eps_n

    def _active_bcs(self) -> list:
        return self.bcs + ([self.footing_bc] if self._displacement_control else [])

    def _assemble_residual(self) -> float:
        """|R| of the current iterate, Dirichlet rows lifted (``QuadratureSystem.residual``)."""
        return self.system.residual(self._active_bcs())

    def _internal_scale(self) -> float:
        """|F_int| over all dofs (the Newton tolerance's scale), >= tiny."""
        fx = self._fx
        vec = fx.fem.assemble_vector(self.form_react)
        vec.scatter_reverse(fx.dolfinx.la.InsertMode.add)
        own = vec.array[: self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs]
        return self.system.norm(own) + 1e-300

    def _region_points(self) -> np.ndarray:
        """(n_qp,) the quadrature points that take their stress from a region element."""
        on = np.zeros(self.n_cells * self.nq, bool)
        for sel, _ in self._element_points.values():
            on |= sel
        return on

    def _region_scale(self) -> float:
        """|F_int| of the DEM region elements' cells alone (the stall's scale): the internal
        force vector of their stress, assembled over those cells only, >= tiny."""
        fx = self._fx
        fem, ufl = fx.fem, fx.ufl
        if self._region_form is None:
            chi = fem.Function(fem.functionspace(self.mesh, ("DG", 0)))
            cells = self._region_points().reshape(self.n_cells, self.nq).any(axis=1)
            chi.x.array[:] = cells[: chi.x.array.size].astype(float)
            v = ufl.TestFunction(self.V)
            self._region_form = fem.form(chi * ufl.dot(self.sig_q, self._eps(v)) * self.dxq)
        vec = fem.assemble_vector(self._region_form)
        vec.scatter_reverse(fx.dolfinx.la.InsertMode.add)
        own = vec.array[: self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs]
        return self.system.norm(own) + 1e-300

    def _largest_stress(self, points: np.ndarray | None) -> float:
        """The largest stress magnitude (the largest absolute eigenvalue of the tensor) of
        the current stress at ``points`` (all points if None), Pa; the largest over the MPI
        ranks."""
        sig = self.sig_cur if points is None else self.sig_cur[points]
        own = (float(np.abs(eigvalsh3_batch(mandel_to_tensor(sig))).max()) if len(sig)
               else 0.0)
        return self.comm.allreduce(own, op=self._fx.MPI.MAX) if self.comm.size > 1 else own

    def _end_step(self, out: Any) -> None:
        """The step's end (``LoadStep``'s converged_on, noise_residual, status, residual,
        tol, residual_pa, redraws, noise, ceiling) from its ``femcoupling.fem.quadrature.NewtonOutcome``: the residual is
        judged on the DEM regions' own force scale where the model has region elements, else
        on the body's."""
        rscale = self._region_scale() if self.region_elements else None
        on = rscale if rscale is not None else out.scale
        pts = self._region_points() if rscale is not None else None
        rel = out.residual * out.scale / on
        self._step_end = {"converged_on": out.converged_on,
                          "noise_residual": out.noise_residual, "status": out.status,
                          "residual": rel, "tol": self.newton_rtol * out.scale / on,
                          "residual_pa": rel * self._largest_stress(pts),
                          "redraws": out.redraws,
                          "noise": out.noise_residual * out.scale / on,
                          "ceiling": self.noise_ceiling if rscale is not None else math.inf}

    def _newton(self) -> int:
        """Newton iterations of the current step (``femcoupling.fem.quadrature.newton_solve``,
        the hierarchical mode's Newton and its rules); returns their number, or -1 on
        failure (the reason in ``last_failure``).

        With region elements the residual cannot fall below the elements' own resolution (a
        DEM answer is rough at the scale of Newton's last corrections: measured stalls at
        1e-4 to 2e-3 of the region's own internal force). Where Newton stalls, the elements'
        noise is measured; a step within ``noise_factor`` times it and within
        ``noise_ceiling`` of the DEM regions' own internal force (``_region_scale``) is
        stopped_at_scatter (said in ``warnings``); above the ceiling, or never within the
        noise, the step is cut."""
        rules = NewtonRules(rtol=self.newton_rtol, max_newton=self.max_newton,
                            noise_factor=self.noise_factor, ceiling=self.noise_ceiling,
                            probe=bool(self.region_elements), probe_size="correction")
        self._step_end = {}
        try:
            out = newton_solve(_SoilNewton(self), rules)
        except NewtonFailure as e:
            self.last_failure = str(e)
            return -1
        self._end_step(out)
        return out.iterations

    def _commit(self) -> None:
        for unit, _ in self._element_units():
            unit.commit()
        for _, m in self._point_sets:
            m.commit()
        self.u_n.x.array[:] = self.u.x.array
        self.u_n.x.scatter_forward()

    # ---- stages --------------------------------------------------------------------------

    def _run_stage(self, stage: str, apply: Any, steps: int, callback: Any = None) -> list:
        """Apply ``apply(load_factor)`` in ``steps`` equal increments, Newton at each, through
        the one load-step loop (``femcoupling.fem.steps.load_path``: a failed step rolled back
        and halved, an easy one doubling the next back towards the nominal size, at most
        ``max_cuts`` halvings below it, then :class:`NewtonFailure`)."""
        if not isinstance(steps, int) or steps < 1:
            raise FemInputError(f"steps={steps!r}: must be an integer >= 1")
        if callback is not None and not callable(callback):
            raise FemInputError(f"callback={callback!r}: must be callable (called with each "
                                "accepted step's LoadStep), or None")

        def take(lf: float) -> LoadStep:
            apply(lf)
            its = self._newton()
            if its < 0:
                raise NewtonFailure(self.last_failure or "")
            self._commit()
            return LoadStep(stage=stage, load_factor=lf,
                              footing_settlement_m=self.footing_settlement_m(),
                              footing_pressure_pa=self.footing_pressure_pa(),
                              newton_iterations=its, plastic_points=self.plastic_points(),
                              **self._step_end)

        def accepted(r: LoadStep) -> None:
            if r.converged_on == "noise":
                self._noise_warning(r)
            self.history.append(r)
            if callback is not None:
                callback(r)

        return self._load(take, apply, steps=steps, max_cuts=self.max_cuts,
                          where=f"stage {stage!r}", accepted=accepted)

    _ext_scale = 0.0

    def _noise_warning(self, r: LoadStep) -> None:
        msg = (f"{r.stage} step at load factor {r.load_factor:.4g}: Newton stalled at "
               f"{r.residual:.3g} of the DEM regions' own internal force ({r.residual_pa:.3g} "
               f"Pa), above the tolerance newton_rtol={self.newton_rtol:g} ({r.tol:.3g} of "
               f"the regions' force), within {self.noise_factor:g} x the elements' noise "
               f"({r.noise_residual:.3g} of the body's force scale) and within "
               f"noise_ceiling={self.noise_ceiling:g}"
               + (f" (after {r.redraws} more iterates: the first stall was above the "
                  "ceiling, within the noise)" if r.redraws else "")
               + ": the DEM region elements do not resolve the tolerance asked; the step "
               "stopped at their scatter (stopped_at_scatter, not converged)")
        self._warn(msg, stacklevel=6)  # (the stage's caller: _run_stage's)

    # ---- state ---------------------------------------------------------------------------

    def save_state(self) -> dict:
        """A copy of the state (displacements, stresses, loads) for :meth:`restore_state`."""
        return {"u": self.u.x.array.copy(), "sig": self.sig_n.copy(),
                "traction": self.traction.value.copy(), "footing_u": float(self.footing_u.value),
                "dc": self._displacement_control, "ext": self._ext_scale,
                "nhist": len(self.history),
                "elements": [unit.state() for unit, _ in self._element_units()]}

    def restore_state(self, state: Mapping) -> None:
        """Return to a state saved by :meth:`save_state` (materials are not restored)."""
        self.u.x.array[:] = state["u"]
        self.u.x.scatter_forward()
        self.u_n.x.array[:] = state["u"]
        self.u_n.x.scatter_forward()
        self.sig_n = state["sig"].copy()
        self.sig_cur = self.sig_n.copy()
        # (the quadrature stress too: the reaction, and so the footing pressure, reads it)
        self._to_q(self.sig_q, self.sig_n, self._qdofs, self.ncomp)
        self.traction.value[:] = state["traction"]
        self.footing_u.value = state["footing_u"]
        self._displacement_control = state["dc"]
        self._ext_scale = state["ext"]
        del self.history[state["nhist"]:]
        for (unit, _), data in zip(self._element_units(), state.get("elements", [])):
            unit.set_state(data)


class _SoilNewton:
    """A ``FemModel`` of the soil body as ``femcoupling.fem.quadrature.newton_solve``'s problem."""

    def __init__(self, m) -> None:
        self.m, self.bcs = m, m._active_bcs()

    def evaluate(self, first: bool, perturb: float = 0.0) -> None:
        deps = self.m._strain_increment()
        self.m._update_tangent_and_stress(deps * (1.0 + perturb) if perturb else deps)

    def residual(self) -> float:
        return self.m.system.residual(self.bcs)

    def force_scale(self) -> float:
        return max(self.m._internal_scale(), self.m._ext_scale)

    def noise_scale(self) -> float:
        return self.m._region_scale()

    def stresses(self) -> np.ndarray:
        return self.m.sig_cur.copy()

    def stress_change_residual(self, before: np.ndarray) -> float:
        m = self.m
        return m.system.change_residual(
            m.sig_cur - before, self.bcs,
            lambda f, v: m._to_q(f, v, m._qdofs, m.ncomp))

    def noisiest(self, before: np.ndarray, count: int = 3) -> str:
        """The region elements whose points' stresses moved most off ``before`` (the noise
        probe's): each element's volume-weighted rms of the points' change (Pa, the Mandel
        norm), the largest ``count``. Empty under MPI (each rank holds its own points)."""
        m = self.m
        if m.comm.size > 1 or not m._element_points:
            return ""
        change = np.linalg.norm(np.asarray(m.sig_cur) - before, axis=1)
        rms = {k: math.sqrt(dot(w, change[sel] ** 2))
               for k, (sel, w) in m._element_points.items()}
        top = sorted(rms, key=lambda k: (-rms[k], k))[:count]
        return ", ".join(f"{k} {rms[k]:.3g} Pa" for k in top)

    def at_boundary_values(self) -> bool:
        return self.m.system.at_boundary_values(self.bcs)

    def increment_norm(self) -> float:
        m = self.m
        return math.sqrt(sum_squares(m.u.x.array - m.u_n.x.array))

    def correction(self) -> np.ndarray:
        return self.m.system.correction(self.bcs)

    def move(self, correction: np.ndarray, factor: float) -> None:
        self.m.system.move(correction, factor)
