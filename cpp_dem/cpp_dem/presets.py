"""Named speed-accuracy presets (issue 7): the numerical knobs a scene can pick in one word.

Each preset sets the time-step safety factor, the geogrid node density scale, the Cundall
local damping of the loading stage, and the loading rate as an inertial number I (the loading
velocity follows from the scene: v = I sqrt(sigma / rho)). Their measured cost and error are in
docs/speed_accuracy.md (`bench/speed_accuracy.py --presets` on the 000 pull-out,
`bench/triaxial_accuracy.py --presets` on the triaxial test). Applied by
``cpp_dem.pullout.apply_preset`` and ``cpp_dem.triaxial.apply_preset``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ._core import ParameterError


@dataclass(frozen=True)
class Preset:
    """Numerical settings of a run (SI)."""

    name: str
    dt_safety: float            #: dt = safety x critical estimate, -
    node_density_scale: object  #: geogrid node mass factor, or "auto"
    local_damping: float        #: Cundall local damping during loading, -
    inertial_number: float      #: loading rate as I = v sqrt(rho / sigma), -

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
                   inertial_number=6.4e-3),
    "balanced": Preset("balanced", dt_safety=0.5, node_density_scale="auto",
                       local_damping=0.2, inertial_number=3.2e-3),
    "accurate": Preset("accurate", dt_safety=0.35, node_density_scale=3e3,
                       local_damping=0.05, inertial_number=8e-4),
}


def preset(name: str) -> Preset:
    """The preset called ``name`` ('fast', 'balanced' or 'accurate')."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ParameterError(f"preset={name!r}: unknown; choose one of "
                             f"{', '.join(PRESETS)}") from None
