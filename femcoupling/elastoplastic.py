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
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from femcoupling import geometry as geo
from femcoupling.geometry import FemInputError
from femcoupling.materials import (AnisotropicElastic, DruckerPrager, GeogridLayerMaterial,
                                   LinearElastic, drucker_prager_return, elastic_tangent,
                                   mandel_identity, mandel_to_tensor, stiffness_block,
                                   tensor_to_mandel)

__all__ = ["SoilModel", "StepResult", "NewtonDivergence"]

_counter = itertools.count()
SQRT2 = math.sqrt(2.0)


class NewtonDivergence(RuntimeError):
    """Newton did not converge even after the step was cut ``max_cuts`` times."""


@dataclasses.dataclass(frozen=True)
class StepResult:
    """One accepted load step.

    Attributes:
        stage: 'geostatic', 'prestress' or 'footing'.
        load_factor: fraction of the stage's load applied, -.
        footing_settlement_m: mean downward displacement of the footing, m (positive down).
        footing_pressure_pa: mean footing pressure, Pa, **compression positive** (the reaction
            in displacement control; the applied pressure in load control).
        newton_iterations: iterations this step took.
        plastic_points: number of plastic quadrature points (global).
        converged_on: "tolerance" (``newton_rtol``), or "stall": with DEM region elements,
            Newton stalled above it at the elements' resolution and the step was taken at
            its best iterate (said in ``SoilModel.warnings``).
        noise_residual: that best residual relative to the whole body's force scale (NaN
            otherwise).
        status: "converged" (``newton_rtol`` met) or "stalled" (taken at a stall: its best
            residual within ``SoilModel.stall_rtol`` of the DEM regions' own internal force,
            above the tolerance) (:mod:`femcoupling.status`).
        residual: the accepted residual relative to the force scale it is judged against:
            the DEM regions' own internal force where the model has region elements, else
            the body's, -.
        tol: ``newton_rtol`` on that same scale, -; ``status`` is "converged" when
            ``residual <= tol``.
        residual_pa: the accepted residual in stress units, Pa: ``residual`` times the
            largest stress magnitude of the points of that scale (the regions' with region
            elements, else the body's).
    """

    stage: str
    load_factor: float
    footing_settlement_m: float
    footing_pressure_pa: float
    newton_iterations: int
    plastic_points: int
    converged_on: str = "tolerance"
    noise_residual: float = float("nan")
    status: str = "converged"
    residual: float = float("nan")
    tol: float = float("nan")
    residual_pa: float = float("nan")


class SoilModel:
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

    def set_region_material(self, name: str, material: LinearElastic) -> None:
        """Give the element region ``name`` a new material (two-way coupling)."""
        self.body.region_tag(name)
        if not isinstance(material, LinearElastic):
            raise FemInputError(f"material={material!r}: must be a LinearElastic")
        self.region_materials[name] = material
        self._set_material_arrays()

    def set_region_element(self, name: str, element: Any) -> None:
        """The element region ``name`` takes its stress and tangent from a DEM element at
        every Newton iterate (the hierarchical mode on this body, one element for the
        region's cells): ``element`` (``femcoupling.region.DemRegionMaterial``) gets the
        region's volume-mean strain increment since the start of the load step (3 x 3) and
        returns its stress increment (3 x 3, Pa) and tangent (6 x 6 Mandel, Pa), which every
        point of the region takes; a converged step commits it. The members of one
        ``femcoupling.region.PoolRegionMaterials`` (several regions' elements on Dask
        workers) are evaluated at once, in parallel. Serial runs only (one MPI rank)."""
        tag = self.body.region_tag(name)
        self._add_element(name, element, np.repeat(self.cell_tag_of == tag, self.nq))

    def cell_stresses(self, name: str) -> dict:
        """The converged stress of each cell of element region ``name``, by the key
        ``set_cell_elements`` gives that cell's element (``"<name>/<cell>"``): 3 x 3, Pa,
        tension positive (the cell's volume mean; where each cell's element takes over)."""
        tag = self.body.region_tag(name)
        cms = self.cell_mean_stress()
        return {f"{name}/{c}": mandel_to_tensor(cms[c])
                for c in np.flatnonzero(self.cell_tag_of == tag)}

    def set_cell_elements(self, name: str, group: Any) -> list:
        """Every cell of element region ``name`` takes its stress and tangent from its own
        DEM element (the hierarchical mode at the cells' scale; with P1 cells, one
        quadrature point each, an element per quadrature point). ``group`` holds one element
        per cell under the keys of :meth:`cell_stresses` (``femcoupling.region.
        PoolRegionMaterials.build(m.cell_stresses(name), runner, workers=)``: all of them
        evaluated at once on Dask workers at every Newton iterate); each cell is then what
        :meth:`set_region_element` makes of a region: its element gets the cell's mean strain
        increment, and the cell's points take its answer. Returns the keys. Serial runs
        only."""
        keys = list(self.cell_stresses(name))
        members = getattr(group, "materials", None)
        missing = [k for k in keys if members is None or k not in members]
        if missing:
            raise FemInputError(f"group={group!r}: needs an element (in its .materials) for "
                                f"every cell of region {name!r}; missing {missing[:5]}"
                                + (" ..." if len(missing) > 5 else ""))
        for k in keys:
            cell = int(k.rsplit("/", 1)[1])
            on = np.zeros(self.n_cells, bool)
            on[cell] = True
            self._add_element(k, members[k], np.repeat(on, self.nq))
        return keys

    def _add_element(self, key: str, element: Any, sel: np.ndarray) -> None:
        """``element`` answers for the quadrature points ``sel`` (their volume mean strain)."""
        if self.comm.size > 1:
            raise FemInputError(f"region elements ({key!r}): serial runs only (this run "
                                f"has {self.comm.size} MPI ranks)")
        for k in ("trial", "commit", "state", "set_state"):
            if not callable(getattr(element, k, None)):
                raise FemInputError(f"element={element!r}: needs a {k}() method (see "
                                    "femcoupling.region.DemRegionMaterial)")
        self.region_elements[key] = element
        self._region_form = None  # (the regions' cells changed)
        w = (self.cell_volume[:, None] * self.qweights[None, :]).reshape(-1)[sel]
        self._element_points[key] = (sel, w / w.sum())  # its points and volume weights

    def _region_element_answers(self, deps: np.ndarray, sig: np.ndarray,
                                tan: np.ndarray, dl: np.ndarray) -> None:
        """Region points with a DEM element (in place): the start-of-step stress plus the
        element's increment for the region's mean strain increment, plus its tangent times
        the point's deviation from that mean (so the region's mean stress is the element's,
        and the pointwise tangent is the consistent Jacobian: with the mean alone every point
        would depend on every other one, and Newton converged linearly, 15 % per
        iteration); no plastic multiplier."""
        means = {name: self._element_points[name][1] @ deps[self._element_points[name][0]]
                 for name in self.region_elements}
        answers = {}
        for unit, names in self._element_units():
            de = {n: mandel_to_tensor(means[n]) for n in names}
            if hasattr(unit, "trial_many"):  # several regions' elements at once (a pool)
                answers.update(unit.trial_many(de))
            else:
                answers[names[0]] = unit.trial(de[names[0]])
        for name, mean in means.items():
            sel = self._element_points[name][0]
            ds, c = answers[name]
            c = stiffness_block(c, self.ncomp)
            sig[sel] = (self.sig_n[sel] + tensor_to_mandel(ds, self.ncomp)
                        + (deps[sel] - mean) @ c.T)
            tan[sel] = c
            dl[sel] = 0.0

    def _element_units(self) -> list:
        """(unit, region names): each region element once, except the members of one group
        (``femcoupling.region.PoolRegionMaterials``: an element's ``group``), which the group
        evaluates, commits and saves at once."""
        units: dict = {}
        for name, el in self.region_elements.items():
            unit = getattr(el, "group", el)
            units.setdefault(id(unit), (unit, []))[1].append(name)
        return list(units.values())

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

    def set_geostatic(self, *, k0: float | None = None) -> None:
        """K0 initial state from the self-weight (tension positive, see the module doc).

        ``k0`` (-, > 0) defaults to the soil's: 1 - sin(phi) for Drucker–Prager, nu / (1 - nu)
        for an elastic soil. The state is in equilibrium with the body force; a check solve is
        run (it must converge in 0 or 1 iterations).
        """
        k0 = self.soil.k0() if k0 is None else geo._pos("k0", k0)
        fx = self._fx
        x = fx.fem.Expression(fx.ufl.SpatialCoordinate(self.mesh), self.qpoints)
        xq = x.eval(self.mesh, np.arange(self.n_cells, dtype=np.int32)).reshape(-1, self.tdim)
        sv = -self.unit_weight_n_m3 * (self.body.height_m - xq[:, self.zc])
        sig = np.zeros((len(sv), self.ncomp))
        sig[:, :3] = k0 * sv[:, None]
        sig[:, self.zc] = sv
        self.sig_n = sig
        self._ext_scale = self.unit_weight_n_m3 * self.body.height_m * self.footing_area
        self._run_stage("geostatic", lambda lf: None, 1)

    def apply_prestress(self, *, steps: int = 1) -> list[StepResult]:
        """Add each layer's prestress T_p / t (tension along x) and equilibrate (PRS, 002)."""
        add = np.zeros_like(self.sig_n)
        for i, lm in enumerate(self.layers):
            sel = np.repeat(self.cell_tag_of == geo.LAYER_TAG0 + i, self.nq)
            add[sel, 0] = lm.prestress_n_per_m / self.body.layers[i].thickness_m
        base = self.sig_n.copy()
        done = [0.0]

        def apply(lf: float) -> None:
            self.sig_n = self.sig_n + (lf - done[0]) * add
            done[0] = lf

        del base
        return self._run_stage("prestress", apply, steps)

    def load_footing(self, *, pressure_pa: float | None = None,
                     settlement_m: float | None = None, steps: int = 10,
                     callback: Any = None) -> list[StepResult]:
        """Load the footing by a pressure (Pa, compression positive; load control) or a
        settlement (m, downward positive; displacement control of a smooth footing), from the
        current state, in ``steps`` equal increments. Returns the converged steps."""
        if (pressure_pa is None) == (settlement_m is None):
            raise FemInputError("load_footing: give exactly one of pressure_pa, settlement_m")
        if pressure_pa is not None:
            p = geo._real("pressure_pa", pressure_pa)
            t0 = float(self.traction.value[self.zc])
            if p - t0 < 0 and self._cohesionless_under_footing():
                raise FemInputError(
                    f"pressure_pa={p!r}: a tensile footing load (the footing pressure, "
                    f"compression positive, would go from {0.0 - t0:g} to {p - t0:g} Pa); the "
                    "soil is a cohesionless Drucker-Prager (cohesion_pa="
                    f"{self.soil.cohesion_pa!r}), which carries no tension, so no load step "
                    "could converge. Load in compression (pressure_pa > 0), unload by at most "
                    f"the current footing pressure ({0.0 - t0:g} Pa), or give the soil "
                    "cohesion")
            self._displacement_control = False

            def apply(lf: float) -> None:
                self.traction.value[self.zc] = t0 - lf * p
            self._ext_scale = max(self._ext_scale, abs(p) * self.footing_area)
        else:
            d = geo._real("settlement_m", settlement_m)
            self._displacement_control = True
            u0 = -self.footing_settlement_m()

            def apply(lf: float) -> None:
                self.footing_u.value = u0 - lf * d
        try:
            return self._run_stage("footing", apply, steps, callback)
        except NewtonDivergence as e:
            if settlement_m is not None and d < 0 and self._cohesionless_under_footing():
                raise NewtonDivergence(
                    f"{e}; settlement_m={d!r} lifts the footing, and the soil is a "
                    f"cohesionless Drucker-Prager (cohesion_pa={self.soil.cohesion_pa!r}), "
                    "which carries no tension") from e
            raise

    def load_footing_to_pressure(self, pressure_pa: float, *, steps: int = 10,
                                 callback: Any = None, tol: float = 0.01,
                                 max_steps_factor: int = 4) -> list[StepResult]:
        """Push the footing down as a rigid smooth footing (displacement control) until its
        mean pressure (the reaction, Pa, compression positive) has risen by ``pressure_pa``
        from the current state, within ``tol`` (relative). For a cohesionless soil, whose
        surface carries no flexible pressure at the footing's edge (with a Drucker–Prager
        soil without cohesion, a pressure load failed at 19 % of 100 kPa).

        A first small settlement gives the elastic slope; then settlement steps, each aimed
        at the target over the steps left by the last step's secant slope (from half to four
        times the last step), until the pressure reaches the target. A step that passes it
        beyond ``tol`` is taken again, shortened by linear interpolation. The results' ``load_factor`` is the pressure's fraction of the
        target; ``callback(r)`` is called for each accepted step. Raises NewtonDivergence if
        the pressure has not reached the target after ``max_steps_factor`` x ``steps``
        steps (the soil's bearing capacity is below it)."""
        target = geo._real("pressure_pa", pressure_pa)
        if not target > 0:
            raise FemInputError(f"pressure_pa={pressure_pa!r}: must be > 0 (Pa, compression "
                                "positive)")
        if not isinstance(steps, int) or steps < 1:
            raise FemInputError(f"steps={steps!r}: must be an integer >= 1")
        self._displacement_control = True
        u_start = float(self.footing_u.value)
        p0 = self.footing_pressure_pa()
        done: list[StepResult] = []
        d = 0.0

        def go(d_to: float) -> None:
            d_from = d

            def apply(lf: float) -> None:
                self.footing_u.value = u_start - (d_from + lf * (d_to - d_from))

            for r in self._run_stage("footing", apply, 1):
                r2 = dataclasses.replace(r, load_factor=(r.footing_pressure_pa - p0) / target)
                self.history[self.history.index(r)] = r2
                done.append(r2)

        def rise() -> float:
            return self.footing_pressure_pa() - p0

        d1 = 1e-6 * self.body.height_m
        go(d1)
        d = d1
        slope = rise() / d1
        if not slope > 0:
            raise NewtonDivergence(f"footing: a settlement of {d1:.3g} m gave no pressure "
                                   f"({rise():.3g} Pa)")
        dd = max((target - rise()) / slope / steps, d1)
        taken = 0
        while rise() < target * (1.0 - tol):
            if taken >= max_steps_factor * steps:
                raise NewtonDivergence(
                    f"footing: the pressure rose by {rise():.4g} Pa after a settlement of "
                    f"{d:.4g} m in {taken} steps, short of pressure_pa={target:g}: the soil's "
                    "bearing capacity is below it")
            state, n_done, p_now = self.save_state(), len(done), rise()
            go(d + dd)
            p_new = rise()
            if p_new > target * (1.0 + tol):
                self.restore_state(state)
                del done[n_done:]
                dd *= (target - p_now) / (p_new - p_now)
                continue
            d += dd
            taken += 1
            # the next step from the last one's secant slope, aiming at the target over the
            # steps left (at most 4 x longer, at least half as long as this one)
            slope = (p_new - p_now) / dd
            want = ((target - p_new) / slope / max(1, steps - taken) if slope > 0
                    else 4.0 * dd)
            dd = min(max(want, 0.5 * dd), 4.0 * dd)
        for r in done:
            if callback is not None:
                callback(r)
        return done

    def _cohesionless_under_footing(self) -> bool:
        """The soil under the footing carries no tension: a Drucker-Prager soil without
        cohesion, and no element region (whose material may carry tension) reaching the top
        under the footing."""
        b, h = self.body.footing_half_width_m, self.body.height_m
        regions_on_top = any(r.center_m[-1] + r.size_m / 2 >= h - 1e-9 * h
                             and r.center_m[0] - r.size_m / 2 < b for r in self.body.regions)
        return (isinstance(self.soil, DruckerPrager) and self.soil.cohesion_pa == 0
                and not regions_on_top)

    # ---- measurements (NumPy out, identical on every rank) -------------------------------

    def footing_settlement_m(self) -> float:
        """Mean downward displacement of the footing, m."""
        s = self._fx.fem.assemble_scalar(self.form_settle)
        return float(self.comm.allreduce(s, op=self._fx.MPI.SUM) / self.footing_area)

    def footing_pressure_pa(self) -> float:
        """Mean footing pressure, Pa, compression positive: from the reaction at the footing's
        constrained dofs in displacement control, the applied traction otherwise."""
        fx = self._fx
        if not self._displacement_control:
            return float(-self.traction.value[self.zc])
        vec = fx.fem.assemble_vector(self.form_react)
        vec.scatter_reverse(fx.dolfinx.la.InsertMode.add)
        n_own = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        d = self.footing_dofs[self.footing_dofs < n_own]
        f = self.comm.allreduce(float(vec.array[d].sum()), op=fx.MPI.SUM)
        return float(-f / self.footing_area)

    def plastic_points(self) -> int:
        """Number of quadrature points that yielded in the last converged step (global)."""
        own = self.n_owned * self.nq
        return int(self.comm.allreduce(int(np.count_nonzero(self.dlam[:own])),
                                       op=self._fx.MPI.SUM))

    def cell_mean_stress(self) -> np.ndarray:
        """(n_cells, ncomp) cell averages of the converged stress (Mandel), Pa."""
        s = self.sig_n.reshape(self.n_cells, self.nq, self.ncomp)
        return np.einsum("cqi,q->ci", s, self.qweights)

    def region_stress(self, name: str, *, tags: Sequence[int] | None = None) -> np.ndarray:
        """Volume-averaged stress over the element region ``name`` (its soil cells), 3x3 (x, y,
        z), Pa, tension positive. ``tags`` overrides the cell tags averaged over."""
        tag_list = [self.body.region_tag(name)] if tags is None else list(tags)
        return self.tag_stress(tag_list)

    def region_strain(self, name: str) -> np.ndarray:
        """Volume-averaged small strain over the element region ``name`` (its soil cells),
        3x3 (x, y, z), -, tension positive, from the current displacements (since the mesh's
        reference state)."""
        tag = self.body.region_tag(name)
        cells = np.arange(self.n_cells, dtype=np.int32)
        eps = self.expr_eps.eval(self.mesh, cells).reshape(self.n_cells, self.nq, self.ncomp)
        cm = np.einsum("cqi,q->ci", eps, self.qweights)[: self.n_owned]
        sel = self.cell_tag_of[: self.n_owned] == tag
        vol = self.cell_volume[: self.n_owned][sel]
        MPI = self._fx.MPI
        tot = np.asarray(self.comm.allreduce(np.concatenate([(cm[sel] * vol[:, None]).sum(0),
                                                             [vol.sum()]]), op=MPI.SUM))
        if tot[-1] <= 0:
            raise FemInputError(f"name={name!r}: the region has no cells")
        return mandel_to_tensor(tot[:-1] / tot[-1])

    def tag_stress(self, tags: Sequence[int]) -> np.ndarray:
        """Volume-averaged stress over the cells with any of ``tags``, 3x3, Pa, tension +."""
        sel = np.isin(self.cell_tag_of[: self.n_owned], np.asarray(tags))
        cm = self.cell_mean_stress()[: self.n_owned][sel]
        vol = self.cell_volume[: self.n_owned][sel]
        MPI = self._fx.MPI
        tot = np.asarray(self.comm.allreduce(np.concatenate([(cm * vol[:, None]).sum(0),
                                                             [vol.sum()]]), op=MPI.SUM))
        if tot[-1] <= 0:
            raise FemInputError(f"tags={list(tags)}: no cells carry these tags")
        return mandel_to_tensor(tot[:-1] / tot[-1])

    def layer_force_n_per_m(self, i: int, *, x_range_m: tuple[float, float] | None = None
                            ) -> float:
        """Mean axial force per metre width in geogrid layer ``i`` (sigma_xx t), N/m, tension
        positive; over the cells whose centre lies in ``x_range_m`` if given."""
        tag = geo.LAYER_TAG0 + i
        sel = self.cell_tag_of[: self.n_owned] == tag
        if x_range_m is not None:
            xc = self._cell_centres()[: self.n_owned, 0]
            sel &= (xc >= x_range_m[0]) & (xc <= x_range_m[1])
        cm = self.cell_mean_stress()[: self.n_owned][sel, 0]
        vol = self.cell_volume[: self.n_owned][sel]
        MPI = self._fx.MPI
        s = self.comm.allreduce(np.array([(cm * vol).sum(), vol.sum()]), op=MPI.SUM)
        return float(s[0] / s[1] * self.body.layers[i].thickness_m) if s[1] > 0 else math.nan

    def region_layer_force(self, name: str) -> float | None:
        """The geogrid tension across the element region ``name``, N/m, tension positive: the
        mean axial force per metre width of the layers that cross it
        (``ReinforcedSoilBody.region_layers``) over the region's x extent, summed over them;
        None where no layer crosses the region. The two-way coupling hands it to the DEM
        element's grid ends (``WallTargets.grid_tension_n_per_m``)."""
        layers = self.body.region_layers(name)
        if not layers:
            return None
        reg = self.body.regions[self.body.region_tag(name) - geo.REGION_TAG0]
        x = reg.center_m[0]
        xr = (x - reg.size_m / 2, x + reg.size_m / 2)
        return float(sum(self.layer_force_n_per_m(i, x_range_m=xr) for i in layers))

    def _cell_centres(self) -> np.ndarray:
        g = self.mesh.geometry
        dm = g.dofmaps[0][: self.n_cells]
        return g.x[dm].mean(axis=1)

    def point_stress(self, points_m: npt.ArrayLike) -> np.ndarray:
        """Stress at points (n, dim) m: the converged quadrature stress L2-projected onto DG1
        per cell (exact for a P2 elastic field), evaluated at the points. (n, 3, 3) Pa, tension
        positive (x, y, z). Points outside the body raise FemInputError."""
        fx = self._fx
        fem, ufl = fx.fem, fx.ufl
        import dolfinx.geometry as dg

        pts = np.atleast_2d(np.asarray(points_m, float))
        if pts.shape[1] != self.tdim:
            raise FemInputError(f"points_m: shape {pts.shape}, need (n, {self.tdim})")
        p3 = np.zeros((len(pts), 3))
        p3[:, : self.tdim] = pts
        D = fem.functionspace(self.mesh, ("DG", 1, (self.ncomp,)))
        t, s = ufl.TrialFunction(D), ufl.TestFunction(D)
        self._to_q(self.sig_q, self.sig_n, self._qdofs, self.ncomp)
        prob = fx.fem_petsc.LinearProblem(
            ufl.inner(t, s) * self.dxq, ufl.inner(self.sig_q, s) * self.dxq,
            petsc_options_prefix=f"femcoupling_proj_{next(_counter)}_",
            petsc_options={"ksp_type": "preonly", "pc_type": "lu",
                           "pc_factor_mat_solver_type": "mumps"})
        sh = prob.solve()
        tree = dg.bb_tree(self.mesh, self.tdim)
        cand = dg.compute_collisions_points(tree, p3)
        coll = dg.compute_colliding_cells(self.mesh, cand, p3)
        vals = np.zeros((len(pts), self.ncomp))
        found = np.zeros(len(pts))
        for i in range(len(pts)):
            cells = coll.links(i)
            cells = cells[cells < self.n_owned]
            if len(cells):
                vals[i] = sh.eval(p3[i], cells[:1])
                found[i] = 1.0
        MPI = fx.MPI
        fnd = np.asarray(self.comm.allreduce(found, op=MPI.SUM))
        tot = np.asarray(self.comm.allreduce(vals, op=MPI.SUM))
        if np.any(fnd == 0):
            raise FemInputError(f"points_m: {pts[fnd == 0].tolist()} lie outside the body")
        return mandel_to_tensor(tot / fnd[:, None])

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

    # ---- output --------------------------------------------------------------------------

    def write_xdmf(self, path: Any, *, time: float = 0.0, append: bool = False) -> None:
        """Write the mesh with its cell tags (element regions and layers marked), the
        displacement (P1 interpolation, m) and the cell-mean stress (3x3 (x, y, z), Pa,
        tension positive) to an XDMF/HDF5 pair; ``append`` adds a time to an existing file."""
        fx = self._fx
        fem = fx.fem
        import dolfinx.io

        P1 = fem.functionspace(self.mesh, ("Lagrange", 1, (self.tdim,)))
        u1 = fem.Function(P1, name="displacement_m")
        u1.interpolate(self.u)
        T = fem.functionspace(self.mesh, ("DG", 0, (3, 3)))
        sig = fem.Function(T, name="stress_pa")
        sig.x.array[:] = mandel_to_tensor(self.cell_mean_stress()).reshape(-1)[
            : sig.x.array.size]
        sig.x.scatter_forward()
        pl = fem.Function(fem.functionspace(self.mesh, ("DG", 0)), name="plastic_fraction")
        pl.x.array[:] = (self.dlam.reshape(self.n_cells, self.nq) != 0).mean(1)
        tagf = fem.Function(fem.functionspace(self.mesh, ("DG", 0)), name="cell_tag")
        tagf.x.array[:] = self.cell_tag_of
        mode = "a" if append else "w"
        with dolfinx.io.XDMFFile(self.comm, str(path), mode) as xf:
            if not append:
                xf.write_mesh(self.mesh)
                self.cell_tags.name = "cell_tags"
                xf.write_meshtags(self.cell_tags, self.mesh.geometry)
            for f in (u1, sig, pl, tagf):
                xf.write_function(f, time)
