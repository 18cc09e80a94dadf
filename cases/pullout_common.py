"""Shared code of the pull-out cases (its code: geogrid_dem/cases/pullout_common.py)."""

from geogrid_dem.cases import pullout_common as _case

globals().update({k: v for k, v in vars(_case).items() if not k.startswith("__")})
