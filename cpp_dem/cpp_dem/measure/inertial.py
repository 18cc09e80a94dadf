"""The inertial number of a loading, and the warning when a quasi-static test is not.

The inertial number (GDR MiDi 2004; da Cruz et al. 2005) compares the time a grain takes to
fall into a hole under the confining pressure with the time the shear takes to open it:

    I = gamma_dot d / sqrt(p / rho)

gamma_dot the shear (or strain) rate, 1/s; d the mean grain diameter, m; p the confining
pressure, Pa; rho the grains' density, kg/m^3. Below I ~ 1e-3 a granular assembly deforms
quasi-statically: its stresses do not depend on the rate (GDR MiDi 2004, da Cruz et al. 2005).
Above, the effective friction grows with I, as mu(I) ~ mu_min + b I with b ~ 1 (da Cruz et
al. 2005), and the solid fraction falls as nu_max - a I with a ~ 0.3. This code's own
measurements (docs/speed_accuracy.md) follow: +1.6 % pull-out force at I = 3.2e-3 but +7 % at
1.6e-2; +4 % peak deviator at I = 3e-3 but +19 % at 1.2e-2. So the quasi-static cases
(pull-out, triaxial, DEM element loading and servo stages) warn above ``QUASI_STATIC_LIMIT``
= 1e-2, with the value: beyond it a test measures a dense flow, not the material's
quasi-static response. Between 1e-3 and 1e-2 (the 'fast' and 'balanced' presets, a cost
choice whose error that page gives) they run quietly.
"""

from __future__ import annotations

import math
import warnings

from cpp_dem._core import ParameterError

#: Inertial number above which a quasi-static loading is reported, -.
QUASI_STATIC_LIMIT = 1e-2
#: Inertial number below which the literature calls a flow quasi-static, -.
QUASI_STATIC_STRICT = 1e-3


class InertialNumberWarning(UserWarning):
    """A loading meant to be quasi-static runs at an inertial number above
    ``cpp_dem.measure.inertial.QUASI_STATIC_LIMIT`` (the message names the stage, the value, and
    the rate, grain size, pressure and density it comes from). Make it an error with
    ``warnings.simplefilter("error", cpp_dem.InertialNumberWarning)``."""


def inertial_number(rate: float, diameter: float, pressure: float, density: float) -> float:
    """I = rate x diameter / sqrt(pressure / density), - (rate 1/s, diameter m, pressure Pa,
    density kg/m^3)."""
    for name, v in (("rate", rate), ("diameter", diameter), ("pressure", pressure),
                    ("density", density)):
        if not math.isfinite(v):
            raise ParameterError(f"{name}={v}: must be finite")
    for name, v, unit in (("diameter", diameter, "m"), ("pressure", pressure, "Pa"),
                          ("density", density, "kg/m^3")):
        if not v > 0:
            raise ParameterError(f"{name}={v}: must be > 0 ({unit})")
    return abs(rate) * diameter / math.sqrt(pressure / density)


def check_quasi_static(value: float, stage: str, *, rate: float, diameter: float,
                       pressure: float, density: float, rate_name: str = "strain rate",
                       rate_unit: str = "1/s", stacklevel: int = 2) -> bool:
    """Warns (InertialNumberWarning) when the inertial number ``value`` of ``stage`` is above
    QUASI_STATIC_LIMIT, naming the stage, the value and its inputs; returns True when it
    warned."""
    if not value > QUASI_STATIC_LIMIT:
        return False
    warnings.warn(InertialNumberWarning(
        f"{stage}: inertial number I = {value:.3g} at {rate_name} {rate:.4g} {rate_unit}, "
        f"mean grain diameter {diameter:.4g} m, pressure {pressure:.4g} Pa, density "
        f"{density:.4g} kg/m^3: above {QUASI_STATIC_LIMIT:g}, so the loading is not "
        f"quasi-static (below {QUASI_STATIC_STRICT:g}, GDR MiDi 2004) and the rate adds to the "
        "strength; load more slowly"), stacklevel=stacklevel + 1)
    return True


__all__ = ["QUASI_STATIC_LIMIT", "QUASI_STATIC_STRICT", "InertialNumberWarning",
           "inertial_number", "check_quasi_static"]
