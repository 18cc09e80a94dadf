"""Result files (the writers live in :mod:`cpp_dem.io`: ``io.vtk``, ``io.hdf5``, ``io.csvfile``,
``io.series``); this module keeps the names where they always were."""

from .io import *  # noqa: F401,F403
from .io import __all__  # noqa: F401
from .io._files import _atomic_write_bytes  # noqa: F401  (used by older callers)
