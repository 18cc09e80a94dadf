"""Speed-accuracy trade of the triaxial test (issue 7). Not a test: one JSON line per run, a
Markdown table on stderr, and with --out a JSONL file for bench/pareto.py.

    .venv/bin/python bench/triaxial_accuracy.py [--knobs rate safety damping grains]
                                                [--presets] [--n 2000] [--out FILE.jsonl]

The sample: a dense App. B sample of --n grains (cases/triaxial.py, expanded without friction,
phi = 32 deg, 75 kPa, E = 4.5 MPa), loaded to --stop-strain (20 %; its peak is at ~12 %).
For the rate, safety and damping knobs the isotropic state is prepared ONCE and every run
starts from a bitwise copy of it (the knob applies to the axial loading only, so no
sample-to-sample scatter is mixed in). The grains knob (--grain-scale of the case: the same
box filled with coarser or finer grains) needs a new sample per value, so its error includes
the scatter between samples. One knob varies at a time; the reference is its most accurate
value, the others at the case's defaults (safety 0.5, damping 0.2, rate 0.5 /s).

Outputs compared: peak deviator q (Pa), the axial strain at the peak, the volumetric strain at
the end (dilatancy). Cost: CPU seconds of this process for the axial loading (one thread:
equal to wall time on an idle machine, and not inflated when other jobs share the cores), also
relative to the knob's reference. The inertial number I = rate x d_mean x sqrt(rho / p) says
how quasi-static the loading is.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "cases"))
sys.path.insert(0, str(ROOT / "bench"))

import cpp_dem as dem  # noqa: E402
from _report import emit, markdown_table, pct  # noqa: E402
import triaxial as case  # noqa: E402
from cpp_dem import _core  # noqa: E402
from cpp_dem.protocols.triaxial import apply_preset, build_box_sample, deviatoric_stage  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

#: knob -> (values, index of the reference value)
KNOBS = {
    "rate": ([0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 4.0], 0),
    "safety": ([0.2, 0.35, 0.5, 0.8], 0),
    "damping": ([0.05, 0.1, 0.2, 0.4], 0),
    "grains": ([0.5, 0.63, 0.79, 1.0, 1.26, 1.59, 2.0], 0),  # grain_scale: 8x .. 1/8x the grains
}


RECORD_STRAIN = 5e-4  #: axial strain between records, -


def base_params(n: int, stop_strain: float) -> case.Params:
    p = case.Params(n=n, prep_friction=0.0, strain_rate=0.5, stop_strain=stop_strain)
    p.box = case.smoke_box(p)
    return p


class Isotropic:
    """One prepared isotropic state, copied bitwise into a fresh scene for every run."""

    def __init__(self, p: case.Params, log):
        t0 = time.process_time()
        self.p = p
        prepared = case.prepare(p, log)
        self.sample = prepared.sample
        self.n_grains = prepared.n_grains
        self.prep_cpu_s = time.process_time() - t0
        sc = self.sample.scene
        self.blob = _core._checkpoint_save(sc)
        mask = np.asarray(sc.radii) > 0
        self.centers = np.asarray(sc.positions)[mask].copy()
        self.radii = np.asarray(sc.radii)[mask].copy()
        w = self.sample.walls
        self.lo = np.array([sc.wall_positions[w[2 * a]] for a in range(3)])
        self.hi = np.array([sc.wall_positions[w[2 * a + 1]] for a in range(3)])

    def copy(self, dt_safety: float, damping: float):
        """A new sample in the saved state, with the loading's dt safety and damping."""
        p = self.p
        s = build_box_sample(self.centers, self.radii, self.lo, self.hi, young=p.young,
                             poisson=p.poisson, friction_deg=p.phi, density=p.density,
                             local_damping=damping, dt_safety=dt_safety)
        # The expansion left a (disabled) RadiusGrowth after the box controller: the same
        # controllers, in the same order, before the state is loaded.
        s.scene.add_controller(_core.RadiusGrowth(walls=list(s.walls), bodies=[],
                                                  target_stress=p.cell_pressure))
        _core._checkpoint_load(s.scene, self.blob)
        s.scene.local_damping = damping
        s.scene.set_auto_timestep(safety=dt_safety, period=100)
        return s


def load(sample, p: case.Params, rate: float) -> dict:
    """Axial loading of ``sample`` at ``rate`` (1/s); the outputs compared and the cost."""
    sc = sample.scene
    t0, w0 = time.process_time(), time.perf_counter()
    steps0 = sc.step_count
    # A record every 0.05 % of axial strain, whatever the step: the peak and the end are
    # read at the same strain resolution in every run.
    every = max(1, int(round(RECORD_STRAIN / (rate * sc.dt))))
    rows = deviatoric_stage(sample, p.cell_pressure, rate, p.stop_strain, record_every=every)
    cpu, wall = time.process_time() - t0, time.perf_counter() - w0
    q = rows["deviatoric_stress"]
    k = int(np.argmax(q))
    pr = dataclasses.replace(p, strain_rate=rate)
    return {"q_peak_Pa": float(q[k]), "axial_strain_at_peak": float(rows["axial_strain"][k]),
            "volumetric_strain_end": float(rows["volumetric_strain"][-1]),
            "steps": sc.step_count - steps0, "dt_s": sc.dt, "cpu_s": cpu, "wall_s": wall,
            "strain_rate_per_s": rate, "inertial_number": case.inertial_number(sc, pr),
            "n_grains": int(np.count_nonzero(np.asarray(sc.radii) > 0))}


def with_errors(rows: list, ref: dict, out) -> None:
    """Errors and cost against ``ref``; prints and appends each row."""
    for r in rows:
        r["err_q_peak"] = (r["q_peak_Pa"] - ref["q_peak_Pa"]) / ref["q_peak_Pa"]
        r["diff_axial_strain_at_peak"] = r["axial_strain_at_peak"] - ref["axial_strain_at_peak"]
        r["diff_volumetric_strain_end"] = (r["volumetric_strain_end"]
                                           - ref["volumetric_strain_end"])
        r["cost_vs_reference"] = r["cpu_s"] / ref["cpu_s"]
        emit({"case": "triaxial", **r}, out)


def knob_runs(iso: Isotropic, knob: str, log) -> list:
    values, _ = KNOBS[knob]
    p = iso.p
    rows = []
    for v in values:
        if knob == "grains":
            pg = dataclasses.replace(p, grain_scale=v)
            sample = Isotropic(pg, log).copy(p.dt_safety, p.damping)
            r = load(sample, p, p.strain_rate)
        else:
            safety = v if knob == "safety" else p.dt_safety
            damping = v if knob == "damping" else p.damping
            rate = v if knob == "rate" else p.strain_rate
            r = load(iso.copy(safety, damping), p, rate)
        log(f"{knob} = {v}: q_peak {r['q_peak_Pa'] / 1e3:.2f} kPa at "
            f"{100 * r['axial_strain_at_peak']:.2f} %, eps_v end "
            f"{100 * r['volumetric_strain_end']:.3f} %, {r['cpu_s']:.1f} s CPU")
        rows.append({"knob": knob, "value": v, **r})
    return rows


def presets_runs(iso: Isotropic, log) -> list:
    """fast / balanced / accurate against the most accurate value of every knob at once."""
    from cpp_dem import presets

    p = iso.p
    rows = [{"knob": "preset", "value": "reference",
             **load(iso.copy(0.2, 0.05), p, KNOBS["rate"][0][0])}]
    for name in presets.PRESETS:
        sample = iso.copy(p.dt_safety, p.damping)
        rate = apply_preset(sample, name, pressure=p.cell_pressure, density=p.density)
        rows.append({"knob": "preset", "value": name, **load(sample, p, rate)})
        log(f"preset {name}: q_peak {rows[-1]['q_peak_Pa'] / 1e3:.2f} kPa, "
            f"{rows[-1]['cpu_s']:.1f} s CPU")
    return rows


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="append", description=__doc__.split("\n\n")[0])
    ap.add_argument("--knobs", nargs="*", choices=sorted(KNOBS), default=list(KNOBS))
    ap.add_argument("--presets", action="store_true",
                    help="also measure the presets fast/balanced/accurate against the most "
                         "accurate value of every knob at once")
    ap.add_argument("--n", type=int, default=2000, help="grains of the base sample (box "
                    "scaled with it, as cases/triaxial.py --n)")
    ap.add_argument("--stop-strain", type=float, default=0.2, help="axial strain, -")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None, help="append the JSON lines here")
    a = ap.parse_args(argv)
    if a.n < 50:
        ap.error(f"--n={a.n}: must be >= 50")
    if not 0 < a.stop_strain < 0.5:
        ap.error(f"--stop-strain={a.stop_strain}: must be in (0, 0.5)")
    dem.set_num_threads(a.threads)

    def log(msg: str) -> None:
        print(f"[triaxial_accuracy] {msg}", file=sys.stderr, flush=True)

    iso = Isotropic(base_params(a.n, a.stop_strain), log)
    log(f"base sample: {iso.n_grains} grains, prepared in {iso.prep_cpu_s:.1f} s CPU")
    table = []
    if a.presets:
        rows = presets_runs(iso, log)
        with_errors(rows, rows[0], a.out)
        table += rows
    for knob in a.knobs:
        rows = knob_runs(iso, knob, log)
        with_errors(rows, rows[KNOBS[knob][1]], a.out)
        table += rows
    markdown_table(table, [
        ("knob", lambda r: str(r["knob"])), ("value", lambda r: str(r["value"])),
        ("grains", lambda r: str(r["n_grains"])), ("CPU (s)", lambda r: f"{r['cpu_s']:.1f}"),
        ("cost / ref", lambda r: f"{r['cost_vs_reference']:.3f}"),
        ("q peak (kPa)", lambda r: f"{r['q_peak_Pa'] / 1e3:.1f}"),
        ("err q peak", lambda r: pct(r["err_q_peak"])),
        ("eps_a at peak", lambda r: f"{100 * r['axial_strain_at_peak']:.1f} %"),
        ("eps_v end", lambda r: f"{100 * r['volumetric_strain_end']:+.2f} %"),
        ("dt (s)", lambda r: f"{r['dt_s']:.2g}"), ("I", lambda r: f"{r['inertial_number']:.2g}")])
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
