"""Named speed-accuracy presets (issue 7): the numerical knobs a scene can pick in one word.

Each preset sets the time-step safety factor, the geogrid node density scale, the Cundall
local damping of the loading stage, and the loading rate as an inertial number I (the loading
velocity follows from the scene: v = I sqrt(sigma / rho)); for coupled runs also the fine FEM
mesh size (relative to the DEM element's edge) and the two-way tolerance. Their measured cost and error are in
docs/speed_accuracy.md (`bench/speed_accuracy.py --presets` on the 000 pull-out,
`bench/triaxial_accuracy.py --presets` on the triaxial test, `bench/coupled_accuracy.py
--study presets` on the coupled PRS element). Applied by ``cpp_dem.protocols.pullout.apply_preset``,
``cpp_dem.protocols.triaxial.apply_preset`` and ``cases/prs_element.py --preset``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cpp_dem._core import ParameterError


@dataclass(frozen=True)
class Preset:
    """Numerical settings of a run (SI)."""

    name: str
    dt_safety: float            #: dt = safety x critical estimate, -
    node_density_scale: object  #: geogrid node mass factor, or "auto"
    local_damping: float        #: Cundall local damping during loading, -
    inertial_number: float      #: loading rate as I = v sqrt(rho / sigma), -
    fem_size_per_element: float = 0.25  #: coupled runs: fine FEM mesh size / element edge, -
    two_way_tol: float = 0.02   #: coupled runs: two-way tolerance on the handed-over stress, -
    #: element tests (prs-element-002): density scaling of the growth and servo stages, the
    #: target dt over the unscaled one (cpp_dem.protocols.quasi_static); 0: off, -
    density_scaling: float = 0.0

    def velocity(self, *, density: float, stress: float) -> float:
        """Loading velocity, m/s, for grains of ``density`` (kg/m^3) under ``stress`` (Pa)."""
        if not (density > 0 and stress > 0):
            raise ParameterError(f"density={density}, stress={stress}: must be > 0")
        return self.inertial_number * math.sqrt(stress / density)

    def strain_rate(self, *, grain_diameter: float, density: float, stress: float) -> float:
        """Loading strain rate, 1/s, of an element test on grains of ``grain_diameter`` (m)
        and ``density`` (kg/m^3) under ``stress`` (Pa): I = rate d sqrt(rho / sigma)."""
        if not (grain_diameter > 0):
            raise ParameterError(f"grain_diameter={grain_diameter}: must be > 0 (m)")
        return self.velocity(density=density, stress=stress) / grain_diameter


PRESETS = {
    "fast": Preset("fast", dt_safety=0.8, node_density_scale=1e5, local_damping=0.2,
                   inertial_number=6.4e-3, fem_size_per_element=0.5, two_way_tol=0.1,
                   density_scaling=16.0),
    "balanced": Preset("balanced", dt_safety=0.5, node_density_scale="auto",
                       local_damping=0.2, inertial_number=3.2e-3, fem_size_per_element=0.25,
                       two_way_tol=0.02, density_scaling=8.0),
    "accurate": Preset("accurate", dt_safety=0.35, node_density_scale=3e3,
                       local_damping=0.05, inertial_number=8e-4, fem_size_per_element=0.125,
                       two_way_tol=0.005, density_scaling=4.0),
}


def preset(name: str) -> Preset:
    """The preset called ``name`` ('fast', 'balanced' or 'accurate')."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ParameterError(f"preset={name!r}: unknown; choose one of "
                             f"{', '.join(PRESETS)}") from None
