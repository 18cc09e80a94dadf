"""The prs_element_002 case, from the prestressed-element paper (its code:
geogrid_dem/cases/prs_element_002.py; also ``geogrid-dem run prs-element-002`` and ``python -m
geogrid_dem.cases.prs_element_002``). Run it with --smoke or --help; imported, this module
offers everything the case module has."""

import sys

from geogrid_dem.cases import prs_element_002 as _case

globals().update({k: v for k, v in vars(_case).items() if not k.startswith("__")})

if __name__ == "__main__":
    sys.exit(_case.main())
