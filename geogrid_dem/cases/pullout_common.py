"""What the two pull-out cases (pullout_000.py, pullout_001.py) share: running the stages
with progress lines, the recorders (HDF5 + CSV, appended and flushed as the run goes), the VTK
snapshots at chosen displacements, the plots (the pull-out paper's Figs 5, 7, 8), the
summary, and the initial cloud of clump grains (--grains clumps:NAME; the option itself:
grains_option.py)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from cpp_dem.io.figures import save_figure
import cpp_dem as dem
from cpp_dem.build import geogrid
from cpp_dem import measure
from cpp_dem.protocols import pullout
from geogrid_dem.cases.grains_option import grain_templates, write_grains_csv
from geogrid_dem.rundir import begin_run, end_run, on_interrupt
from cpp_dem.io import (CsvRecorder, H5Recorder, PvdWriter, write_vtk_box,
                            write_vtk_contacts, write_vtk_spheres)

SERIES = {k: (None, u) for k, u in pullout.PULL_UNITS.items()}

#: Largest solid fraction of the clumps' bounding spheres in the initial cloud, -: random
#: sequential addition jams above about 0.3 (cpp_dem.build.packing.loose_cloud).
CLUMP_CLOUD_FRACTION = 0.25


def clump_layers(spec: str, radii, lo, hi, *, grid_z: float, clearance: float,
                 seed: int) -> tuple:
    """The initial cloud of clumps for --grains clumps:NAME: one clump per radius (m, its
    equivalent-volume radius), random seeded orientations, in the two layers clear of the
    geogrid plane z = grid_z by ``clearance`` (m) (pullout.layered_clump_cloud). The bounding
    spheres take more room than the grains, so the cloud is shrunk uniformly to at most
    CLUMP_CLOUD_FRACTION of the layers' volume; the preparation grows the grains anyway.
    Returns centres and radii of the bounding spheres (m) and (cloud, templates) for
    pullout.build_sample(clumps=...)."""
    from cpp_dem.build.clumps import bounding_volume_factor

    templates = grain_templates(spec)
    radii = np.asarray(radii, float)
    layers = float((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2] - 2.0 * clearance))
    frac = bounding_volume_factor(templates) * float(np.sum(4 / 3 * np.pi * radii**3)) / layers
    shrink = min(1.0, (CLUMP_CLOUD_FRACTION / frac) ** (1.0 / 3.0))
    cloud = pullout.layered_clump_cloud(templates, 2.0 * radii * shrink, lo, hi, grid_z=grid_z,
                                        clearance=clearance, seed=seed)
    r = cloud.scales * np.array([templates[t].bounding_radius for t in cloud.template])
    return cloud.positions, r, (cloud, templates)


def grain_label(sample: pullout.PulloutSample) -> str:
    """'N spheres' or 'N clumps (M spheres)' for titles and logs."""
    sc = sample.scene
    n_sph = int(np.count_nonzero(measure.sphere_mask(sc)))
    if sc.num_clumps:
        return f"{sc.num_clumps} clumps ({n_sph} spheres)"
    return f"{n_sph} spheres"


def largest_overlaps(scene) -> dict:
    """The largest overlaps of the active grain contacts, as fractions of the (smaller)
    sphere's radius, -: 'pair' (grain-grain; for clumps member-member between two clumps, as
    the core's blow-up check measures them), 'wall' (grain-wall) and 'grid' (grain-geogrid,
    of the grain's radius)."""
    c = scene.contacts()
    ids = np.asarray(c["ids"], dtype=np.int64).reshape(-1, 2)
    ov = np.asarray(c["overlap"], dtype=float)
    r = np.asarray(scene.radii, dtype=float)
    out = {"pair": 0.0, "wall": 0.0, "grid": 0.0}
    pair = ids[:, 1] >= 0
    if np.any(pair):
        out["pair"] = float(np.max(ov[pair] / np.minimum(r[ids[pair, 0]], r[ids[pair, 1]])))
    if np.any(~pair):
        out["wall"] = float(np.max(ov[~pair] / r[ids[~pair, 0]]))
    g = scene.grid_contacts()
    if len(g.get("overlap", ())):
        sph = np.asarray(g["sphere"], dtype=np.int64)
        out["grid"] = float(np.max(np.asarray(g["overlap"], dtype=float) / r[sph]))
    return out


def make_logger(tag: str):
    def log(msg: str) -> None:
        print(f"[{tag}] {msg}", flush=True)
    return log


def write_vtk_state(sample: pullout.PulloutSample, vtk_dir: Path, name: str,
                    pvds: dict | None = None) -> None:
    """Spheres, contact network, geogrid (member forces) and box as .vtp files; adds them to
    the PVD collections in ``pvds`` (keys 'spheres', 'contacts', 'geogrid', 'box') when
    given."""
    sc = sample.scene
    files = {"spheres": write_vtk_spheres(vtk_dir / f"spheres_{name}.vtp", sc),
             "contacts": write_vtk_contacts(vtk_dir / f"contacts_{name}.vtp", sc)}
    gpath = vtk_dir / f"geogrid_{name}.vtp"
    geogrid.write_vtk_geogrid(gpath, sc, sample.grid)
    files["geogrid"] = gpath
    lo, hi = sample.box_lo_hi()
    files["box"] = write_vtk_box(vtk_dir / f"box_{name}.vtp", lo, hi, time=sc.time)
    if pvds is not None:
        for k, f in files.items():
            pvds[k].add(sc.time, Path(f).name)


def plot_pull(rec: dict, png_force: Path, png_members: Path, title: str,
              summary: dict | None = None, more_forces: dict | None = None) -> None:
    """Force-displacement with the top-wall stress (000 Fig. 5) and the axial stresses of
    members A and C in apertures 1 and 2 (000 Figs 7 and 8). ``more_forces``: series name ->
    legend label of further forces (N) of ``rec``, drawn on a right-hand axis of the
    force-displacement plot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d_mm = 1e3 * rec["displacement"]
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    ax[0].plot(d_mm, rec["pull_force"], label="pull-out force (clamp reaction)")
    if summary is not None:
        ax[0].plot(1e3 * summary["initial_peak_displacement_m"],
                   summary["initial_peak_force_N"], "o", color="C3",
                   label="initial peak" if summary.get("initial_peak_found", True)
                   else "largest force so far (no peak yet)")
    ax[0].set_xlabel("front displacement (mm)")
    ax[0].set_ylabel("pull-out force (N)")
    if more_forces:
        right = ax[0].twinx()
        for k, (name, label) in enumerate(more_forces.items()):
            right.plot(d_mm, rec[name], color=f"C{4 + k}", lw=0.8, label=label)
        right.set_ylabel("force (N), right-hand axis")
        h0, l0 = ax[0].get_legend_handles_labels()
        h1, l1 = right.get_legend_handles_labels()
        ax[0].legend(h0 + h1, l0 + l1, fontsize=8)
    else:
        ax[0].legend()
    ax[1].plot(d_mm, rec["top_stress"] / 1e3, color="C2")
    ax[1].set_xlabel("front displacement (mm)")
    ax[1].set_ylabel("top-wall normal stress (kPa)")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, png_force)
    plt.close(fig)

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    for k, a in (("A", ax[0]), ("C", ax[1])):
        for n in (1, 2):
            a.plot(d_mm, rec[f"stress_{k}{n}"] / 1e6, label=f"{k}, aperture {n}")
        a.set_xlabel("front displacement (mm)")
        a.set_ylabel("axial stress (MPa, tension +)")
        a.set_title("longitudinal members A" if k == "A" else "transverse members C")
        a.legend()
        a.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, png_members)
    plt.close(fig)


def _record_so_far(out: Path) -> dict | None:
    """The pull recorded so far in out/pullout.csv (flushed row by row); None before 3
    rows."""
    rec = pullout.read_record(out / "pullout.csv")
    return rec if rec and len(rec.get("pull_force", ())) >= 3 else None


def interrupted_report(out: Path, *, meta: dict, finished: list, distance: float, title: str,
                       more_forces: dict | None) -> None:
    """What an interrupted pull-out reports (rundir.on_interrupt): summary.json with the
    stages it finished (``finished``: the preparation, the pull to how far) and the
    statistics of the pull so far (pullout.summarize of the rows recorded); the figures
    pullout_force.png and pullout_members.png of it."""
    def summary() -> dict:
        s = {**meta, "finished": list(finished)}
        rec = _record_so_far(out)
        if rec is not None:
            d = float(rec["displacement"][-1])
            s["finished"].append(f"pull to {1e3 * d:.3g} mm of {1e3 * distance:g} mm")
            s.update(pullout.summarize(rec))
        return s

    def figures() -> None:
        rec = _record_so_far(out)
        if rec is not None:
            d = float(rec["displacement"][-1])
            nan = np.full(len(rec["pull_force"]), np.nan)  # (members the grid has not)
            plot_pull({**{k: nan for k in SERIES}, **rec}, out / "pullout_force.png",
                      out / "pullout_members.png", f"{title} (interrupted at {1e3 * d:.3g} mm)",
                      pullout.summarize(rec), more_forces)

    on_interrupt(out, summary=summary, figures=figures)


def run_case(sample: pullout.PulloutSample, out: Path, *, tag: str, meta: dict,
             prep_kwargs: dict, velocity: float, distance: float, record_every: int,
             snapshot_displacements, grain_density: float, stress: float, title: str,
             log, before_pull=None, extra_series: dict | None = None,
             extra_summary=None) -> dict:
    """Prepares the sample, pulls it, writes every output in ``out``; returns the summary.
    ``before_pull(sample)``, if given, runs between the preparation and the pull (e.g. a
    speed-accuracy preset that applies to the pull only). A clump counts as one grain
    (``num_grains``); ``num_spheres`` counts the spheres (a clump's members).

    ``extra_series``: name -> (fn(sample) -> float, unit, legend label): more columns of the
    record, each evaluated at every record (after pullout.pull_record, on the same state) and
    written to pullout.h5/.csv beside the standard ones; the returned record holds them too,
    and pullout_force.png draws them on a right-hand axis.
    ``extra_summary(rec) -> dict``: more entries of summary.json, from the whole record.
    Interrupted, it leaves summary.json and the figures of the pull so far
    (interrupted_report)."""
    t_start = time.perf_counter()
    begin_run(out, tag)
    finished: list[str] = []  # the stages done, for the summary of an interrupted run
    interrupted_report(out, meta=meta, finished=finished, distance=distance,
                       title=title, more_forces={k: e[2] for k, e in
                                                 (extra_series or {}).items()} or None)
    vtk = out / "vtk"
    vtk.mkdir(exist_ok=True)
    sc = sample.scene
    n_grains = measure.grain_of_body(sc)[1]  # a clump is one grain
    n_spheres = int(np.count_nonzero(measure.sphere_mask(sc)))
    if sc.num_clumps:
        tpl = sorted({int(n) for n in np.bincount(np.asarray(sc.clump_ids)[
            np.asarray(sc.clump_ids) >= 0])})
        log(f"grains: {meta['grains']}, {sc.num_clumps} clumps of {'/'.join(map(str, tpl))} "
            f"spheres ({n_spheres} spheres), contact stiffness of the grain's equivalent radius; "
            f"overlap limit {sc.max_overlap_ratio:.3g} of a member's radius")
    log(f"{n_grains} grains, geogrid of {len(sample.grid.nodes)} nodes / "
        f"{len(sample.grid.links)} links / {len(sample.grid.pfacets)} PFacets / "
        f"{sample.grid.n_members} members; clamp holds {len(sample.clamp_nodes)} nodes "
        f"({sample.info['clamp']}); apertures 1, 2 = cells {sample.apertures.tolist()}; "
        f"{dem.threads_for(sc)} threads")
    t0 = time.perf_counter()
    res = pullout.prepare(sample, stress=stress, log=log, **prep_kwargs)
    t_prep = time.perf_counter() - t0
    if not res.converged:
        log("warning: the sample did not reach the stability criteria; pulling anyway")
    # The series (vtk/{spheres,contacts,geogrid,box}.pvd) start at the prepared state.
    pvds = {k: PvdWriter(vtk / f"{k}.pvd", overwrite=True)
            for k in ("spheres", "contacts", "geogrid", "box")}
    write_vtk_state(sample, vtk, "prepared", pvds)
    write_grains_csv(sc, out, "prepared")
    finished.append("preparation" + ("" if res.converged else " (not converged)"))
    ov_prep = largest_overlaps(sc)
    if before_pull is not None:
        before_pull(sample)
    inertial = pullout.inertial_number(velocity, grain_density, stress)
    log(f"preparation {t_prep:.1f} s; pulling at {velocity} m/s to {distance * 1e3:g} mm "
        f"(inertial number I = v sqrt(rho/sigma) = {inertial:.2g}), dt {sc.dt:.3g} s")
    extra_series = dict(extra_series or {})
    # A member the grid does not have (index -1, e.g. the transverse members C of a grid of
    # triangles) has NaN in pullout.pull_record; its series are not recorded (the recorders
    # write no NaN).
    absent = {f"{q}_{k}" for k, m in sample.aperture_members().items() if m < 0
              for q in ("force", "stress")}
    series = {**{k: v for k, v in SERIES.items() if k not in absent},
              **{k: (None, e[1]) for k, e in extra_series.items()}}
    extra_values: dict[str, list] = {k: [] for k in extra_series}
    h5 = H5Recorder(out / "pullout.h5", series=series, overwrite=True,
                    metadata={**meta, "units": "SI; pull towards -x; pull-out force and member "
                                               "forces tension/resistance positive"},
                    snapshot_fields=("positions", "velocities", "radii"))
    csv = CsvRecorder(out / "pullout.csv", series=series, overwrite=True)
    last = [time.perf_counter()]
    t_pull0 = time.perf_counter()
    nan = float("nan")

    def on_record(row: dict) -> None:
        if extra_series:
            more = {k: float(e[0](sample)) for k, e in extra_series.items()}
            for k, v in more.items():
                extra_values[k].append(v)
            row = {**row, **more}
        if absent:
            row = {k: v for k, v in row.items() if k not in absent}
        h5.record(**row)
        csv.record(**row)
        if time.perf_counter() - last[0] > 5:
            last[0] = time.perf_counter()
            frac = row["displacement"] / distance
            el = time.perf_counter() - t_pull0
            eta = el * (1 - frac) / frac if frac > 0.01 else float("nan")
            a1, c1 = row.get("force_A1", nan), row.get("force_C1", nan)
            log(f"d {1e3 * row['displacement']:7.2f} mm  F {row['pull_force']:9.2f} N  "
                f"A1 {a1:8.2f} N  C1 {c1:8.2f} N  top "
                f"{row['top_stress'] / 1e3:6.2f} kPa  ({100 * frac:.0f} %, ~{eta:.0f} s left)")

    def on_snapshot(d: float) -> None:
        name = f"d{1e3 * d:06.2f}mm"
        f = sample.grid.member_axial_forces(sc)
        h5.snapshot(sc, extra={"member_axial_force": (f, "N"),
                               "grid_node_positions": (sc.positions[sample.grid.nodes], "m"),
                               "front_displacement": (np.array([d]), "m")})
        write_vtk_state(sample, vtk, name, pvds)
        log(f"snapshot at {1e3 * d:.1f} mm: member forces {f.min():.1f} .. {f.max():.1f} N "
            f"-> vtk/*_{name}.vtp")

    steps0 = sc.step_count
    try:
        rec = pullout.pull(sample, velocity=velocity, distance=distance,
                           record_every=record_every, on_record=on_record,
                           snapshot_displacements=snapshot_displacements,
                           on_snapshot=on_snapshot)
    finally:
        h5.close()
        csv.close()
        for p in pvds.values():
            p.close()
    t_pull = time.perf_counter() - t_pull0
    pull_steps = sc.step_count - steps0
    rec = {**rec, **{k: np.asarray(v, float) for k, v in extra_values.items()}}
    summ = pullout.summarize(rec)
    if extra_summary is not None:
        summ = {**summ, **extra_summary(rec)}
    plot_pull(rec, out / "pullout_force.png", out / "pullout_members.png", title, summ,
              {k: e[2] for k, e in extra_series.items()} or None)
    ov_end = largest_overlaps(sc)
    summary = {**meta, **summ, "num_grains": n_grains,
               "num_clumps": int(sc.num_clumps), "num_spheres": n_spheres,
               "max_overlap_ratio_limit": float(sc.max_overlap_ratio),
               "largest_overlap_prepared": ov_prep, "largest_overlap_final": ov_end,
               "grid_nodes": int(len(sample.grid.nodes)),
               "grid_members": int(sample.grid.n_members),
               "apertures": sample.apertures.tolist(),
               "porosity_prepared": res.porosity, "top_stress_prepared_Pa": res.top_stress,
               "prep_converged": res.converged,
               "node_density_scale": sample.node_density_scale,
               "inertial_number": inertial, "dt_s": sc.dt, "pull_steps": pull_steps,
               "top_stress_mean_Pa": float(rec["top_stress"].mean()),
               "top_stress_max_rel_dev": float(np.max(np.abs(rec["top_stress"] / stress - 1))),
               "wall_time_prep_s": t_prep, "wall_time_pull_s": t_pull,
               "wall_time_total_s": time.perf_counter() - t_start,
               "particle_steps_per_s_pull": n_spheres * pull_steps / t_pull if t_pull else 0,
               "threads": dem.get_num_threads()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    end_run(out)
    peak = ("initial peak" if summ["initial_peak_found"]
            else "initial peak: none yet (the force has not dropped 10 %); largest force")
    log(f"{peak} {summ['initial_peak_force_N']:.2f} N at "
        f"{1e3 * summ['initial_peak_displacement_m']:.1f} mm; mean {summ['mean_force_N']:.2f} N,"
        f" CoV {summ['cov_force']:.3f}; |C|/|A| (apertures 1-2) "
        f"{summ.get('transverse_over_longitudinal', float('nan')):.3f}")
    log(f"wall time: preparation {t_prep:.1f} s, pull {t_pull:.1f} s ({pull_steps} steps), "
        f"total {summary['wall_time_total_s']:.1f} s; outputs in {out}")
    return summary

