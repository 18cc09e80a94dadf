"""The deposition case (its code: geogrid_dem/cases/deposition.py; also
``geogrid-dem run deposition`` and ``python -m geogrid_dem.cases.deposition``). Run it with
--smoke or --help; imported, this module offers everything the case module has."""

import sys

from geogrid_dem.cases import deposition as _case

globals().update({k: v for k, v in vars(_case).items() if not k.startswith("__")})

if __name__ == "__main__":
    sys.exit(_case.main())
