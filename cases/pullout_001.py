"""The pullout_001 case, from the thesis (its code: geogrid_dem/cases/pullout_001.py; also
``geogrid-dem run pullout-001`` and ``python -m geogrid_dem.cases.pullout_001``). Run it with
--smoke or --help; imported, this module offers everything the case module has."""

import sys

from geogrid_dem.cases import pullout_001 as _case

globals().update({k: v for k, v in vars(_case).items() if not k.startswith("__")})

if __name__ == "__main__":
    sys.exit(_case.main())
