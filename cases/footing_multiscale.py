"""The footing_multiscale case, from the prestressed-element paper (its code:
geogrid_dem/cases/footing_multiscale.py; also ``geogrid-dem run footing-multiscale`` and
``python -m geogrid_dem.cases.footing_multiscale``). Run it with --smoke or --help; imported,
this module offers everything the case module has."""

import sys

from geogrid_dem.cases import footing_multiscale as _case

globals().update({k: v for k, v in vars(_case).items() if not k.startswith("__")})

if __name__ == "__main__":
    sys.exit(_case.main())
