"""The geogrids of the thesis's triaxial chapter ("Discrete Element Modeling of Soil-Geogrid
Interactions" §5.1, §6.3, App. A), shared by the box's layer and the cylinder's disc
(``triaxial --geogrid``): their members' radius and spacing, their material, and the slab of
grains they displace."""

from __future__ import annotations

import cpp_dem as dem

#: each grid's members' radius R_c, m, and node spacing, m: the square grid 1 mm with 10 nodes
#: over 9.5 cm; the triangular grid 0.5 mm, edge 1.43 cm (§5.1)
GRIDS = {"square": (1e-3, 0.095 / 9), "triangular": (0.5e-3, 0.0143)}

#: the grains within this of a grid's plane (over its footprint) are removed before it is
#: added, m: 1 mm, the square grid's R_c, whatever the grid (so --clear-layer removes the same)
SLAB_M = 1e-3


def add_grid_material(sc, pattern: str) -> tuple[int, dem.BeamParams]:
    """The grid's material in ``sc`` (Table 5.1: E = 5 MPa, nu = 0.3, rho = 2650 kg/m^3,
    phi = 20 deg) and its members' beam law, cohesive links of normal and shear cohesion
    1e7 Pa (App. A) of the ``pattern`` grid's radius: (material id, BeamParams)."""
    mat = sc.add_material(dem.linear_material(density=2650.0, young=5e6, poisson=0.3,
                                              friction_angle_deg=20.0))
    beam = dem.BeamParams(young=5e6, poisson=0.3, radius=GRIDS[pattern][0],
                          normal_cohesion=1e7, shear_cohesion=1e7)
    return mat, beam
