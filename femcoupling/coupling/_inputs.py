"""Input checks of the coupling modules, on top of :mod:`femcoupling._checks` (the same error
type, the same message format "<field>=<value>: <what is allowed>")."""

from __future__ import annotations

import numbers
from typing import Any

from femcoupling._checks import FemInputError, _real


def check_int(name: str, value: Any, lo: int, what: str = "") -> int:
    """``value`` if it is a whole number (not a bool) >= ``lo``; else FemInputError."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo:
        raise FemInputError(f"{name}={value!r}: must be a whole number >= {lo}{what}")
    return value


def check_open(name: str, value: Any, lo: float, hi: float, what: str = "") -> float:
    """``value`` as a finite float in the open interval (``lo``, ``hi``); else
    FemInputError."""
    v = _real(name, value)
    if not lo < v < hi:
        raise FemInputError(f"{name}={v!r}: must be in ({lo:g}, {hi:g}){what}")
    return v


def check_positive(name: str, value: Any, what: str = "") -> float:
    """``value`` as a finite float > 0 (not a bool, not a string); else FemInputError saying
    so, with ``what`` it is."""
    try:
        v = _real(name, value)
    except FemInputError:
        v = None
    if v is None or not v > 0.0:
        raise FemInputError(f"{name}={value!r}: must be a finite number > 0{what}")
    return v


def check_fraction(value: Any, name: str = "min_eig_fraction") -> float:
    """A tangent's eigenvalue floor as a fraction of its largest eigenvalue: in (0, 1)."""
    return check_open(name, value, 0.0, 1.0, " (the eigenvalue floor as a fraction of the "
                      "largest eigenvalue; 1e-3 by default)")


def check_client(client: Any) -> None:
    """``client`` is None or a ``dask.distributed.Client``; else FemInputError saying what it
    must be (a scheduler's address becomes a client through
    ``cpp_dem.elements.cluster.dask_client``)."""
    if client is None:
        return
    try:
        from distributed import Client
    except ImportError:  # (no dask.distributed: nothing can be a client)
        Client = ()
    if Client and isinstance(client, Client):
        return
    raise FemInputError(
        f"client={client!r:.120}: must be a dask.distributed.Client of a running cluster, "
        "or None (a LocalCluster of `workers` processes); for a scheduler's address "
        "(tcp://host:8786) or scheduler file, cpp_dem.elements.cluster.dask_client(address, "
        "0)[0] is its client")


def check_names(name: str, value: Any, *, what: str) -> list:
    """``value`` as a list of distinct non-empty strings (not a string itself), at least
    one; else FemInputError naming ``name`` and ``what`` they are."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise FemInputError(f"{name}={value!r:.200}: must be a list of {what} (names), not "
                            f"a {type(value).__name__}")
    names = list(value)
    if not names:
        raise FemInputError(f"{name}=[]: must name at least one {what.rstrip('s')}")
    bad = [x for x in names if not (isinstance(x, str) and x)]
    if bad:
        raise FemInputError(f"{name}={names!r:.200}: {bad[0]!r} is not a name; {what} are "
                            "named by non-empty strings")
    dup = sorted({x for x in names if names.count(x) > 1})
    if dup:
        raise FemInputError(f"{name}={names!r:.200}: {dup} listed more than once; each of "
                            f"the {what} once")
    return names
