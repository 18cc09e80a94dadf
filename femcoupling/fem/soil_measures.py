"""What :class:`femcoupling.fem.model.FemModel` gives out: the footing's settlement and
pressure, region and point stresses (NumPy 3 x 3, tension positive, the same on every MPI
rank), layer forces, and the XDMF output. A part of ``FemModel`` for the soil body."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from femcoupling._checks import FemInputError, _real, _whole
from femcoupling.fem import geometry as geo
from femcoupling.fem.quadrature import lu_options
from femcoupling.fem.solver import SOIL_ONLY, body_kind
from femcoupling.materials.continuum import mandel_to_tensor

_counter = itertools.count()


@body_kind("soil", SOIL_ONLY)
class SoilMeasures:
    """See the module doc."""

    def footing_settlement_m(self) -> float:
        """Mean downward displacement of the footing, m."""
        s = self._fx.fem.assemble_scalar(self.form_settle)
        return float(self.comm.allreduce(s, op=self._fx.MPI.SUM) / self.footing_area)

    def footing_pressure_pa(self) -> float:
        """Mean footing pressure, Pa, compression positive: from the reaction at the footing's
        constrained dofs in displacement control, the applied traction otherwise."""
        if not self._displacement_control:
            return float(-self.traction.value[self.zc])
        f = self.system.reaction(self.form_react, self.footing_dofs, self.comm)
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
        positive; over the cells whose centre lies in ``x_range_m`` (m, (low, high), low <
        high) if given. A layer the body does not have, or a range with none of the layer's
        cells, raises FemInputError."""
        n = len(self.body.layers)
        if n == 0:
            raise FemInputError(f"i={i!r}: the body has no geogrid layers")
        _whole("i", i, 0, n - 1, f"the index of one of the body's {n} geogrid layers")
        if x_range_m is not None:
            try:
                lo_hi = () if isinstance(x_range_m, str) else tuple(x_range_m)
            except TypeError:
                lo_hi = ()
            if len(lo_hi) != 2:
                raise FemInputError(f"x_range_m={x_range_m!r}: must be (low, high), m")
            lo, hi = _real("x_range_m[0]", lo_hi[0]), _real("x_range_m[1]", lo_hi[1])
            if not lo < hi:
                raise FemInputError(f"x_range_m={x_range_m!r}: must be (low, high) with "
                                    "low < high, m")
        tag = geo.LAYER_TAG0 + i
        sel = self.cell_tag_of[: self.n_owned] == tag
        if x_range_m is not None:
            xc = self._cell_centres()[: self.n_owned, 0]
            sel &= (xc >= x_range_m[0]) & (xc <= x_range_m[1])
        cm = self.cell_mean_stress()[: self.n_owned][sel, 0]
        vol = self.cell_volume[: self.n_owned][sel]
        MPI = self._fx.MPI
        s = self.comm.allreduce(np.array([(cm * vol).sum(), vol.sum()]), op=MPI.SUM)
        if not s[1] > 0:
            lay = self.body.layers[i]
            raise FemInputError(f"x_range_m={x_range_m!r}: no cell of geogrid layer {i} (x "
                                f"from {lay.x_min_m:g} to {lay.x_max_m:g} m) has its centre "
                                "in it" if x_range_m is not None else
                                f"i={i!r}: geogrid layer {i} has no cells")
        return float(s[0] / s[1] * self.body.layers[i].thickness_m)

    def region_layer_force(self, name: str) -> float | None:
        """The geogrid tension across the element region ``name``, N/m, tension positive: the
        mean axial force per metre width of the layers that cross it
        (``ReinforcedSoilBody.region_layers``) over the region's x extent, summed over them;
        None where no layer crosses the region. The two-way coupling hands it to the DEM
        element's grid ends (``WallTargets.grid_tension_n_per_m``)."""
        layers = self.body.region_layers(name)
        if not layers:
            return None
        reg = self.body.region(name)
        x = reg.center_m[0]
        xr = (x - reg.size_m / 2, x + reg.size_m / 2)
        return float(sum(self.layer_force_n_per_m(i, x_range_m=xr) for i in layers))

    def _cell_centres(self) -> np.ndarray:
        g = self.mesh.geometry
        dm = g.dofmaps[0][: self.n_cells]
        return g.x[dm].mean(axis=1)

    def point_stress(self, points_m: npt.ArrayLike) -> np.ndarray:
        """Stress at points (n, dim) m: the converged quadrature stress L2-projected per cell
        onto DG of one degree below the displacements' (DG1 for P2, exact for an elastic P2
        field; DG0 for P1, one quadrature point per cell: its stress), evaluated at the
        points. (n, 3, 3) Pa, tension positive (x, y, z). Points outside the body raise
        FemInputError."""
        fx = self._fx
        fem, ufl = fx.fem, fx.ufl
        import dolfinx.geometry as dg

        pts = np.atleast_2d(np.asarray(points_m, float))
        if pts.shape[1] != self.tdim:
            raise FemInputError(f"points_m: shape {pts.shape}, need (n, {self.tdim})")
        p3 = np.zeros((len(pts), 3))
        p3[:, : self.tdim] = pts
        # (the quadrature, of degree 2 (degree - 1), integrates this space's mass matrix
        # exactly; DG1 on P1's one point per cell was singular: NaN)
        D = fem.functionspace(self.mesh, ("DG", self.degree - 1, (self.ncomp,)))
        t, s = ufl.TrialFunction(D), ufl.TestFunction(D)
        self._to_q(self.sig_q, self.sig_n, self._qdofs, self.ncomp)
        prob = fx.fem_petsc.LinearProblem(
            ufl.inner(t, s) * self.dxq, ufl.inner(self.sig_q, s) * self.dxq,
            petsc_options_prefix=f"femcoupling_proj_{next(_counter)}_",
            petsc_options=lu_options(self.comm))
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

    def write_xdmf(self, path: Any, *, time: float = 0.0, append: bool = False) -> None:
        """Write the mesh with its cell tags (element regions and layers marked), the
        displacement (P1 interpolation, m) and the cell-mean stress (3x3 (x, y, z), Pa,
        tension positive) to an XDMF/HDF5 pair; ``append`` adds a time to an existing file."""
        fx = self._fx
        fem = fx.fem
        import dolfinx.io

        P1 = fem.functionspace(self.mesh, ("Lagrange", 1, (self.tdim,)))
        u1 = fem.Function(P1, name="displacement_m")
        # (the vertices' values copied: the first dofs of a Lagrange cell are its vertices'
        # in every degree. dolfinx's interpolate between the spaces goes through basix's
        # matrices, which BLAS rounds as its kernel does: another CPU, other last bits)
        nv = P1.dofmap.list.shape[1]
        bs = self.tdim
        u1.x.array.reshape(-1, bs)[P1.dofmap.list.reshape(-1)] = self.u.x.array.reshape(
            -1, bs)[self.V.dofmap.list[:, :nv].reshape(-1)]
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
