"""Hierarchical FEM x DEM in 3D: a periodic DEM element at the quadrature point of every
tetrahedron (docs/multiscale.md, "Hierarchical mode in 3D").

The FEM is a box ``lx`` x ``ly`` x ``lz`` (m) of P1 tetrahedra (dolfinx's ``create_box``: six
per hexahedron of an ``nx`` x ``ny`` x ``nz`` grid), one quadrature point each; the pool's
element k is cell k. Everything else is the plane-strain mode's
(:class:`femcoupling.hierarchical.HierarchicalPlaneStrain`): the elements as the points'
material (``ElementPoolMaterial(dim=3)``: each element takes the full displacement-gradient
increment of its point, rotation included, and returns its stress and tangent in its own
Voigt order xx, yy, zz, yz, xz, xy with engineering shear), Newton and its acceptance
(``femcoupling.quadrature.newton_solve``), step cuts, records (``out=``) and statuses.

Loading (``step``):

- ``homogeneous=True``: every boundary node on u = G x, G the total displacement gradient
  (3 x 3, -) given to ``step(gradient=G)``: every element sees the same increment (a
  verification: a homogeneous field gives the element's own response);
- otherwise a triaxial test: u_x = 0 on x = 0, u_y = 0 on y = 0, u_z = 0 on z = 0, the top
  z = lz moved by ``step(top_displacement=)`` (u_z, m), and the faces x = lx and y = ly loaded
  by ``confining_pa`` (Pa, compression positive).

The force scale of the tolerance is the largest element stress times the box's volume to the
power 2/3. Stresses are tension positive, Pa. The FEM is serial, or split over the ranks of
``comm`` with the elements' pool on rank 0 (as the plane-strain mode's;
:mod:`femcoupling.mpi_points`). The secant tangent is plane strain only.
"""

from __future__ import annotations

import math

import numpy as np

from femcoupling import _dolfinx
from femcoupling.geometry import FemInputError
from femcoupling.hierarchical import HierarchicalPlaneStrain
from femcoupling.quadrature import QuadratureSystem

__all__ = ["Hierarchical3D"]


class Hierarchical3D(HierarchicalPlaneStrain):
    """See the module doc. ``pool``: an ElementPool with one element per tetrahedron
    (6 nx ny nz); the other arguments as ``HierarchicalPlaneStrain``'s."""

    gdim = 3

    def __init__(self, pool, *, lx: float, ly: float, lz: float, nx: int, ny: int, nz: int,
                 homogeneous: bool = False, confining_pa: float | None = None,
                 newton_rtol: float = 1e-3, max_newton: int = 10,
                 strain_kw: dict | None = None, tangent: str = "network",
                 convergence: str = "noise", relaxation: str | float = "aitken",
                 noise_factor: float = 2.0, noise_ceiling: float | None = None, comm=None,
                 verbose: bool = False, out=None, overwrite: bool = False) -> None:
        for name, v in (("lx", lx), ("ly", ly), ("lz", lz)):
            if not (math.isfinite(v) and v > 0):
                raise FemInputError(f"{name}={v!r}: must be > 0 (m)")
        for name, v in (("nx", nx), ("ny", ny), ("nz", nz)):
            if not (isinstance(v, int) and v >= 1):
                raise FemInputError(f"{name}={v!r}: must be an integer >= 1")
        if not homogeneous and confining_pa is None:
            raise FemInputError("confining_pa=None: a triaxial test needs the confining "
                                "pressure (Pa, compression positive), or homogeneous=True")
        fx = self._fx = _dolfinx.load()
        fem, ufl = fx.fem, fx.ufl
        self.pool, self.lx, self.ly, self.lz = pool, float(lx), float(ly), float(lz)
        self.nx, self.ny, self.nz = nx, ny, nz
        self.comm = comm
        self._options(out=out, overwrite=overwrite, verbose=verbose, tangent=tangent,
                      tangents=("network", "network-elastic"), convergence=convergence,
                      relaxation=relaxation, noise_factor=noise_factor,
                      noise_ceiling=noise_ceiling, newton_rtol=newton_rtol)
        self.homogeneous, self.confining_pa = homogeneous, confining_pa
        self.newton_rtol, self.max_newton = newton_rtol, max_newton
        self.strain_kw = dict(strain_kw or {})
        msh = self.mesh = self._box(comm)
        self.n_cells = msh.topology.index_map(3).size_local  # (this rank's)
        self._check_pool(pool, 6 * nx * ny * nz, "cells (6 nx ny nz tetrahedra)")

        def eps(w):  # Voigt xx, yy, zz, yz, xz, xy with engineering shear (the element's)
            e = ufl.sym(ufl.grad(w))
            return ufl.as_vector([e[0, 0], e[1, 1], e[2, 2], 2 * e[1, 2], 2 * e[0, 2],
                                  2 * e[0, 1]])

        fdim = 2
        st = fx.PETSc.ScalarType
        at = lambda c, v: (lambda x: np.isclose(x[c], v))  # noqa: E731
        right = np.sort(fx.mesh.locate_entities_boundary(msh, fdim, at(0, lx)))
        back = np.sort(fx.mesh.locate_entities_boundary(msh, fdim, at(1, ly)))
        both = np.concatenate([right, back])
        order = np.argsort(both, kind="stable")
        tags = fx.mesh.meshtags(msh, fdim, both[order], np.concatenate(
            [np.full(len(right), 1, np.int32), np.full(len(back), 2, np.int32)])[order])
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        self.traction_x = fem.Constant(msh, np.zeros(3, dtype=st))
        self.traction_y = fem.Constant(msh, np.zeros(3, dtype=st))
        sysq = self.system = QuadratureSystem(
            msh, degree=1, qdeg=1, ncomp=6, strain=eps,
            loads=lambda v: (ufl.dot(self.traction_x, v) * ds(1),
                             ufl.dot(self.traction_y, v) * ds(2)),
            lu="mumps" if self._parallel else None)
        self.V, self.Wv, self.Wt = sysq.V, sysq.Wv, sysq.Wt
        self._points(1)
        self.u, self.u_n, self.du = sysq.u, sysq.u_n, sysq.du
        self.sig_q, self.tan_q = sysq.sig_q, sysq.tan_q
        self.expr_grad = fem.Expression(ufl.grad(self.u), sysq.qpoints)
        self.expr_grad_n = fem.Expression(ufl.grad(self.u_n), sysq.qpoints)
        self.top_u = fem.Constant(msh, st(0.0))
        if homogeneous:
            self._h = fem.Function(self.V)
            facets = fx.mesh.locate_entities_boundary(
                msh, fdim, lambda x: np.ones(x.shape[1], dtype=bool))
            self.bcs = [fem.dirichletbc(self._h, fem.locate_dofs_topological(
                self.V, fdim, facets))]
        else:
            def fixed(c, where):
                sub = self.V.sub(c)
                dofs = fem.locate_dofs_topological(
                    sub, fdim, fx.mesh.locate_entities_boundary(msh, fdim, where))
                return dofs, sub

            self.bcs = [fem.dirichletbc(st(0.0), *fixed(0, at(0, 0.0))),
                        fem.dirichletbc(st(0.0), *fixed(1, at(1, 0.0))),
                        fem.dirichletbc(st(0.0), *fixed(2, at(2, 0.0))),
                        fem.dirichletbc(self.top_u, *fixed(2, at(2, lz)))]
            p = float(confining_pa)
            self.traction_x.value[:] = [-p, 0.0, 0.0]
            self.traction_y.value[:] = [0.0, -p, 0.0]
        self.history = []
        self._material(pool, tangent=tangent, strain_kw=self.strain_kw, dim=3)
        self._gradient = np.zeros((3, 3))

    def _box(self, comm=None):
        """The box of tetrahedra on ``comm`` (None: serial)."""
        fx = self._fx
        return fx.mesh.create_box(fx.MPI.COMM_SELF if comm is None else comm,
                                  [np.zeros(3), np.array([self.lx, self.ly, self.lz])],
                                  [self.nx, self.ny, self.nz], fx.mesh.CellType.tetrahedron)

    _serial_mesh = _box

    def _scale_length(self) -> float:
        return (self.lx * self.ly * self.lz) ** (2.0 / 3.0)

    def step(self, *, gradient=None, top_displacement: float | None = None,
             max_cuts: int = 4):
        """One load step: ``gradient`` (3 x 3, -, total since the start: the homogeneous
        mode's u = G x) or ``top_displacement`` (m, total: the triaxial test's top u_z). A
        step Newton fails is rolled back and taken in two halves, at most ``max_cuts`` times
        deep; returns the last half-step's ``HierStep`` (all are in ``history``; its ``load``
        is G_zz, or the top displacement)."""
        if self.homogeneous:
            if gradient is None or top_displacement is not None:
                raise FemInputError("step: the homogeneous mode takes gradient= (3 x 3) only")
            g = np.asarray(gradient, float)
            if g.shape != (3, 3) or not np.all(np.isfinite(g)):
                raise FemInputError(f"gradient: shape {g.shape}; a finite 3 x 3 displacement "
                                    "gradient expected")
            target = g
        else:
            if top_displacement is None or gradient is not None:
                raise FemInputError("step: the triaxial test takes top_displacement= only")
            target = float(top_displacement)
        return self._cut_steps(target, max_cuts)

    def _cut_steps(self, target, max_cuts: int):
        from femcoupling.quadrature import NewtonFailure

        try:
            return self._step_to(target)
        except NewtonFailure:
            if max_cuts <= 0:
                raise
            self._rollback()
            now = self._gradient if self.homogeneous else self._bc_now[0]
            self._cut_steps(0.5 * (now + target), max_cuts - 1)
            return self._cut_steps(target, max_cuts - 1)

    def _step_to(self, target):
        if self.homogeneous:
            self._pending_gradient = np.array(target, float)
            r = self._step(float(target[2, 2]), 0.0)
            self._gradient = self._pending_gradient
            return r
        return self._step(float(target), 0.0)

    def _set_boundary(self, top_displacement: float, right_displacement: float) -> None:
        if self.homogeneous:
            g = self._pending_gradient
            self._h.interpolate(lambda x: g @ x)
        else:
            self.top_u.value = top_displacement
