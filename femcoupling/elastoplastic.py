"""The continuum outer domain: a reinforced soil body solved in dolfinx (plane strain or 3D).

:class:`SoilModel` holds the mesh of a :class:`~femcoupling.geometry.ReinforcedSoilBody`,
P2 (default) displacements, and a stress history at the quadrature points (a quadrature
space; the return mapping is the NumPy kernel
:func:`femcoupling.materials.drucker_prager_return`). Loading is incremental with a full
Newton iteration on the consistent tangent at each step (MUMPS LU).

Stages (each one a sequence of equilibrium steps):

1. :meth:`SoilModel.set_geostatic` -- a K0 initial state from the self-weight:
   sigma_zz = -gamma (H - z), sigma_xx = sigma_yy = K0 sigma_zz (tension positive), in
   equilibrium with the body force (no displacement results).
2. :meth:`SoilModel.apply_prestress` -- prestressed geogrid layers (PRS, 002): the initial
   tensile stress T_p / t along x is added in the layers' bands, and the body is brought to
   equilibrium (the band shortens and compresses the soil around it).
3. :meth:`SoilModel.load_footing` -- a footing pressure (load control) or a footing
   settlement (displacement control, smooth footing) in steps.

Boundary conditions: bottom fixed; x = 0 (symmetry) and x = width rollers (u_x = 0);
3D: y = 0 and y = length rollers (u_y = 0); the top is free apart from the footing.

Extraction: :meth:`SoilModel.region_stress` (volume average over a tagged region) and
:meth:`SoilModel.point_stress` (from a local L2 projection onto DG1) return NumPy 3x3
tensors ordered (x, y, z), **tension positive** (in 2D y is the out-of-plane direction).
Every method is collective under MPI and returns the same values on every rank.

The class is split by role: this module holds the mesh, the spaces, the material arrays,
Newton and the state; :mod:`femcoupling.soil_loading` the load stages,
:mod:`femcoupling.soil_regions` the regions with a material or DEM element of their own,
:mod:`femcoupling.soil_measures` what the model gives out (settlement, stresses, forces,
XDMF), and :mod:`femcoupling.soil_steps` a step's record.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from femcoupling import geometry as geo
from femcoupling.geometry import FemInputError
from femcoupling.materials import (AnisotropicElastic, GeogridLayerMaterial, LinearElastic,
                                   drucker_prager_return, elastic_tangent, mandel_to_tensor)
from femcoupling.soil_loading import LoadingStages
from femcoupling.soil_measures import SoilMeasures
from femcoupling.soil_regions import RegionMaterials
from femcoupling.soil_steps import NewtonDivergence, StepResult

__all__ = ["SoilModel", "StepResult", "NewtonDivergence"]

SQRT2 = math.sqrt(2.0)


class SoilModel(RegionMaterials, LoadingStages, SoilMeasures):
    """A reinforced soil body in dolfinx; see the module doc. Collective on ``comm``.

    Args:
        body: the geometry (tags documented in :mod:`femcoupling.geometry`).
        soil: the soil's material (:class:`LinearElastic` or :class:`DruckerPrager`).
        layers: one :class:`GeogridLayerMaterial` per geogrid layer of ``body``.
        region_materials: optional material per element-region name (default: ``soil``).
        unit_weight_n_m3: soil unit weight gamma, N/m^3, >= 0 (0: weightless).
        degree: displacement degree (1 or 2).
        newton_rtol: Newton stops when |R| <= newton_rtol * |F_int| (free dofs), -.
        max_newton: iterations before a step is cut in half.
        max_cuts: step halvings before :class:`NewtonDivergence`.
        comm: mpi4py communicator (default COMM_WORLD).
    """

    def __init__(self, body: geo.ReinforcedSoilBody, *, soil: LinearElastic,
                 layers: Sequence[GeogridLayerMaterial] = (),
                 region_materials: Mapping[str, LinearElastic] | None = None,
                 unit_weight_n_m3: float = 0.0, degree: int = 2, newton_rtol: float = 1e-8,
                 max_newton: int = 25, max_cuts: int = 6, comm: Any = None) -> None:
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
        if degree not in (1, 2):
            raise FemInputError(f"degree={degree!r}: must be 1 or 2")
        geo._pos("newton_rtol", newton_rtol)

        from femcoupling import _dolfinx

        fx = self._fx = _dolfinx.load()
        fem, ufl = fx.fem, fx.ufl
        import basix
        import basix.ufl

        self.body, self.soil, self.layers = body, soil, layers
        self.region_materials = region_materials
        #: DEM elements as materials, by region (``set_region_element``) or by region cell
        #: (``set_cell_elements``: "<region>/<cell>")
        self.region_elements: dict = {}
        self._element_points: dict = {}
        #: with region elements: a step whose residual has not halved in this many Newton
        #: iterations, its best within ``stall_rtol`` of the DEM regions' own internal force
        #: (not the body's: a 0.1 m region in a 4 x 3 m body carries a small share of it), is
        #: taken there, as "stalled". 1e-2: the equilibrium the region elements are relaxed
        #: to (their unbalanced-force ratio, 1e-2 in the region elements of this package)
        self.stall_iterations = 3
        self.stall_rtol = 1e-2
        #: every warning of the run (steps taken at a stall), in order
        self.warnings: list[str] = []
        self._step_end: dict = {}
        self._region_form = None  # the DEM regions' internal force (built on demand)
        self.unit_weight_n_m3, self.degree = gamma, degree
        self.newton_rtol, self.max_newton, self.max_cuts = newton_rtol, max_newton, max_cuts
        self.comm = comm if comm is not None else fx.MPI.COMM_WORLD
        self.history: list[StepResult] = []

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

        # --- spaces ---
        self.V = fem.functionspace(msh, ("Lagrange", degree, (tdim,)))
        qdeg = max(1, 2 * (degree - 1))
        self.qdeg = qdeg
        cell = msh.basix_cell()
        qe_v = basix.ufl.quadrature_element(cell, value_shape=(self.ncomp,), scheme="default",
                                            degree=qdeg)
        qe_t = basix.ufl.quadrature_element(cell, value_shape=(self.ncomp, self.ncomp),
                                            scheme="default", degree=qdeg)
        self.Wv = fem.functionspace(msh, qe_v)
        self.Wt = fem.functionspace(msh, qe_t)
        pts, wts = basix.make_quadrature(cell, qdeg)
        self.qpoints, self.qweights = pts, wts / wts.sum()
        self.nq = len(wts)
        self._qdofs = self.Wv.dofmap.list.reshape(-1)  # (cell, q) -> quadrature dof (block)
        self._qdofs_t = self.Wt.dofmap.list.reshape(-1)

        self.u = fem.Function(self.V, name="displacement")
        self.u_n = fem.Function(self.V)
        self.du = fem.Function(self.V)
        self.sig_q = fem.Function(self.Wv)      # current stress at the quadrature points
        self.tan_q = fem.Function(self.Wt)      # consistent tangent
        n_qp = self.n_cells * self.nq
        self.sig_n = np.zeros((n_qp, self.ncomp))  # converged stress, (cell, q) order
        self.sig_cur = np.zeros((n_qp, self.ncomp))
        self.dlam = np.zeros(n_qp)

        # --- per-quadrature-point material parameters ---
        self.cell_tag_of = np.full(self.n_cells, geo.SOIL_TAG, dtype=np.int32)
        self.cell_tag_of[self.cell_tags.indices] = self.cell_tags.values
        self._set_material_arrays()

        # --- forms ---
        v, dv = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        self.dxq = ufl.Measure("dx", domain=msh, metadata={"quadrature_degree": qdeg,
                                                           "quadrature_scheme": "default"})
        ds = ufl.Measure("ds", domain=msh, subdomain_data=self.facet_tags)
        dx = ufl.Measure("dx", domain=msh)
        st = fx.PETSc.ScalarType
        self.traction = fem.Constant(msh, np.zeros(tdim, dtype=st))
        grav = np.zeros(tdim, dtype=st)
        grav[self.zc] = -gamma
        self.body_force = fem.Constant(msh, grav)
        self._eps = self._mandel_strain
        f_int = ufl.dot(self.sig_q, self._eps(v)) * self.dxq
        f_body = ufl.dot(self.body_force, v) * dx
        f_trac = ufl.dot(self.traction, v) * ds(geo.FOOTING)
        self.form_res = fem.form(f_int - f_body - f_trac)
        self.form_react = fem.form(f_int - f_body)
        self.form_jac = fem.form(ufl.dot(ufl.dot(self.tan_q, self._eps(dv)), self._eps(v))
                                 * self.dxq)
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

        self.A = fx.fem_petsc.create_matrix(self.form_jac)
        self.b = fx.fem_petsc.create_vector(self.V)
        self.ksp = fx.PETSc.KSP().create(self.comm)
        self.ksp.setOperators(self.A)
        self.ksp.setType("preonly")
        pc = self.ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType("mumps")
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

    def _set_material_arrays(self) -> None:
        n = self.n_cells
        K, G, A, B, Kc = (np.zeros(n) for _ in range(5))
        aniso = []  # (cell mask, stiffness) of AnisotropicElastic materials
        for tag in np.unique(self.cell_tag_of):
            m = self.material_of_tag(int(tag))
            sel = self.cell_tag_of == tag
            K[sel], G[sel] = m.bulk_pa, m.shear_pa
            A[sel], B[sel], Kc[sel] = m.dp_parameters()
            if isinstance(m, AnisotropicElastic):
                aniso.append((sel, m.matrix(self.ncomp)))
        rep = lambda a: np.repeat(a, self.nq)  # noqa: E731 - (cell, q) order
        self.K, self.G, self.alpha, self.beta, self.kc = map(rep, (K, G, A, B, Kc))
        # The elastic stiffness per quadrature point: isotropic from (K, G), replaced where a
        # region has a full stiffness (those points never yield: k = inf).
        C = elastic_tangent(self.K, self.G, self.ncomp)
        for sel, c in aniso:
            C[rep(sel)] = c
        self.C = C
        self._aniso = rep(np.any([sel for sel, _ in aniso], axis=0)) if aniso else None

    def _to_q(self, func: Any, values: np.ndarray, dofs: np.ndarray, size: int) -> None:
        func.x.array.reshape(-1, size)[dofs] = values.reshape(-1, size)
        func.x.scatter_forward()

    def _update_tangent_and_stress(self, deps: np.ndarray) -> None:
        trial = self.sig_n + np.einsum("nij,nj->ni", self.C, deps)
        sig, tan, dl = drucker_prager_return(trial, bulk_pa=self.K, shear_pa=self.G,
                                             alpha=self.alpha, beta=self.beta, k_pa=self.kc)
        if self._aniso is not None:  # elastic there: the return left the trial stress
            tan[self._aniso] = self.C[self._aniso]
        if self.region_elements:
            self._region_element_answers(deps, sig, tan, dl)
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
        """b = R(u) lifted by J (g - u) at the constrained dofs (the predictor of the
        prescribed increment), b = u - g there; returns |b| (dolfinx's Newton convention:
        solve J dx = b, u <- u - dx)."""
        fx = self._fx
        PETSc = fx.PETSc
        bcs = self._active_bcs()
        with self.b.localForm() as loc:
            loc.set(0.0)
        fx.fem_petsc.assemble_vector(self.b, self.form_res)
        fx.fem_petsc.apply_lifting(self.b, [self.form_jac], bcs=[bcs], x0=[self.u.x.petsc_vec],
                                   alpha=-1.0)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fx.fem_petsc.set_bc(self.b, bcs, x0=self.u.x.petsc_vec, alpha=-1.0)
        return self.b.norm()

    def _internal_scale(self) -> float:
        """|F_int| over all dofs (the Newton tolerance's scale), >= tiny."""
        fx = self._fx
        vec = fx.fem.assemble_vector(self.form_react)
        vec.scatter_reverse(fx.dolfinx.la.InsertMode.add)
        own = vec.array[: self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs]
        return math.sqrt(self.comm.allreduce(float(own @ own), op=fx.MPI.SUM)) + 1e-300

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
        return math.sqrt(self.comm.allreduce(float(own @ own), op=fx.MPI.SUM)) + 1e-300

    def _largest_stress(self, points: np.ndarray | None) -> float:
        """The largest stress magnitude (the largest absolute eigenvalue of the tensor) of
        the current stress at ``points`` (all points if None), Pa."""
        sig = self.sig_cur if points is None else self.sig_cur[points]
        if len(sig) == 0:
            return 0.0
        ev = np.linalg.eigvalsh(mandel_to_tensor(sig))
        return float(np.abs(ev).max())

    def _end_step(self, rnorm: float, scale: float, rscale: float | None, *,
                  stall: bool) -> None:
        """The step's end (``StepResult``'s converged_on, noise_residual, status, residual,
        tol, residual_pa): ``rnorm`` the accepted residual's norm, ``scale`` the body's force
        scale, ``rscale`` the DEM regions' own (None without region elements)."""
        on = rscale if rscale is not None else scale
        pts = self._region_points() if rscale is not None else None
        rel = rnorm / on
        self._step_end = {"converged_on": "stall" if stall else "tolerance",
                          "noise_residual": rnorm / scale if stall else float("nan"),
                          "status": "stalled" if stall else "converged",
                          "residual": rel, "tol": self.newton_rtol * scale / on,
                          "residual_pa": rel * self._largest_stress(pts)}

    def _newton(self) -> int:
        """Newton iterations of the current step; returns their number, or -1 on failure.

        With region elements the residual cannot fall below the elements' own resolution (a
        DEM answer is rough at the scale of Newton's last corrections: measured stalls at
        1e-4 to 2e-3 of the region's own internal force). A step whose residual has not
        halved in ``stall_iterations`` iterations, and whose best residual is within
        ``stall_rtol`` of the DEM regions' own internal force (``_region_scale``), is taken at
        its best iterate ("stall", status "stalled", said in ``warnings``); above it Newton
        goes on to ``max_newton``, and the step is cut."""
        fx = self._fx
        bcs = self._active_bcs()
        self._update_tangent_and_stress(self._strain_increment())
        self._step_end = {}
        best, best_u, best_scales, since = math.inf, None, None, 0
        for it in range(0, self.max_newton + 1):
            rnorm = self._assemble_residual()
            scale = max(self._internal_scale(), self._ext_scale)
            if not np.isfinite(rnorm):
                return -1
            rscale = self._region_scale() if self.region_elements else None
            if rnorm <= self.newton_rtol * scale:
                self._end_step(rnorm, scale, rscale, stall=False)
                return it
            if self.region_elements:
                since = 0 if rnorm < 0.5 * best else since + 1
                if rnorm < best:
                    best, best_u, best_scales = rnorm, self.u.x.array.copy(), (scale, rscale)
                if since >= self.stall_iterations and best <= self.stall_rtol * best_scales[1]:
                    self.u.x.array[:] = best_u  # (the elements answer it again, bitwise)
                    self.u.x.scatter_forward()
                    self._update_tangent_and_stress(self._strain_increment())
                    self._end_step(best, *best_scales, stall=True)
                    return it
            if it == self.max_newton:
                break
            self.A.zeroEntries()
            fx.fem_petsc.assemble_matrix(self.A, self.form_jac, bcs=bcs)
            self.A.assemble()
            self.ksp.setOperators(self.A)
            self.ksp.solve(self.b, self.du.x.petsc_vec)
            if self.ksp.getConvergedReason() <= 0:
                return -1
            self.du.x.scatter_forward()
            self.u.x.array[:] -= self.du.x.array
            self.u.x.scatter_forward()
            self._update_tangent_and_stress(self._strain_increment())
        return -1

    def _commit(self) -> None:
        for unit, _ in self._element_units():
            unit.commit()
        self.sig_n = self.sig_cur.copy()
        self.u_n.x.array[:] = self.u.x.array
        self.u_n.x.scatter_forward()

    def _rollback(self) -> None:
        self.u.x.array[:] = self.u_n.x.array
        self.u.x.scatter_forward()

    # ---- stages --------------------------------------------------------------------------

    def _run_stage(self, stage: str, apply: Any, steps: int, callback: Any = None) -> list:
        """Apply ``apply(load_factor)`` in ``steps`` equal increments, Newton at each."""
        if not isinstance(steps, int) or steps < 1:
            raise FemInputError(f"steps={steps!r}: must be an integer >= 1")
        out = []
        lf_done, dlf = 0.0, 1.0 / steps
        cuts = 0
        while lf_done < 1.0 - 1e-12:
            lf = min(1.0, lf_done + dlf)
            apply(lf)
            its = self._newton()
            if its < 0:
                self._rollback()
                cuts += 1
                if cuts > self.max_cuts:
                    raise NewtonDivergence(f"stage {stage!r}: Newton failed at load factor "
                                           f"{lf:.6g} after {self.max_cuts} step cuts")
                dlf /= 2.0
                continue
            self._commit()
            lf_done = lf
            cuts = 0
            if its <= self.max_newton // 2:  # easy step: grow back towards the nominal size
                dlf = min(2.0 * dlf, 1.0 / steps)
            r = StepResult(stage, lf, self.footing_settlement_m(), self.footing_pressure_pa(),
                           its, self.plastic_points(), **self._step_end)
            if r.converged_on == "stall":
                self._stall_warning(r)
            self.history.append(r)
            out.append(r)
            if callback is not None:
                callback(r)
        return out

    _ext_scale = 0.0

    def _stall_warning(self, r: StepResult) -> None:
        import warnings

        from femcoupling.hierarchical import NoiseWarning

        msg = (f"{r.stage} step at load factor {r.load_factor:.4g}: Newton stalled at "
               f"{r.residual:.3g} of the DEM regions' own internal force ({r.residual_pa:.3g} "
               f"Pa; {r.noise_residual:.3g} of the body's force scale), above the tolerance "
               f"newton_rtol={self.newton_rtol:g} ({r.tol:.3g} of the regions' force) and "
               f"within stall_rtol={self.stall_rtol:g}: the DEM region elements do not resolve "
               "the tolerance asked; the step is taken at its best iterate (stalled, not "
               "converged)")
        self.warnings.append(msg)
        warnings.warn(msg, NoiseWarning, stacklevel=3)

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
