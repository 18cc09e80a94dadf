"""The cases' --grains option (triaxial, pullout-000 and pullout-001): 'spheres', or
'clumps:NAME' with NAME a shipped grain (gravel_a .. gravel_d), 'gravel' for the four mixed,
or a clump template CSV (x, y, z, r in m). The case's radii or PSD are then the clumps'
equivalent-volume radii (docs/clumps.md). Also the grains' CSV output the cases share."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import cpp_dem as dem
from cpp_dem import measure

ALLOWED = ("'spheres' or 'clumps:NAME' (NAME: a shipped grain gravel_a .. gravel_d, 'gravel' "
           "for the four mixed, either with @N for N spheres each, or a clump template CSV "
           "x,y,z,r in m)")

HELP = ("spheres, or clumps:NAME with NAME a shipped grain (gravel_a .. gravel_d, 24 spheres "
        "each, or N with NAME@N; 'gravel' mixes the four) or a clump template CSV (x,y,z,r in "
        "m); the case's radii are then equivalent-volume radii (docs/clumps.md)")


def grain_templates(spec: str) -> list:
    """The clump templates of a --grains value 'clumps:NAME'
    (cpp_dem.build.clump_mesh.templates_from_spec); SystemExit naming --grains, the value and what is
    allowed when it names none or the template cannot be read."""
    from cpp_dem.build.clump_mesh import templates_from_spec

    try:
        return templates_from_spec(spec)
    except dem.ParameterError as e:
        raise SystemExit(f"error: --{e}") from None
    except (OSError, ValueError) as e:
        raise SystemExit(f"error: --grains={spec!r}: cannot read the template: {e}") from None


def check_grains(ap, value: str) -> None:
    """argparse check of --grains: 'spheres', or 'clumps:NAME' naming templates that load
    (ap.error, exit status 2, naming the field, the value and what is allowed)."""
    if value == "spheres":
        return
    if not value.startswith("clumps:") or not value[7:]:
        ap.error(f"--grains={value}: must be {ALLOWED}")
    try:
        grain_templates(value)
    except SystemExit as e:
        ap.error(str(e).removeprefix("error: "))


def write_grains_csv(scene, out: Path, name: str) -> None:
    """packing_<name>.csv: the grains' spheres (x, y, z, r in m; clump members included, the
    geogrid's nodes not); with clumps also clumps_<name>.csv: clump, centre of mass (m),
    orientation of the principal frame (w, x, y, z), mass (kg)."""
    grains = measure.sphere_mask(scene)
    dem.write_packing_csv(out / f"packing_{name}.csv", scene.positions[grains],
                          scene.radii[grains])
    if scene.num_clumps:
        np.savetxt(out / f"clumps_{name}.csv",
                   np.column_stack([np.arange(scene.num_clumps), scene.clump_positions,
                                    scene.clump_orientations, scene.clump_masses]),
                   delimiter=",", header="clump,x_m,y_m,z_m,qw,qx,qy,qz,mass_kg", comments="",
                   fmt=["%d"] + ["%.10g"] * 8)
