"""Hierarchical FEM x DEM in plane strain: a DEM element at every quadrature point (issue 18,
second part; docs/coupling_hierarchical.md).

The FEM is a rectangle ``lx`` x ``ly`` (m) of P1 triangles with one quadrature point each
(``degree=2``: P2 triangles with three points each, which do not lock under isochoric or
dilatant flow as constant-strain triangles do), in dolfinx. Each quadrature point owns one
persistent ``DemElement`` held by an ``ElementPool`` on Dask workers (the pool's element k is
cell k // nq, point k % nq; with P1, cell k). In a load step Newton iterates:

1. the displacement-gradient increment since the start of the step, grad(u) - grad(u_n), at
   every quadrature point (shear and rotation included; the FEM's (x, y) is the element's
   (x, z), and its out-of-plane y is held: plane strain);
2. every element is restored to the start of the step (``pool.reject``: a rejected iterate
   leaves no trace) and takes that increment; it returns its stress and its network tangent;
3. the residual and the Jacobian are assembled from them (Voigt xx, yy, xy with engineering
   shear), and the displacements are corrected.

An accepted step is saved (``pool.accept``: every element's state saved as bytes). Each
step ends in a status (:mod:`femcoupling.coupling.status`): ``converged`` (the residual within
``newton_rtol``) or ``stopped_at_scatter`` (``convergence="noise"``: Newton stalled above
``newton_rtol`` with the residual within ``noise_factor`` times the elements' measured noise
and within the ``noise_ceiling``, 10 x ``newton_rtol`` by default). A step whose residual is
within the noise but above the ceiling is not accepted: it is cut, as a step Newton fails
(``NewtonFailure``; a step that still fails after its cuts raises it, the run has
``failed``). The residual is relative to the internal force scale (the largest element
stress times the square root of the domain's area) and also given in stress units
(``HierStep.residual_pa``, Pa: that relative residual times the largest element stress).
The
elements are the points' material (``ElementPoolMaterial``, a ``femcoupling.fem.quadrature.
QuadratureMaterial``), and Newton and its rules are ``femcoupling.fem.quadrature.newton_solve``,
the same as the Drucker–Prager soil body's of ``femcoupling.fem.soil_model``.

Boundary conditions (``platens="smooth"``, the default): left u_x = 0, bottom u_y = 0; the
top is moved by ``top_displacement`` (u_y, m); the right is either loaded by a confining
pressure (``confining_pa``, compression positive: a biaxial test) or moved
(``right_displacement``, u_x, m). ``platens="rough"`` (a biaxial test whose platens grip the
sample, the usual set-up for shear bands): the bottom is held (u_x = u_y = 0), the top moves
down without sliding (u_x = 0, u_y = ``top_displacement``), and both sides carry the
confining pressure; no symmetry plane forces the band's shape. ``platens="footing"`` (a
rigid smooth strip footing of half width ``footing_b``, m, beside its symmetry plane): the
left and right on rollers (u_x = 0), the bottom u_y = 0, the top moved by
``top_displacement`` over 0 <= x <= ``footing_b`` (u_y; u_x free: smooth) and loaded by the
surcharge ``confining_pa`` beyond it; ``footing_pressure_pa()`` is the footing's mean pressure
from its reaction. With both
``right_displacement`` and ``top_displacement`` and ``homogeneous=True`` every boundary node
is moved with the homogeneous field, so every element sees the same strain.

Stresses are tension positive here (FEM), Pa. The FEM is serial, or, with ``comm`` (an
mpi4py communicator, ``mpiexec -n N``), split over its ranks with the elements' pool on rank 0
(``pool=None`` on the others; :mod:`femcoupling.fem.mpi_points`): element k is the same place on
any number of ranks.

Records (``out=DIR``), appended and flushed at every accepted step:
- ``elements.h5``: one row per element per step: step, load, element, increment, stress,
  its bootstrap scatter, tangent, contact count, DEM seconds and steps;
- ``fem.xdmf``: the displacement and the elements' stresses per cell, at every step;
- ``steps.csv``: iterations, residual (relative and in Pa), the measured noise, what ended
  the step and its status, and the FEM/DEM time split;
- ``report.md``: the run so far and every warning.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from femcoupling import _dolfinx
from femcoupling._checks import FemInputError
from femcoupling.coupling.handover import HandoverError, spd_floor
from femcoupling.coupling.records import append_rows
from femcoupling.coupling.relaxation import aitken_factor, check_relaxation
from femcoupling.coupling.status import NoiseWarning
from femcoupling.fem.mpi_points import (PointPartition, RootMaterial, StartStress, bcast_from_root,
                                        check_on_root)
from femcoupling.fem.quadrature import (NewtonFailure, NewtonRules, QuadratureSystem,
                                        check_material, lu_package, newton_solve)
from femcoupling.fem.model import FemModel
from femcoupling.fem.steps import LoadStep

__all__ = ["HierarchicalPlaneStrain", "HierStep", "NewtonFailure", "NoiseWarning", "TANGENTS",
           "aitken_factor", "quadrature_points", "secant_update"]

_IX = [0, 2, 4]  # DEM Voigt (xx, yy, zz, yz, xz, xy) rows of the FEM's (xx, yy, xy)


def _rectangle(fx, lx: float, ly: float, nx: int, ny: int, comm=None):
    """The plane-strain model's mesh: [0, lx] x [0, ly] (m) in 2 nx ny triangles, on ``comm``
    (None: serial)."""
    return fx.mesh.create_rectangle(fx.MPI.COMM_SELF if comm is None else comm,
                                    [np.array([0.0, 0.0]), np.array([lx, ly])], [nx, ny],
                                    fx.mesh.CellType.triangle)


def _check_footing(platens: str, footing_b, lx: float, nx: int) -> None:
    """``footing_b`` (m) is given with, and only with, ``platens="footing"``, inside the top
    edge and on one of the mesh's vertical lines (the footing's edge is a node)."""
    if platens != "footing":
        if footing_b is not None:
            raise FemInputError(f"footing_b={footing_b!r}: only with platens='footing'")
        return
    if footing_b is None or not (0 < footing_b < lx and math.isfinite(footing_b)):
        raise FemInputError(f"footing_b={footing_b!r}: the footing's half width, m, "
                            f"0 < footing_b < lx ({lx} m)")
    cells = footing_b * nx / lx
    if abs(cells - round(cells)) > 1e-9 * nx:
        raise FemInputError(f"footing_b={footing_b!r}: must end on a mesh line, a multiple of "
                            f"lx / nx = {lx / nx:g} m (the footing's edge is a node)")


def _qdeg(degree: int) -> int:
    """The quadrature degree of the elements' points: one point (P1) or three (P2)."""
    return 1 if degree == 1 else 2


def _coordinates(fx, mesh, qpoints: np.ndarray) -> np.ndarray:
    """The coordinates (m, shape (points, gdim)) of the reference points ``qpoints`` in every
    cell of ``mesh``, in (cell, point) order: the elements' order."""
    gdim = mesh.geometry.dim
    cells = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local, dtype=np.int32)
    expr = fx.fem.Expression(fx.ufl.SpatialCoordinate(mesh), qpoints)
    return expr.eval(mesh, cells).reshape(-1, gdim)


def quadrature_points(lx: float, ly: float, nx: int, ny: int, degree: int = 1) -> np.ndarray:
    """The coordinates (m, shape (n, 2)) of the quadrature points of a
    ``HierarchicalPlaneStrain(lx=, ly=, nx=, ny=, degree=)``, in its elements' order (element
    k at cell k // nq, point k % nq), without building the model: to choose elements by
    place before the pool is built (a weaker zone:
    ``geogrid_dem.studies.biaxial.WeakZoneFactory``)."""
    import basix

    fx = _dolfinx.load()
    pts, _ = basix.make_quadrature(basix.CellType.triangle, _qdeg(degree))
    return _coordinates(fx, _rectangle(fx, lx, ly, nx, ny), pts)


def dem_increment(g: np.ndarray) -> np.ndarray:
    """The DEM element's 3 x 3 increment from a FEM 2 x 2 displacement-gradient increment:
    FEM (x, y) -> element (x, z); the out-of-plane y is held (plane strain)."""
    de = np.zeros((3, 3))
    de[0, 0], de[0, 2], de[2, 0], de[2, 2] = g[0, 0], g[0, 1], g[1, 0], g[1, 1]
    return de


def fem_stress(s: np.ndarray) -> np.ndarray:
    """FEM Voigt stress (xx, yy, xy), Pa, from the element's 3 x 3 stress."""
    return np.array([s[0, 0], s[2, 2], 0.5 * (s[0, 2] + s[2, 0])])


def voigt_stress(s: np.ndarray) -> np.ndarray:
    """Voigt stress (xx, yy, zz, yz, xz, xy), Pa, from a 3 x 3 stress (its symmetric part)."""
    s = np.asarray(s, float)
    return np.array([s[0, 0], s[1, 1], s[2, 2], 0.5 * (s[1, 2] + s[2, 1]),
                     0.5 * (s[0, 2] + s[2, 0]), 0.5 * (s[0, 1] + s[1, 0])])


def fem_tangent(d6: np.ndarray) -> np.ndarray:
    """FEM 3 x 3 tangent (xx, yy, xy; engineering shear) from the element's 6 x 6 Voigt one."""
    return np.asarray(d6)[np.ix_(_IX, _IX)]


#: The element tangents the FEM's Jacobian can be built from.
TANGENTS = {
    "network": "the contact network's stiffness at the relaxed state: contacts on their "
               "friction cone there slide, the others stick (relaxation leaves few on the "
               "cone, so it is close to the elastic network tangent, and equal to it where "
               "none is)",
    "network-elastic": "the contact network's stiffness with every contact stuck: the "
                       "elastic network tangent",
    "secant": "the network tangent changed (BFGS, rank two) to reproduce the element's "
              "stress increment over the step's strain increment so far: it sees the "
              "sliding of the increment; the network tangent where the increment is zero "
              "or the element gave back energy",
}


def secant_update(tangent: np.ndarray, strain: np.ndarray, stress: np.ndarray,
                  min_eig_fraction: float = 1e-3) -> np.ndarray | None:
    """The FEM tangent (3 x 3, Voigt xx, yy, xy with engineering shear, Pa) changed to map
    the strain increment ``strain`` (3,) onto the stress increment ``stress`` (3,), both
    tension positive: T - (T de)(T de)^T / (de . T de) + ds ds^T / (ds . de) on the
    symmetric, positive part of ``tangent`` (eigenvalues raised to ``min_eig_fraction`` of the
    largest). None where no positive secant exists (ds . de <= 0: the element gave back
    energy) or the increment is zero."""
    try:
        t = spd_floor(tangent, min_eig_fraction, name="secant_update")
    except HandoverError:  # (no positive stiffness at all)
        return None
    td = t @ strain
    curv_t, curv = float(strain @ td), float(stress @ strain)
    if not (curv_t > 0 and curv > 1e-12 * curv_t):
        return None
    return t - np.outer(td, td) / curv_t + np.outer(stress, stress) / curv


@dataclasses.dataclass(frozen=True, kw_only=True)
class HierStep(LoadStep):
    """One accepted load step of the hierarchical models (the Newton fields:
    ``femcoupling.fem.steps.LoadStep``; ``residual`` is relative to the internal force scale,
    ``residual_pa`` is it times the largest element stress: the residual force over the
    square root of the domain's area): the top displacement, the elements' stresses and the
    step's timings."""

    load: float  #: the top's displacement (total since the start), m
    #: the elements' mean Voigt stress (xx, yy, xy; 3D: xx, yy, zz, yz, xz, xy), tension
    #: positive, Pa
    mean_stress: np.ndarray
    element_stresses: np.ndarray  #: (n_cells, ncomp) the element stresses, Pa
    dem_s: float  #: the DEM seconds (sum over the elements' work), s
    fem_s: float  #: the FEM seconds (the step's wall time outside the pool's calls), s
    wall_s: float  #: the step's wall time, s
    recovered: list  #: the elements rebuilt after a lost worker
    increments: np.ndarray  #: (n_cells, 3, 3): each element's increment of the step, -
    #: the noise's residual in Pa (NaN if it was not measured)
    noise_residual_pa: float = float("nan")
    #: (n_cells, 3) each element's stress scatter (xx, yy, xy), Pa: the bootstrap of its
    #: contact network (``DemElement.stress_scatter``), how far a sample of its size is from
    #: the material's mean
    element_scatter: np.ndarray | None = None


def _relative_scatter(r: HierStep) -> float:
    """The elements' mean bootstrap scatter relative to their largest stress component."""
    if r.element_scatter is None:
        return float("nan")
    big = np.abs(r.element_stresses).max(axis=1)
    return float(np.mean(r.element_scatter.max(axis=1) / np.maximum(big, 1e-300)))


class HierarchicalPlaneStrain(FemModel):
    """See the module doc. ``pool``: an ElementPool with one element per cell (cell k ->
    element k). ``newton_rtol``: the residual's tolerance relative to the internal force
    scale, -; ``noise_factor``: with ``convergence="noise"``, a stalled step is accepted
    within this many times the elements' measured noise ...; ``noise_ceiling``: ... and only
    up to this residual (relative, like ``newton_rtol``; default 10 x ``newton_rtol``), above
    which the step is cut."""

    def __init__(self, pool, *, lx: float, ly: float, nx: int, ny: int,
                 confining_pa: float | None = None, homogeneous: bool = False,
                 newton_rtol: float = 1e-3, max_newton: int = 10, strain_kw: dict | None = None,
                 tangent: str = "network", convergence: str = "noise",
                 relaxation: str | float = "aitken", noise_factor: float = 2.0,
                 noise_ceiling: float | None = None, degree: int = 1,
                 platens: str = "smooth", footing_b: float | None = None, comm=None,
                 verbose: bool = False, out=None, overwrite: bool = False) -> None:
        if platens not in ("smooth", "rough", "footing"):
            raise FemInputError(f"platens={platens!r}: 'smooth' (left and bottom on rollers), "
                                "'rough' (bottom held, top without sliding, confining "
                                "pressure on both sides) or 'footing' (a smooth strip footing "
                                "of half width footing_b, the surcharge confining_pa beside it)")
        if platens in ("rough", "footing") and (homogeneous or confining_pa is None):
            raise FemInputError(f"platens={platens!r}: needs confining_pa (Pa; 'rough': on "
                                "both sides, 'footing': the surcharge), and not "
                                "homogeneous=True")
        _check_footing(platens, footing_b, lx, nx)
        self.platens, self.footing_b = platens, footing_b
        if degree not in (1, 2):
            raise FemInputError(f"degree={degree!r}: 1 (P1 triangles, one point each) or 2 (P2 "
                                "triangles, three points each: no volumetric locking)")
        if not (lx > 0 and ly > 0 and math.isfinite(lx) and math.isfinite(ly)):
            raise FemInputError(f"lx={lx}, ly={ly}: must be > 0 (m)")
        if nx < 1 or ny < 1:
            raise FemInputError(f"nx={nx}, ny={ny}: must be >= 1")
        fx = self._fx = _dolfinx.load()
        fem, ufl = fx.fem, fx.ufl

        self.pool, self.lx, self.ly = pool, float(lx), float(ly)
        self.nx, self.ny = nx, ny
        self.comm = comm
        self._options(out=out, overwrite=overwrite, verbose=verbose, tangent=tangent,
                      tangents=tuple(TANGENTS), convergence=convergence, relaxation=relaxation,
                      noise_factor=noise_factor, noise_ceiling=noise_ceiling,
                      newton_rtol=newton_rtol, max_newton=max_newton)
        self.homogeneous = homogeneous
        self.confining_pa = confining_pa
        self.strain_kw = dict(strain_kw or {})
        msh = self.mesh = _rectangle(fx, lx, ly, nx, ny, comm)
        self.n_cells = msh.topology.index_map(2).size_local  # (this rank's)
        nq = 1 if degree == 1 else 3
        self._check_pool(pool, 2 * nx * ny * nq,
                         f"quadrature points (2 nx ny triangles, {nq} point(s) each)")

        def eps(w):
            e = ufl.sym(ufl.grad(w))
            return ufl.as_vector([e[0, 0], e[1, 1], 2 * e[0, 1]])

        fdim = 1
        # the loaded sides: the right (smooth platens), or both (rough: -p n on each), or the
        # top beside the footing (its facets' midpoints beyond footing_b)
        tol_x = 1e-9 * lx
        beside = lambda x: np.isclose(x[1], ly) & (x[0] >= footing_b - tol_x)  # noqa: E731
        loaded = fx.mesh.locate_entities_boundary(
            msh, fdim, {"rough": lambda x: np.isclose(x[0], lx) | np.isclose(x[0], 0.0),
                        "footing": beside}.get(platens, lambda x: np.isclose(x[0], lx)))
        tags = fx.mesh.meshtags(msh, fdim, np.sort(loaded), np.full(len(loaded), 1, np.int32))
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        st = fx.PETSc.ScalarType
        self.traction = fem.Constant(msh, np.zeros(2, dtype=st))
        if platens == "rough":
            self._pressure = fem.Constant(msh, st(float(confining_pa)))
            n_out = ufl.FacetNormal(msh)
            loads = lambda v: (-self._pressure * ufl.dot(n_out, v) * ds(1),)  # noqa: E731
        else:
            loads = lambda v: (ufl.dot(self.traction, v) * ds(1),)  # noqa: E731
        # spaces, forms and solver: the same as the FEM soil's (femcoupling.fem.quadrature)
        sysq = self.system = QuadratureSystem(
            msh, degree=degree, qdeg=_qdeg(degree), ncomp=3, strain=eps,
            loads=loads, lu=lu_package(self.comm, None))
        self.V, self.Wv, self.Wt = sysq.V, sysq.Wv, sysq.Wt
        self.degree = degree
        self._points(nq)
        self.u, self.u_n, self.du = sysq.u, sysq.u_n, sysq.du
        self.sig_q, self.tan_q = sysq.sig_q, sysq.tan_q
        self.expr_grad = fem.Expression(ufl.grad(self.u), sysq.qpoints)
        self.expr_grad_n = fem.Expression(ufl.grad(self.u_n), sysq.qpoints)
        # boundary conditions
        self.top_u = fem.Constant(msh, st(0.0))
        self.right_u = fem.Constant(msh, st(0.0))
        V0, V1 = self.V.sub(0), self.V.sub(1)

        def dofs(sub, where):
            facets = fx.mesh.locate_entities_boundary(msh, fdim, where)
            return fem.locate_dofs_topological(sub, fdim, facets)

        self.bcs = [fem.dirichletbc(st(0.0), dofs(V0, lambda x: np.isclose(x[0], 0.0)), V0),
                    fem.dirichletbc(st(0.0), dofs(V1, lambda x: np.isclose(x[1], 0.0)), V1),
                    fem.dirichletbc(self.top_u, dofs(V1, lambda x: np.isclose(x[1], ly)), V1)]
        if platens == "footing":
            under = lambda x: np.isclose(x[1], ly) & (x[0] <= footing_b + tol_x)  # noqa: E731
            self._footing_dofs = dofs(V1, under)
            self.bcs = [self.bcs[0], self.bcs[1],
                        fem.dirichletbc(self.top_u, self._footing_dofs, V1),
                        fem.dirichletbc(st(0.0), dofs(V0, lambda x: np.isclose(x[0], lx)), V0)]
            self.traction.value[:] = [0.0, -float(confining_pa)]
            self._form_reaction = fem.form(self.system.res)
        elif platens == "rough":
            ends = lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], ly)  # noqa: E731
            self.bcs = [fem.dirichletbc(st(0.0), dofs(V0, ends), V0),
                        fem.dirichletbc(st(0.0), dofs(V1, lambda x: np.isclose(x[1], 0.0)), V1),
                        fem.dirichletbc(self.top_u, dofs(V1, lambda x: np.isclose(x[1], ly)),
                                        V1)]
        elif homogeneous:
            # every boundary node on the homogeneous field u = (e_x x, e_y y)
            self._hx = fem.Function(self.V.sub(0).collapse()[0])
            self._hy = fem.Function(self.V.sub(1).collapse()[0])
            bnd = lambda x: (np.isclose(x[0], 0) | np.isclose(x[0], lx) |  # noqa: E731
                             np.isclose(x[1], 0) | np.isclose(x[1], ly))
            facets = fx.mesh.locate_entities_boundary(msh, fdim, bnd)
            hdofs = [fem.locate_dofs_topological((V0, self._hx.function_space), fdim, facets),
                     fem.locate_dofs_topological((V1, self._hy.function_space), fdim, facets)]
            self.bcs = [fem.dirichletbc(self._hx, hdofs[0], V0),
                        fem.dirichletbc(self._hy, hdofs[1], V1)]
        else:
            self.bcs.append(None)  # placeholder for the right: traction (confining) or u_x
            if confining_pa is None:
                self.bcs[-1] = fem.dirichletbc(self.right_u,
                                               dofs(V0, lambda x: np.isclose(x[0], lx)), V0)
            else:
                self.traction.value[:] = [-float(confining_pa), 0.0]
            self.bcs = [b for b in self.bcs if b is not None]
        #: the elements as the quadrature points' material (femcoupling.fem.quadrature)
        self._material(pool, tangent=tangent, strain_kw=self.strain_kw)

    @property
    def _parallel(self) -> bool:
        """Whether the FEM is split over more than one MPI rank."""
        return self.comm is not None and self.comm.size > 1

    @property
    def _root(self) -> bool:
        """Whether this is the rank that writes the records (rank 0; serial: True)."""
        return self.comm is None or self.comm.rank == 0

    def _check_pool(self, pool, n: int, what: str) -> None:
        """The pool (rank 0's under MPI) holds one element per quadrature point."""
        if self._parallel:
            check_on_root(self.comm, pool)
            have = bcast_from_root(self.comm, pool.n if self._root else None)
        else:
            have = pool.n
        if have != n:
            raise FemInputError(f"pool: has {have} elements for {n} {what}")

    def _serial_mesh(self):
        """The model's mesh on one rank (the elements' numbering: PointPartition)."""
        return _rectangle(self._fx, self.lx, self.ly, self.nx, self.ny)

    def _material(self, pool, **kw) -> None:
        """The elements as the points' material: ``ElementPoolMaterial`` (under MPI on rank 0,
        seen by every rank: ``femcoupling.fem.mpi_points.RootMaterial``)."""
        mat = ElementPoolMaterial(pool, **kw) if pool is not None else None
        if self._parallel:
            mat = RootMaterial(self.comm, mat)
        check_material(mat, "material", "gradient")
        #: the elements as the quadrature points' material (femcoupling.fem.quadrature)
        self.material = mat
        self._set_q(mat.stress, mat.tangent)

    def _options(self, *, out, overwrite: bool, verbose: bool, tangent: str, tangents: tuple,
                 convergence: str, relaxation, noise_factor: float,
                 noise_ceiling: float | None, newton_rtol: float, max_newton: int) -> None:
        """Checks and keeps the options both dimensions share (``out`` cleared of an
        earlier run's records only with ``overwrite``)."""
        self.out = None if out is None else Path(out)
        if self.out is not None:
            old = [f for f in ("elements.h5", "fem.xdmf", "fem.h5", "steps.csv", "report.md")
                   if (self.out / f).exists()]
            if old and not overwrite:
                raise FemInputError(f"out={str(self.out)!r}: holds the records of an earlier "
                                    f"run ({', '.join(old)}); give a new folder, or "
                                    "overwrite=True to replace them")
            if self._root:
                for f in old:
                    (self.out / f).unlink()
            if self._parallel:
                self.comm.barrier()
        self.verbose = verbose
        if tangent not in tangents:
            raise FemInputError(f"tangent={tangent!r}: one of " + "; ".join(
                f"'{k}' ({TANGENTS[k]})" for k in tangents))
        self.tangent = tangent
        if convergence not in ("noise", "tolerance"):
            raise FemInputError(f"convergence={convergence!r}: 'noise' (newton_rtol, or, "
                                "when Newton stalls above it, within the elements' measured "
                                "noise) or 'tolerance' (newton_rtol only)")
        self.convergence = convergence
        self.relaxation = check_relaxation(relaxation)
        if not (noise_factor > 0 and math.isfinite(noise_factor)):
            raise FemInputError(f"noise_factor={noise_factor}: must be > 0 (a stalled step is "
                                "accepted within this many times the noise's residual)")
        if not (newton_rtol > 0 and math.isfinite(newton_rtol)):
            raise FemInputError(f"newton_rtol={newton_rtol!r}: must be > 0 (relative to the "
                                "internal force scale)")
        ceiling = 10.0 * newton_rtol if noise_ceiling is None else noise_ceiling
        if not (math.isfinite(ceiling) and ceiling >= newton_rtol):
            raise FemInputError(f"noise_ceiling={noise_ceiling!r}: must be >= newton_rtol="
                                f"{newton_rtol!r} and finite (the largest residual, relative "
                                "to the internal force scale, a step may be accepted at "
                                "within the elements' noise; default 10 x newton_rtol)")
        self._solver_options(newton_rtol=newton_rtol, max_newton=max_newton,
                             noise_factor=noise_factor, noise_ceiling=ceiling)

    # ---- the elements' material ---------------------------------------------------------
    @property
    def bad_tangents(self) -> int:
        """Element tangents replaced by their last good one (``ElementPoolMaterial``)."""
        return self.material.bad_tangents

    @property
    def secants_used(self) -> int:
        """Element tangents replaced by their secant (tangent="secant")."""
        return self.material.secants_used

    @property
    def _sig(self) -> np.ndarray:
        return self.material.stress

    @property
    def _tan(self) -> np.ndarray:
        return self.material.tangent

    @property
    def _last_pool_step(self):
        return self.material.last_step

    def _points(self, nq: int) -> None:
        """The quadrature points: ``nq`` per cell, element k at cell k // nq, point k % nq (the
        quadrature spaces' own order, checked). Under MPI a rank's points are the elements
        at their places in the serial mesh (``femcoupling.fem.mpi_points.PointPartition``)."""
        if len(self.system.qweights) != nq:
            raise RuntimeError(f"{nq} quadrature point(s) per cell expected")
        self.nq, self.n_local_points = nq, self.n_cells * nq
        if not np.array_equal(self.Wv.dofmap.list[: self.n_cells].reshape(-1),
                              np.arange(self.n_local_points)):
            raise RuntimeError("the quadrature space's points are not in (cell, point) order")
        self.partition = None
        self.n_points = self.n_local_points
        if self._parallel:
            size = max(self.lx, self.ly, getattr(self, "lz", 0.0))
            serial = _coordinates(self._fx, self._serial_mesh(), self.system.qpoints)
            self.partition = PointPartition(self.comm, self._local_coordinates(), serial, size)
            self.n_points = self.partition.n

    def _local(self, values: np.ndarray) -> np.ndarray:
        """This rank's rows of a per-element array (serial: all of it)."""
        return values if self.partition is None else self.partition.local(values)

    def _put(self, f, values: np.ndarray) -> None:
        """A quadrature function ``f`` at this rank's points from a per-element array (its
        ghost points, under MPI, from their owners)."""
        v = np.asarray(self._local(values), float).reshape(-1)
        f.x.array[: v.size] = v
        f.x.scatter_forward()

    def _set_q(self, sig: np.ndarray, tan: np.ndarray) -> None:
        self._put(self.sig_q, sig)
        self._put(self.tan_q, tan)

    comm = None  #: the FEM's MPI communicator (None: serial)
    partition = None  #: each rank's points as elements under MPI (mpi_points.PointPartition)
    gdim = 2  #: the FEM's dimension
    degree = 1  #: the displacement's degree (``Hierarchical3D``: P1)

    def _local_coordinates(self) -> np.ndarray:
        return _coordinates(self._fx, self.mesh, self.system.qpoints)

    @property
    def point_coordinates(self) -> np.ndarray:
        """The quadrature points' coordinates, m, shape (n_points, gdim), in element order (on
        every rank)."""
        x = self._local_coordinates()
        return x if self.partition is None else self.partition.gather(x)

    def _grad_increment(self) -> np.ndarray:
        """Every element's displacement-gradient increment since the step's start (under MPI
        gathered from the ranks, on every rank), (n_points, gdim, gdim), -."""
        cells = np.arange(self.n_cells, dtype=np.int32)
        d = self.gdim
        g = self.expr_grad.eval(self.mesh, cells).reshape(-1, d, d)
        gn = self.expr_grad_n.eval(self.mesh, cells).reshape(-1, d, d)
        return g - gn if self.partition is None else self.partition.gather(g - gn)

    def _evaluate(self, first: bool, perturb: float = 0.0) -> None:
        """Stress and tangent of every element for the current iterate (its increments
        scaled by 1 + ``perturb``: the noise probe)."""
        g = self._grad_increment()
        self._set_q(*self.material.trial(g * (1.0 + perturb) if perturb else g))

    def _softest(self, n: int = 3) -> str:
        """The ``n`` elements of the current iterate with the smallest tangent eigenvalue:
        index, that eigenvalue (Pa), contacts and mean stress (Pa)."""
        ev = np.array([np.linalg.eigvalsh(0.5 * (c + c.T))[0] for c in self._tan])
        contacts = self._last_pool_step.contacts
        return "; ".join(f"element {k}: smallest tangent eigenvalue {ev[k]:.3g} Pa, "
                         f"{contacts[k]} contacts, mean stress {self._sig[k][:2].mean():.4g} Pa"
                         for k in np.argsort(ev)[:n])

    @property
    def _warns_here(self) -> bool:
        return self._root

    def _scale_length(self) -> float:
        """The force scale over the largest stress: the square root of the domain's area, m
        (3D: its volume to the power 2/3, m^2)."""
        return math.sqrt(self.lx * self.ly)

    def _scale(self) -> float:
        """|F_int| of the current stresses (the tolerance's scale)."""
        return float(np.abs(self._sig).max()) * self._scale_length() + 1e-300

    # ---- a load step -----------------------------------------------------------------------
    def step(self, *, top_displacement: float, right_displacement: float = 0.0,
             max_cuts: int = 4) -> HierStep:
        """One load step to the given boundary displacements (m, total since the start). If
        Newton fails, the step is rolled back (the elements to their accepted state, u to
        u_n) and halved, at most ``max_cuts`` times below the whole step
        (``femcoupling.fem.steps.load_path``, the loop of every model: an easy half-step
        grows the next back); the last accepted step's record is returned (all of them are
        in ``history``). Past ``max_cuts``, the model is left at its last accepted step and
        :class:`NewtonFailure` says where the load stopped."""
        return self._cut_steps(self._bc_now, (top_displacement, right_displacement), max_cuts,
                               lambda p: self._step(float(p[0]), float(p[1])))

    def _cut_steps(self, now, target, max_cuts: int, go) -> HierStep:
        """The load from the accepted ``now`` to ``target`` (the boundary values: a tuple or
        an array) by ``go(point)`` (solves and commits a step to ``point``, or raises
        NewtonFailure), through ``load_path``: ``point`` is ``target`` itself at the end, else
        ``now + lf (target - now)``."""
        a, b = np.asarray(now, float), np.asarray(target, float)

        def at(lf: float):
            return target if lf == 1.0 else a + lf * (b - a)

        return self._load(lambda lf: go(at(lf)), lambda lf: self._restore(at(lf)), steps=1,
                          max_cuts=max_cuts, where=f"load step {len(self.history)}")[-1]

    def _restore(self, point) -> None:
        """The boundary back at ``point`` (the last accepted step's) after a failed load."""
        self._set_boundary(float(point[0]), float(point[1]))

    _bc_now = (0.0, 0.0)  # the boundary displacements of the last accepted step, m

    def _reject_points(self) -> None:
        """The elements back at their accepted state (``FemModel._rollback``)."""
        self.material.reject()

    def footing_pressure_pa(self) -> float:
        """The footing's mean pressure, Pa, compression positive (``platens="footing"``): the
        reaction at its vertical displacement dofs (the internal force of the points' current
        stresses less the surcharge's share of the edge node) over its half width
        (``QuadratureSystem.reaction``: ``SoilModel.footing_pressure_pa`` sums the same way)."""
        self._check_footing_platens("footing_pressure_pa")
        total = self.system.reaction(self._form_reaction, self._footing_dofs,
                                     self.comm if self._parallel else None)
        return -total / self.footing_b

    def footing_settlement_m(self) -> float:
        """The footing's settlement, m, positive down (``platens="footing"``): its imposed
        vertical displacement (every footing node moves with it), as
        ``SoilModel.footing_settlement_m``."""
        self._check_footing_platens("footing_settlement_m")
        return -float(self.top_u.value)

    def _check_footing_platens(self, what: str) -> None:
        if self.platens != "footing":
            raise FemInputError(f"{what}(): only with platens='footing' (this model's "
                                f"platens={self.platens!r})")

    def _set_boundary(self, top_displacement: float, right_displacement: float) -> None:
        if self.platens == "footing" and right_displacement != 0.0:
            raise FemInputError(f"right_displacement={right_displacement!r}: the footing's "
                                "right side is on rollers (0 only)")
        self.top_u.value = top_displacement
        self.right_u.value = right_displacement
        if self.homogeneous:
            ex, ey = right_displacement / self.lx, top_displacement / self.ly
            self._hx.interpolate(lambda x: ex * x[0])
            self._hy.interpolate(lambda x: ey * x[1])

    def _step(self, top_displacement: float, right_displacement: float) -> HierStep:
        t0 = time.perf_counter()
        self._set_boundary(top_displacement, right_displacement)
        mat = self.material
        mat.new_step_counters()
        rules = NewtonRules(rtol=self.newton_rtol, max_newton=self.max_newton,
                            noise_factor=self.noise_factor, ceiling=self.noise_ceiling,
                            probe=self.convergence == "noise")
        log = ((lambda msg: print(f"[hier] {msg}", flush=True))
               if self.verbose and self._root else None)
        out = newton_solve(_HierNewton(self), rules, relaxation=self.relaxation, log=log)
        rel, noise_rel, its = out.residual, out.noise_residual, out.iterations
        stress_of_scale = out.scale / self._scale_length()  # Pa: the largest stress
        if out.converged_on == "noise":
            self._warn(f"load step {len(self.history)} (top {top_displacement:.6g} m): the "
                       f"tolerance asked (newton_rtol={self.newton_rtol:g}) is below the "
                       f"elements' noise (a 1e-9 change of their increments moves the "
                       f"residual by {noise_rel:.3g} of the internal force scale); stopped "
                       f"at the noise at {rel:.3g} ({rel * stress_of_scale:.3g} Pa; ceiling "
                       f"{self.noise_ceiling:g}): stopped_at_scatter, not converged")
        mat.commit()
        self._bc_now = (top_displacement, right_displacement)
        self.u_n.x.array[:] = self.u.x.array
        wall = time.perf_counter() - t0
        r = HierStep(load=top_displacement, newton_iterations=its, residual=rel,
                     mean_stress=self._sig.mean(axis=0), element_stresses=self._sig.copy(),
                     dem_s=mat.step_dem_s, fem_s=wall - mat.step_pool_s, wall_s=wall,
                     recovered=mat.step_recovered, increments=mat.increments.copy(),
                     noise_residual=noise_rel, converged_on=out.converged_on,
                     relaxation=out.relaxation, redraws=out.redraws,
                     element_scatter=mat.scatter.copy(),
                     status=out.status, residual_pa=rel * stress_of_scale,
                     noise_residual_pa=noise_rel * stress_of_scale)
        self.history.append(r)
        if self.out is not None:
            self._write_records(r)
        return r


    # ---- records -----------------------------------------------------------------------------
    def _write_records(self, r: HierStep) -> None:
        """Appends the accepted step to ``out``: one row per element in ``elements.h5`` (the
        step, its load, the element, its displacement-gradient increment, stress (tension
        positive, Pa), its bootstrap scatter (Pa), tangent (Voigt 6 x 6, Pa), contact count,
        DEM seconds and steps),
        flushed; the FEM state in ``fem.xdmf`` (displacement m, the elements' stress Pa per
        cell, at the load as time); and a line of ``steps.csv`` with the FEM/DEM time split."""
        k = len(self.history) - 1
        if self._root:
            self.out.mkdir(parents=True, exist_ok=True)
        if self._parallel:
            self.comm.barrier()
        self._write_xdmf(r, append=k > 0)  # (collective under MPI)
        if not self._root:
            return
        ps = self._last_pool_step
        n = self.n_points
        rows = {
            "step": np.full(n, k, dtype=np.int64),
            "load_m": np.full(n, r.load),
            "element": np.arange(n, dtype=np.int64),
            "increment": np.asarray(r.increments, float).reshape(n, 3, 3),
            "stress_pa": np.asarray(ps.stresses, float).reshape(n, 3, 3),
            "tangent_pa": np.array([np.full((6, 6), np.nan) if t is None else t
                                    for t in ps.tangents], float).reshape(n, 6, 6),
            "scatter_pa": np.asarray(ps.scatters, float).reshape(n, 3, 3),
            "contacts": np.asarray(ps.contacts, dtype=np.int64),
            "cpu_s": np.asarray(ps.cpu_s, float),
            "dem_steps": np.asarray(ps.steps, dtype=np.int64),
        }
        append_rows(self.out / "elements.h5", rows,
                    units=("SI; stress tension positive; increment: displacement-gradient "
                           "increment of the step, the element's (x, y, z) with the FEM's "
                           "(x, y) as (x, z)"))
        csv = self.out / "steps.csv"
        new = not csv.exists()
        with open(csv, "a") as fh:
            if new:
                fh.write("step,load_m,iterations,residual,noise_residual,converged_on,"
                         "relaxation_min,fem_s,dem_s,wall_s,recovered,bad_tangents,status,"
                         "residual_pa,noise_residual_pa\n")
            fh.write(f"{k},{r.load!r},{r.newton_iterations},{r.residual!r},{r.noise_residual!r},"
                     f"{r.converged_on},{min(r.relaxation, default=1.0)!r},{r.fem_s!r},"
                     f"{r.dem_s!r},{r.wall_s!r},{len(r.recovered)},{self.bad_tangents},"
                     f"{r.status},{r.residual_pa!r},{r.noise_residual_pa!r}\n")
        self._write_report()

    def _write_report(self) -> None:
        """``report.md``: the run so far: per load step the Newton iterations, residual,
        noise and what converged it, and the elements' scatter; the FEM/DEM CPU split; and
        every warning. Rewritten
        at every accepted step."""
        h = self.history
        fem_s = sum(r.fem_s for r in h)
        dem_s = sum(r.dem_s for r in h)
        wall_s = sum(r.wall_s for r in h)
        lines = ["# Hierarchical FEM x DEM run", "",
                 f"- status: **{self.status}** (the worst of the steps'; converged: every "
                 f"step's residual within newton_rtol; stopped_at_scatter: a step accepted "
                 f"within the elements' noise, above newton_rtol)",
                 f"- {self.n_points} elements, {len(h)} load steps accepted; tangent "
                 f"`{self.tangent}`, convergence `{self.convergence}` (newton_rtol "
                 f"{self.newton_rtol:g}, noise factor {self.noise_factor:g}, noise ceiling "
                 f"{self.noise_ceiling:g}), relaxation `{self.relaxation}`",
                 f"- CPU: FEM {fem_s:.2f} s (the wall time outside the element calls), DEM "
                 f"{dem_s:.2f} s (the elements' work summed over workers), wall {wall_s:.2f} s"
                 f"; DEM share of the work {dem_s / max(fem_s + dem_s, 1e-300):.1%}",
                 f"- element tangents replaced by their last good one: {self.bad_tangents}",
                 "- element scatter: the bootstrap standard deviation of each element's "
                 "stress over its contacts, as a fraction of its largest stress component, "
                 "mean over the elements",
                 "", "| step | top, m | iterations | residual | residual, Pa | noise residual "
                 "| status | converged on | min relaxation | mean sigma_xx, kPa | mean "
                 "sigma_yy, kPa | element scatter |",
                 "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for k, r in enumerate(h):
            lines.append(f"| {k} | {r.load:.6g} | {r.newton_iterations} | {r.residual:.3g} | "
                         f"{r.residual_pa:.3g} | {r.noise_residual:.3g} | {r.status} | "
                         f"{r.converged_on} | "
                         f"{min(r.relaxation, default=1.0):.3g} | "
                         f"{r.mean_stress[0] / 1e3:.2f} | {r.mean_stress[1] / 1e3:.2f} | "
                         f"{_relative_scatter(r):.3f} |")
        lines += ["", f"## Warnings ({len(self.warnings)})", ""]
        lines += [f"- {w}" for w in self.warnings] or ["none"]
        (self.out / "report.md").write_text("\n".join(lines) + "\n")

    def _write_xdmf(self, r: HierStep, append: bool) -> None:
        fx = self._fx
        fem = fx.fem
        import dolfinx.io

        T = fem.functionspace(self.mesh, ("DG", 0, (3, 3)))
        sig = fem.Function(T, name="stress_pa")
        st = self._local(np.asarray(self._last_pool_step.stresses, float))
        st = st.reshape(self.n_cells, self.nq, 9)
        st = st[:, 0] if self.nq == 1 else st.mean(axis=1)  # (a cell's points: their mean)
        sig.x.array[: st.size] = st.reshape(-1)  # (the owned cells; ghosts from their owners)
        sig.x.scatter_forward()
        u = self.u
        if self.degree != 1:  # XDMF holds the mesh's degree: P2 at the vertices (P1)
            if not hasattr(self, "_u_out"):
                self._u_out = fem.Function(fem.functionspace(self.mesh, ("Lagrange", 1,
                                                                         (self.gdim,))))
            self._u_out.interpolate(self.u)
            u = self._u_out
        u.name = "displacement_m"
        with dolfinx.io.XDMFFile(self.mesh.comm, str(self.out / "fem.xdmf"),
                                 "a" if append else "w") as xf:
            if not append:
                xf.write_mesh(self.mesh)
            xf.write_function(u, r.load)
            xf.write_function(sig, r.load)

class _HierNewton:
    """``HierarchicalPlaneStrain`` as ``femcoupling.fem.quadrature.newton_solve``'s problem."""

    def __init__(self, m: "HierarchicalPlaneStrain") -> None:
        self.m = m

    def evaluate(self, first: bool, perturb: float = 0.0) -> None:
        self.m._evaluate(first, perturb)

    def residual(self) -> float:
        return self.m.system.residual(self.m.bcs)

    def force_scale(self) -> float:
        return self.m._scale()

    def at_boundary_values(self) -> bool:
        return self.m.system.at_boundary_values(self.m.bcs)

    noise_scale = force_scale  # (every point is a DEM element)

    def stresses(self) -> np.ndarray:
        return self.m._sig.copy()

    def stress_change_residual(self, before: np.ndarray) -> float:
        return self.m.system.change_residual(self.m._sig - before, self.m.bcs, self.m._put)

    def correction(self) -> np.ndarray:
        return self.m.system.correction(self.m.bcs, describe=lambda: (
            f"softening elements whose tangents lost stiffness; the softest elements: "
            f"{self.m._softest()}"))

    def move(self, correction: np.ndarray, factor: float) -> None:
        self.m.system.move(correction, factor)


class ElementPoolMaterial(StartStress):
    """The DEM elements of an ``ElementPool`` as the material of the hierarchical mode's
    quadrature points (a ``femcoupling.fem.quadrature.QuadratureMaterial``; element k is point k).

    ``trial(g)``: ``g`` (n, 2, 2) the displacement-gradient increments since the last commit
    (shear and rotation included; FEM (x, y) is the element's (x, z), its y held: plane
    strain); every element, restored to its committed state if an earlier trial moved it
    (``pool.reject``: a rejected iterate leaves no trace), takes its increment and returns
    its stress and ``tangent``; returns the FEM Voigt stresses (n, 3), Pa, tension positive,
    and tangents (n, 3, 3: xx, yy, xy with engineering shear), Pa. A tangent far from
    positive (its smallest eigenvalue below -10 % of its largest) or not finite is not a
    softening element but a near-singular network solve (seen as -730 MPa against +3 MPa, it
    sent Newton away): such an element keeps its last good tangent for the iterate
    (``bad_tangents`` counts them). With tangent="secant" the network tangent is changed to
    map the increment onto the stress increment (``secant_update``; ``secants_used``).
    ``commit`` accepts (``pool.accept``: the states saved on the workers); ``state`` and
    ``set_state`` are the pool's accepted states (bytes per element) with the committed
    stresses and tangents. Its ``strain_measure`` is "gradient"; ``stress_n`` the committed
    stresses; ``plastic`` 0 (an element's plasticity is in its contacts)."""

    strain_measure = "gradient"

    def __init__(self, pool, *, tangent: str = "network", strain_kw: dict | None = None,
                 dim: int = 2) -> None:
        from cpp_dem.elements.pool import ElementError

        if dim not in (2, 3) or (dim == 3 and tangent == "secant"):
            raise FemInputError(f"dim={dim!r}, tangent={tangent!r}: dim 2 (plane strain) or 3; "
                                "the secant tangent in 2D only")
        self.dim = dim
        self._element_error = ElementError
        self.pool, self.tangent_kind = pool, tangent
        self.strain_kw = dict(strain_kw or {})
        #: what the elements are asked for (the secant is built here from the network one)
        self._element_tangent = "network" if tangent == "secant" else tangent
        self.bad_tangents = 0
        self.secants_used = 0
        self.tangent = None
        first = pool.apply_strain([np.zeros((3, 3))] * pool.n, tangent=self._element_tangent,
                                  **self.strain_kw)
        pool.reject()  # (a zero increment with relaxation: measured, then undone)
        self._pending = False
        self.increments = np.zeros((pool.n, 3, 3))
        self.stress, self.tangent = self._fem_answers(first.stresses, first.tangents)
        self.stress_start = self.stress.copy()  # the element stresses at the step's start
        self.last_step = first
        self.scatter = None
        self.new_step_counters()

    def new_step_counters(self) -> None:
        """Zero the step's DEM seconds, pool seconds and recovered elements."""
        self.step_dem_s = self.step_pool_s = 0.0
        self.step_recovered: list = []

    def _fem_answers(self, stresses, tangents) -> tuple[np.ndarray, np.ndarray]:
        if self.dim == 3:  # (the element's own Voigt order and engineering shear)
            sig = np.array([voigt_stress(s) for s in stresses])
            tan = np.array([np.asarray(t, float) for t in tangents])
        else:
            sig = np.array([fem_stress(s) for s in stresses])
            tan = np.array([fem_tangent(t) for t in tangents])
        if self.tangent_kind == "secant":  # (the first call's increments are zero)
            for k, g in enumerate(self.increments):
                de = np.array([g[0, 0], g[2, 2], g[0, 2] + g[2, 0]])  # (FEM x, y = DEM x, z)
                if np.any(de != 0):
                    c = secant_update(tan[k], de, sig[k] - self.stress_start[k])
                    if c is not None:
                        tan[k] = c
                        self.secants_used += 1
        last = self.tangent
        for k, c in enumerate(tan):
            ok = bool(np.all(np.isfinite(c)))
            if ok:
                ev = np.linalg.eigvalsh(0.5 * (c + c.T))
                ok = ev[0] >= -0.1 * ev[-1]
            if not ok and last is not None:
                tan[k] = last[k]
                self.bad_tangents += 1
        return sig, tan

    def trial(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._pending:
            self.pool.reject()
        self.increments = (np.array(g, float) if self.dim == 3 else
                           np.array([dem_increment(x) for x in g]))
        self._pending = True
        try:
            step = self.pool.apply_strain(list(self.increments), tangent=self._element_tangent,
                                          scatter=True, **self.strain_kw)
        except self._element_error as e:  # an element could not take this iterate: cut
            raise NewtonFailure(f"an element failed on this iterate: {e}") from e
        self.stress, self.tangent = self._fem_answers(step.stresses, step.tangents)
        to_fem = voigt_stress if self.dim == 3 else fem_stress
        self.scatter = (None if step.scatters is None else
                        np.array([to_fem(c) for c in step.scatters]))
        self.last_step = step
        self.step_dem_s += float(sum(step.cpu_s))
        self.step_pool_s += step.wall_s
        self.step_recovered = self.step_recovered + step.recovered
        return self.stress, self.tangent

    def reject(self) -> None:
        """Back to the committed state (the last trial leaves no trace)."""
        self.pool.reject()
        self._pending = False

    def commit(self) -> None:
        self.pool.accept()
        self._pending = False
        self.stress_start = self.stress.copy()

    def state(self) -> tuple:
        """The pool's accepted states (bytes per element), the committed stresses and
        tangents."""
        return self.pool.states(), self.stress_start.copy(), self.tangent.copy()

    def set_state(self, data) -> None:
        """Back to a ``state()``: the elements, their stresses and tangents."""
        states, stress, tangent = data
        self.pool.load_states(states)
        self._pending = False
        self.stress_start = np.array(stress, float)
        self.stress, self.tangent = self.stress_start.copy(), np.array(tangent, float)
