"""Measures of a scene: box and sample measures (`box`; its functions are also importable
from `cpp_dem.measure` itself), the inertial number of a quasi-static stage (`inertial`), the
grid-soil interaction measures of the prestressed-element study (`grid_soil`) and the contact
network's tangent stiffness of a periodic cell (`network_tangent`)."""

from cpp_dem.measure.box import *  # noqa: F401,F403  (the box measures, as cpp_dem.measure.X)
from cpp_dem.measure.box import __all__  # noqa: F401
