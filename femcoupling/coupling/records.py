"""The records a coupled run writes as it goes.

- :func:`append_rows`: rows appended to an HDF5 record: one dataset per field, resizable
  along the first axis, flushed after every append (a run's records survive its end,
  whatever ends it);
- :class:`ElementRecords`: the records of a :class:`femcoupling.fem.model.FemModel` with DEM
  elements at its points (``out=DIR``), appended and flushed at every accepted step:
  ``elements.h5`` (one row per element per step: step, load, element, increment, stress, its
  bootstrap scatter, tangent, contact count, DEM seconds and steps), ``fem.xdmf`` (the
  displacement and the elements' stresses per cell), ``steps.csv`` (iterations, residuals,
  noise, status, the FEM/DEM time split) and ``report.md`` (the run so far, every
  warning).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from femcoupling._checks import FemInputError
from femcoupling.fem.steps import LoadStep

__all__ = ["ElementRecords", "RECORD_FILES", "append_rows"]

#: the files an ``ElementRecords`` writes into its folder
RECORD_FILES = ("elements.h5", "fem.xdmf", "fem.h5", "steps.csv", "report.md")


def append_rows(path: Path, rows: dict, *, units: str) -> None:
    """Appends ``rows`` (field -> array, the same first length for every field) to the HDF5
    file ``path``, creating it, with ``units`` as its attribute, at the first call."""
    import h5py

    rows = {k: np.asarray(v) for k, v in rows.items()}
    n = len(next(iter(rows.values())))
    with h5py.File(path, "a") as f:
        if not f.keys():
            f.attrs["units"] = units
            for key, v in rows.items():
                f.create_dataset(key, data=v, maxshape=(None,) + v.shape[1:], chunks=True)
        else:
            for key, v in rows.items():
                d = f[key]
                d.resize(d.shape[0] + n, axis=0)
                d[-n:] = v
        f.flush()


def _relative_scatter(r: LoadStep) -> float:
    """The elements' mean bootstrap scatter relative to their largest stress component."""
    if r.element_scatter is None:
        return float("nan")
    big = np.abs(r.element_stresses).max(axis=1)
    return float(np.mean(r.element_scatter.max(axis=1) / np.maximum(big, 1e-300)))


class ElementRecords:
    """The records of a model with DEM elements at its points, in the folder ``out`` (module
    doc). Refuses a folder that holds an earlier run's records unless ``overwrite`` (then
    they are removed, by rank 0 under MPI: ``root``; the ranks wait for it)."""

    def __init__(self, out, *, overwrite: bool, root: bool = True, comm=None) -> None:
        self.out = Path(out)
        old = [f for f in RECORD_FILES if (self.out / f).exists()]
        if old and not overwrite:
            raise FemInputError(f"out={str(self.out)!r}: holds the records of an earlier "
                                f"run ({', '.join(old)}); give a new folder, or "
                                "overwrite=True to replace them")
        if root:
            for f in old:
                (self.out / f).unlink()
        if comm is not None and comm.size > 1:
            comm.barrier()

    def write(self, m, r) -> None:
        """Appends the accepted step to ``out``: one row per element in ``elements.h5`` (the
        step, its load, the element, its displacement-gradient increment, stress (tension
        positive, Pa), its bootstrap scatter (Pa), tangent (Voigt 6 x 6, Pa), contact count,
        DEM seconds and steps),
        flushed; the FEM state in ``fem.xdmf`` (displacement m, the elements' stress Pa per
        cell, at the load as time); and a line of ``steps.csv`` with the FEM/DEM time split."""
        k = len(m.history) - 1
        if m._root:
            self.out.mkdir(parents=True, exist_ok=True)
        if m._parallel:
            m.comm.barrier()
        self._write_xdmf(m, r, append=k > 0)  # (collective under MPI)
        if not m._root:
            return
        ps = m._last_pool_step
        n = m.n_points
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
                     f"{r.dem_s!r},{r.wall_s!r},{len(r.recovered)},{m.bad_tangents},"
                     f"{r.status},{r.residual_pa!r},{r.noise_residual_pa!r}\n")
        self._write_report(m)

    def _write_report(self, m) -> None:
        """``report.md``: the run so far: per load step the Newton iterations, residual,
        noise and what converged it, and the elements' scatter; the FEM/DEM CPU split; and
        every warning. Rewritten
        at every accepted step."""
        h = m.history
        fem_s = sum(r.fem_s for r in h)
        dem_s = sum(r.dem_s for r in h)
        wall_s = sum(r.wall_s for r in h)
        lines = ["# Hierarchical FEM x DEM run", "",
                 f"- status: **{m.status}** (the worst of the steps'; converged: every "
                 f"step's residual within newton_rtol; stopped_at_scatter: a step accepted "
                 f"within the elements' noise, above newton_rtol)",
                 f"- {m.n_points} elements, {len(h)} load steps accepted; tangent "
                 f"`{m.tangent}`, convergence `{m.convergence}` (newton_rtol "
                 f"{m.newton_rtol:g}, noise factor {m.noise_factor:g}, noise ceiling "
                 f"{m.noise_ceiling:g}), relaxation `{m.relaxation}`",
                 "- strain: " + (
                     "each element its own point's" if m.nonlocal_strain is None else
                     f"nonlocal ({m.nonlocal_strain!r}; femcoupling.fem.nonlocal_strain)"),
                 f"- CPU: FEM {fem_s:.2f} s (the wall time outside the element calls), DEM "
                 f"{dem_s:.2f} s (the elements' work summed over workers), wall {wall_s:.2f} s"
                 f"; DEM share of the work {dem_s / max(fem_s + dem_s, 1e-300):.1%}",
                 f"- element tangents replaced by their last good one: {m.bad_tangents}",
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
        lines += ["", f"## Warnings ({len(m.warnings)})", ""]
        lines += [f"- {w}" for w in m.warnings] or ["none"]
        (self.out / "report.md").write_text("\n".join(lines) + "\n")

    def _write_xdmf(self, m, r, append: bool) -> None:
        fx = m._fx
        fem = fx.fem
        import dolfinx.io

        T = fem.functionspace(m.mesh, ("DG", 0, (3, 3)))
        sig = fem.Function(T, name="stress_pa")
        st = m._local(np.asarray(m._last_pool_step.stresses, float))
        st = st.reshape(m.n_cells, m.nq, 9)
        st = st[:, 0] if m.nq == 1 else st.mean(axis=1)  # (a cell's points: their mean)
        sig.x.array[: st.size] = st.reshape(-1)  # (the owned cells; ghosts from their owners)
        sig.x.scatter_forward()
        u = m.u
        if m.degree != 1:  # XDMF holds the mesh's degree: P2 at the vertices (P1)
            if not hasattr(self, "_u_out"):
                self._u_out = fem.Function(fem.functionspace(m.mesh, ("Lagrange", 1,
                                                                         (m.gdim,))))
            self._u_out.interpolate(m.u)
            u = self._u_out
        u.name = "displacement_m"
        with dolfinx.io.XDMFFile(m.mesh.comm, str(self.out / "fem.xdmf"),
                                 "a" if append else "w") as xf:
            if not append:
                xf.write_mesh(m.mesh)
            xf.write_function(u, r.load)
            xf.write_function(sig, r.load)
