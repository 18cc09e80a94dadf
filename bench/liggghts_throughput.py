"""The throughput scene of bench/throughput.py in LIGGGHTS (Debian's ``liggghts``, 3.8): one
timed block in one process, for ``throughput.py`` to alternate with cpp_dem's blocks.

The scene is the bench's (SI units): the same packing (centres, radii, box), the same
density, the same fixed dt and the same neighbour skin (cpp_dem's Verlet margin); six planar
walls at the box's faces (``fix wall/gran ... primitive``), frictionless as the issue's
scene asks; a Hooke law with shear history (``model hooke/stiffness tangential history``) whose
constant stiffnesses are cpp_dem's linear law's at the mean radius (k_n = E R_mean between two
grains, 2 E R_mean against a wall, k_t = poisson x k_n), Coulomb friction tan(30 deg) between
grains and no viscous damping (LIGGGHTS has no Cundall local damping; the packing is at rest,
so the undamped steps stay quasi-static: both codes do the same contact work per step).
cpp_dem's k_n varies with the two radii (2 E r1 r2 / (r1 + r2)), so the two codes' contact
forces differ by up to the radii's spread; the block compares cost, and the physics it
reports (pair contacts, the packing's own motion) only says both run the same packing.

:func:`run_block` writes the data and input files, runs ``liggghts -in`` once (``warmup``
untimed steps, then ``steps`` timed ones) and returns LIGGGHTS's own "Loop time" of the timed
``run`` (its setup and input reading are not timed) with the number of pair contacts."""

from __future__ import annotations

import math
import re
import subprocess
from pathlib import Path

__all__ = ["LiggghtsError", "input_script", "write_data", "run_block"]


class LiggghtsError(RuntimeError):
    """LIGGGHTS failed or printed no loop time."""


def write_data(path: Path, centers, radii, lo, hi, density: float) -> None:
    """The packing as a LIGGGHTS data file (``atom_style granular``: id type diameter density
    x y z), the simulation box one largest radius outside the walls."""
    pad = 1.5 * float(max(radii))
    lines = ["LIGGGHTS data file of bench/throughput.py's packing", "",
             f"{len(radii)} atoms", "2 atom types", ""]
    for a, lo_a, hi_a in zip("xyz", lo, hi):
        lines.append(f"{lo_a - pad:.17g} {hi_a + pad:.17g} {a}lo {a}hi")
    lines += ["", "Atoms", ""]
    for k, (c, r) in enumerate(zip(centers, radii), start=1):
        lines.append(f"{k} 1 {2 * r:.17g} {density:.17g} {c[0]:.17g} {c[1]:.17g} {c[2]:.17g}")
    path.write_text("\n".join(lines) + "\n")


def input_script(data: Path, lo, hi, *, young: float, poisson: float, friction_angle_deg: float,
                 mean_radius: float, dt: float, skin: float, warmup: int, steps: int) -> str:
    """The LIGGGHTS input of one block (atom type 1: grains, 2: walls)."""
    kn = young * mean_radius            # 2 E r r / (r + r) at r = R_mean, N/m
    kn_wall = 2 * young * mean_radius   # against a wall (infinite radius), N/m
    kt, kt_wall = poisson * kn, poisson * kn_wall
    mu = math.tan(math.radians(friction_angle_deg))
    walls = []
    for k, (a, lo_a, hi_a) in enumerate(zip("xyz", lo, hi)):
        for side, pos in (("lo", lo_a), ("hi", hi_a)):
            walls.append(f"fix w{a}{side} all wall/gran model hooke/stiffness tangential history "
                         f"primitive type 2 {a}plane {pos:.17g}")
    return "\n".join([
        "units si",
        "atom_style granular",
        "atom_modify map array",
        "boundary f f f",
        "newton off",
        "communicate single vel yes",
        "processors 1 1 1",
        f"read_data {data}",
        f"neighbor {skin:.17g} bin",
        "neigh_modify delay 0",
        f"fix kn all property/global kn peratomtypepair 2 {kn:.17g} {kn_wall:.17g} "
        f"{kn_wall:.17g} {kn_wall:.17g}",
        f"fix kt all property/global kt peratomtypepair 2 {kt:.17g} {kt_wall:.17g} "
        f"{kt_wall:.17g} {kt_wall:.17g}",
        "fix gn all property/global gamman peratomtypepair 2 0 0 0 0",
        "fix gt all property/global gammat peratomtypepair 2 0 0 0 0",
        f"fix mu all property/global coefficientFriction peratomtypepair 2 {mu:.17g} 0 0 0",
        "pair_style gran model hooke/stiffness tangential history",
        "pair_coeff * *",
        f"timestep {dt:.17g}",
        *walls,
        "fix integr all nve/sphere",
        "compute cn all contact/atom",
        "compute csum all reduce sum c_cn",
        "thermo_style custom step atoms c_csum ke",
        "thermo_modify norm no lost error",
        f"thermo {max(1, steps)}",
        f"run {warmup}",
        f"run {steps}",
        ""])


_LOOP = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms")


def run_block(exe: str, workdir: Path, centers, radii, lo, hi, *, young: float,
              poisson: float, friction_angle_deg: float, density: float, dt: float,
              skin: float, warmup: int, steps: int, timeout_s: float = 3600.0) -> dict:
    """One LIGGGHTS process: ``warmup`` then ``steps`` steps. Returns ``loop_s`` (the timed
    run's loop time, s), ``particle_steps_per_s``, ``pair_contacts`` (at the end), ``atoms``
    (at the end: none lost) and the command."""
    workdir.mkdir(parents=True, exist_ok=True)
    data = workdir / "packing.data"
    if not data.exists():
        write_data(data, centers, radii, lo, hi, density)
    script = workdir / "in.throughput"
    script.write_text(input_script(data, lo, hi, young=young, poisson=poisson,
                                   friction_angle_deg=friction_angle_deg,
                                   mean_radius=float(sum(radii) / len(radii)), dt=dt, skin=skin,
                                   warmup=warmup, steps=steps))
    cmd = [exe, "-echo", "none", "-log", "none", "-in", str(script)]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=workdir,
                              timeout=timeout_s)
    except subprocess.TimeoutExpired as exc:
        raise LiggghtsError(f"liggghts ran over {timeout_s:.0f} s") from exc
    loops = _LOOP.findall(proc.stdout)
    if proc.returncode != 0 or len(loops) < 2:
        tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-12:])
        raise LiggghtsError(f"liggghts failed (exit {proc.returncode}):\n{tail}")
    loop_s, _procs, nsteps, atoms = loops[-1]
    loop_s, nsteps, atoms = float(loop_s), int(nsteps), int(atoms)
    # the last thermo line: step atoms c_csum ke
    rows = [ln.split() for ln in proc.stdout.splitlines()]
    thermo = [r for r in rows if len(r) == 4 and r[0].isdigit() and r[1].isdigit()]
    csum = float(thermo[-1][2]) if thermo else math.nan
    return {"loop_s": loop_s, "steps": nsteps, "atoms": atoms,
            "particle_steps_per_s": atoms * nsteps / loop_s if loop_s > 0 else math.nan,
            "pair_contacts": csum / 2, "command": " ".join(cmd)}
