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

from ._core import (  # noqa: F401  (re-exported)
    BeamParams,
    BlowUpError,
    ContactModel,
    ContactPhys,
    Material,
    ParameterError,
    get_num_threads,
    mix_materials,
    set_num_threads,
)
from .packing import read_packing_csv, write_packing_csv  # noqa: F401
from ._core import RadiusGrowth, ServoWall, TriaxialController  # noqa: F401  (samples)
from .checkpoint import load_checkpoint, save_checkpoint  # noqa: F401
from .scene import BOX_WALLS, Scene, hertz_mindlin_material, linear_material  # noqa: F401

from . import geogrid, packing  # noqa: F401,E402

__all__ = [
    "BeamParams",
    "geogrid",
    "BOX_WALLS",
    "RadiusGrowth",
    "ServoWall",
    "TriaxialController",
    "load_checkpoint",
    "save_checkpoint",
    "read_packing_csv",
    "write_packing_csv",
    "BlowUpError",
    "ContactModel",
    "ContactPhys",
    "Material",
    "ParameterError",
    "Scene",
    "get_num_threads",
    "hertz_mindlin_material",
    "linear_material",
    "mix_materials",
    "set_num_threads",
]
