# Yade side of bench/throughput.py. Run by it as
#
#     yade -n -j<threads> -x bench/yade_throughput.py <config.json>
#
# (Yade's own Python, not the project venv). The config is written by throughput.py and holds
# the packing CSV (x,y,z,r with header, m), the box, the material, dt, damping, gravity,
# verletDist and the step counts. The scene is the one cpp_dem runs:
#   - spheres + 6 axis-aligned one-sided walls (utils.wall with sense = side of the spheres),
#   - FrictMat (same E, poisson = ks/kn ratio, friction angle, density),
#   - Ip2_FrictMat_FrictMat_FrictPhys + Law2_ScGeom_FrictPhys_CundallStrack,
#   - InsertionSortCollider (Bo1_Sphere_Aabb, Bo1_Wall_Aabb) with the given verletDist,
#   - NewtonIntegrator with the same local damping and gravity, the same fixed O.dt.
# One JSON object with the timings and the physics after the timed steps is written to
# config["out"] and printed on a line starting with "YADE_RESULT ".
import json
import math
import os
import resource
import statistics
import sys
import time

import yade.config
from yade import O, utils
from yade.wrapper import (Bo1_Sphere_Aabb, Bo1_Wall_Aabb, ForceResetter, FrictMat,
                          Ig2_Sphere_Sphere_ScGeom, Ig2_Wall_Sphere_ScGeom, InsertionSortCollider,
                          InteractionLoop, Ip2_FrictMat_FrictMat_FrictPhys,
                          Law2_ScGeom_FrictPhys_CundallStrack, NewtonIntegrator)


def read_packing(path):
    """Centres and radii (m) from a CSV with header x,y,z,r."""
    centers, radii = [], []
    with open(path, encoding="utf-8") as fh:
        header = fh.readline().strip().replace(" ", "").lower()
        if header != "x,y,z,r":
            raise ValueError(f"{path}: header is '{header}', expected 'x,y,z,r'")
        for line in fh:
            line = line.strip()
            if not line:
                continue
            x, y, z, r = (float(v) for v in line.split(","))
            centers.append((x, y, z))
            radii.append(r)
    return centers, radii


def cpu_seconds():
    """CPU time (user + system) of this process, all threads, s."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def busy_cpu_seconds():
    """CPU seconds spent busy (not idle/iowait) by the whole machine since boot."""
    with open("/proc/stat", encoding="ascii") as fh:
        fields = [int(v) for v in fh.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def main():
    cfg_path = sys.argv[1]
    with open(cfg_path, encoding="utf-8") as fh:
        cfg = json.load(fh)
    t_setup = time.perf_counter()
    centers, radii = read_packing(cfg["packing"])
    n = len(radii)
    O.reset()
    mat = O.materials.append(FrictMat(young=cfg["young"], poisson=cfg["poisson"],
                                      frictionAngle=math.radians(cfg["friction_angle_deg"]),
                                      density=cfg["density"], label="mat"))
    lo, hi = cfg["box_lo"], cfg["box_hi"]
    # Walls in the order of cpp_dem's add_box: x-, x+, y-, y+, z-, z+; one-sided (sense = the
    # side where the spheres are), like cpp_dem's infinite one-sided planes.
    wall_ids = []
    for axis in range(3):
        wall_ids.append(O.bodies.append(utils.wall(lo[axis], axis=axis, sense=+1, material=mat)))
        wall_ids.append(O.bodies.append(utils.wall(hi[axis], axis=axis, sense=-1, material=mat)))
    O.bodies.append([utils.sphere(c, r, material=mat) for c, r in zip(centers, radii)])
    collider = InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()],
                                     verletDist=cfg["verlet_dist"])
    if cfg.get("target_interv") is not None:
        collider.targetInterv = cfg["target_interv"]
    newton = NewtonIntegrator(damping=cfg["local_damping"], gravity=tuple(cfg["gravity"]))
    O.engines = [
        ForceResetter(),
        collider,
        InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],
                        [Ip2_FrictMat_FrictMat_FrictPhys()],
                        [Law2_ScGeom_FrictPhys_CundallStrack()]),
        newton,
    ]
    O.dt = cfg["dt"]
    O.timingEnabled = bool(cfg.get("timing", False))
    t_setup = time.perf_counter() - t_setup

    contacts_samples = []
    t0 = time.perf_counter()
    O.run(cfg["warmup_steps"], True)
    warmup_wall = time.perf_counter() - t0
    contacts_samples.append(O.interactions.countReal())
    builds_before = collider.numAction
    steps, repeats = cfg["steps"], cfg["repeats"]
    extra, threshold = cfg.get("extra_repeats", 0), cfg.get("busy_threshold", 0.1)
    walls, cpus, others = [], [], []
    physics = {}
    # `repeats` timed blocks, the physics read after them (same step as cpp_dem), then up to
    # `extra` more blocks while fewer than `repeats` were undisturbed by other processes.
    while True:
        b0, c0 = busy_cpu_seconds(), cpu_seconds()
        t0 = time.perf_counter()
        O.run(steps, True)
        walls.append(time.perf_counter() - t0)
        cpus.append(cpu_seconds() - c0)
        others.append(max(0.0, busy_cpu_seconds() - b0 - cpus[-1]) / walls[-1])
        if len(walls) <= repeats:
            contacts_samples.append(O.interactions.countReal())
        if len(walls) == repeats:
            physics = {
                "collider_runs_timed": collider.numAction - builds_before,
                "collider_runs_total": collider.numAction,
                "mean_active_contacts": statistics.fmean(contacts_samples),
                "active_contacts_end": contacts_samples[-1],
                "wall_forces": [list(O.forces.f(i)) for i in wall_ids],
                "unbalanced_force": utils.unbalancedForce(),
            }
        clean = sum(o < threshold for o in others)
        if len(walls) >= repeats and (clean >= repeats or len(walls) >= repeats + extra):
            break
    pss = [n * steps / w for w in walls]
    clean_ix = [k for k, o in enumerate(others) if o < threshold] or list(range(len(pss)))
    best = max(clean_ix, key=lambda k: pss[k])
    result = {
        "code": "yade",
        "yade_version": yade.config.version,
        "threads": O.numThreads,
        "n_particles": n,
        "steps": steps,
        "repeats": repeats,
        "warmup_steps": cfg["warmup_steps"],
        "setup_wall_s": round(t_setup, 3),
        "warmup_wall_s": round(warmup_wall, 3),
        "wall_s_per_repeat": [round(w, 4) for w in walls],
        "wall_s_total": sum(walls[:repeats]),
        "particle_steps_per_s": pss[best],
        "particle_steps_per_s_median": statistics.median(pss),
        "cpu_utilisation": round(cpus[best] / (walls[best] * O.numThreads), 3),
        "other_load_cores": round(others[best], 2),
        "other_load_cores_per_repeat": [round(o, 2) for o in others],
        "undisturbed_repeats": sum(o < threshold for o in others),
        "verlet_dist": collider.verletDist,
        "target_interv": collider.targetInterv,
        **physics,
    }
    if O.timingEnabled:
        result["engine_time_s"] = {type(e).__name__: e.execTime * 1e-9 for e in O.engines}
    with open(cfg["out"], "w", encoding="utf-8") as fh:
        json.dump(result, fh)
    print("YADE_RESULT " + json.dumps(result), flush=True)


main()
