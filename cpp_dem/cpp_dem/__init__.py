"""cpp_dem: a C++ DEM engine for granular soil and geogrids, driven from Python.

The step loop runs in C++ (`cpp_dem._core`); this package builds scenes, runs them, records
and writes results. Importing it never imports dolfinx (DEM-only mode). SI units throughout.

Quick start::

    import numpy as np, cpp_dem as dem
    scene = dem.Scene(gravity=(0, 0, -9.81))
    sand = scene.add_material(dem.Material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    scene.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=sand)
    scene.add_spheres([[0.05, 0.05, 0.05]], [0.005], material=sand)
    scene.set_auto_timestep(safety=0.8)
    scene.run(1000)
"""

import os as _os

# OpenMP threads that wait at a barrier spin for a long time by default (libgomp: ~300k
# spins). When another process holds a core, a spinning thread steals it from the thread
# the barrier waits for and a 2-thread run slows down ten-fold or more (measured: a smoke
# pull-out that takes 10 s ran for half an hour beside another job). A short spin, then
# sleep, keeps the dedicated-machine speed and degrades gracefully when shared. Set
# GOMP_SPINCOUNT / OMP_WAIT_POLICY yourself to override; it must be set before the first
# import of cpp_dem (libgomp reads it when it loads).
if "OMP_WAIT_POLICY" not in _os.environ:
    _os.environ.setdefault("GOMP_SPINCOUNT", "20000")

from cpp_dem._core import (  # noqa: F401,E402  (re-exported)
    BeamParams,
    BlowUpError,
    BondParams,
    ContactModel,
    ContactPhys,
    Material,
    ParameterError,
    contact_laws,
    get_num_threads,
    material_fields,
    mix_materials,
)
from cpp_dem.build.packing import read_packing_csv, write_packing_csv  # noqa: F401
from cpp_dem._core import (CylinderServo, MembranePressure, MeshServo,  # noqa: F401
                           PlatenClamp, RadiusGrowth, ServoWall, TriaxialController)
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint  # noqa: F401
from cpp_dem.scene import (BOX_WALLS, ControllerLimitWarning, Scene, apply_threads,
                           free_cores, hertz_mindlin_material,  # noqa: F401
                           set_num_threads, threads_for,
                    PhysicalRangeWarning, ServoTargetWarning, TargetNotMetWarning,
                    TimeStepWarning,
                    linear_material)
from cpp_dem.measure.inertial import InertialNumberWarning  # noqa: F401,E402

from cpp_dem.build import geogrid  # noqa: F401,E402
from cpp_dem.build import packing
from cpp_dem.protocols import periodic
from cpp_dem._core import CellController  # noqa: F401,E402  (periodic cells)
from cpp_dem.elements.periodic import DemElement  # noqa: F401,E402
from cpp_dem.elements.increments import ContactLossWarning  # noqa: F401,E402

__all__ = [
    "BeamParams",
    "BondParams",
    "CellController",
    "DemElement",
    "periodic",
    "geogrid",
    "BOX_WALLS",
    "apply_threads",
    "free_cores",
    "threads_for",
    "CylinderServo",
    "MembranePressure",
    "MeshServo",
    "PlatenClamp",
    "RadiusGrowth",
    "ServoWall",
    "TriaxialController",
    "load_checkpoint",
    "save_checkpoint",
    "read_packing_csv",
    "write_packing_csv",
    "BlowUpError",
    "ContactModel",
    "ContactLossWarning",
    "ControllerLimitWarning",
    "ServoTargetWarning",
    "PhysicalRangeWarning",
    "TimeStepWarning",
    "InertialNumberWarning",
    "TargetNotMetWarning",
    "ContactPhys",
    "Material",
    "ParameterError",
    "Scene",
    "get_num_threads",
    "hertz_mindlin_material",
    "linear_material",
    "mix_materials",
    "contact_laws",
    "material_fields",
    "set_num_threads",
]
