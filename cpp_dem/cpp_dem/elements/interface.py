"""The one interface of the DEM elements that a continuum model drives and that the pool
(``cpp_dem.elements.pool.ElementPool``) keeps on Dask workers.

Every element is a ``PoolElement``: its whole state as bytes, and back, bitwise.

    ``to_bytes() -> bytes``          the state the pool saves at ``accept()``, spills to disk,
                                     moves to a worker that joins late, and restores a lost
                                     worker's element from
    ``from_bytes(data)``             (a classmethod) the element again; run on, it gives
                                     bitwise what the saved element would have given

It is driven in one of two ways (one family, two ways in):

- **strain-driven** (``StrainElement``): ``apply_strain(de, **kw)`` takes a 3 x 3
  displacement-gradient increment (-) and returns the stress (3 x 3, Pa, tension positive);
  ``contact_count()``, ``stress_scatter()``, ``network_tangent()`` and ``fd_tangent()`` give
  what a Newton iteration needs. ``cpp_dem.DemElement`` in both its kinds: a periodic cell
  (``DemElement.periodic``) or a box of six servo walls (``DemElement.box``). The
  hierarchical mode and ``femcoupling.materials.dem_elements.PoolRegionMaterials`` drive these
  (``ElementPool.build`` / ``apply_strain``).
- **target-driven** (``TargetElement``): ``run(initial, final)`` takes the FEM region's
  state before and after the load (``femcoupling.coupling.handover.WallTargets``) and
  returns the element's answer (``femcoupling.coupling.twoway.ElementResponse``).
  ``RunnerElement`` makes one of a two-way ``element_runner`` (a picklable callable
  ``runner(name, initial, final)``) and a region name: the case's walled box element with
  its geogrid (``geogrid_dem.studies.prs_element``) or a periodic element servo-controlled to
  the full tensor (``femcoupling.materials.dem_elements.PeriodicRegionElement``). The
  two-way loop drives these (``ElementPool.runners`` / ``run``).

**A RunnerElement's bytes hold code** (its runner, pickled as Dask sends it), so they are
restored only in the session that made them: ``to_bytes`` signs them (HMAC-SHA-256) with the
key of the client process that made the runner (``RunnerFactory``, or this process), which
the pool's hosts on the workers are given; ``from_bytes`` checks the signature before it
unpickles anything, and refuses bytes of another session or of a file (``ParameterError``).
The rest is cpp_dem's element format (``cpp_dem.elements.state_format``).

**A runner's byte state is optional.** A runner with ``state() -> bytes`` and
``set_state(bytes)`` (``PeriodicRegionElement``: the elements it prepared) is saved with its
element at every ``accept()`` and, after a lost worker or a move to a late worker, restored
from that state. A runner without them (the ``prs_element`` case's runner: its prepared
element is a live scene in its worker's memory) is saved as it was sent: after a loss or a
move, its region runs again from the runner as sent, which prepares its element again. The
answers are the same (the preparation is deterministic); only the time differs.

``check_element`` and ``check_runner`` refuse an object that lacks a method of its kind, by
name, before it reaches a worker.
"""

from __future__ import annotations

import hmac
import secrets
from typing import Any, Protocol, runtime_checkable

from cpp_dem._core import ParameterError
from cpp_dem.elements import state_format

__all__ = ["PoolElement", "RunnerElement", "RunnerFactory", "StrainElement", "TargetElement",
           "check_element", "check_runner", "element_methods"]


@runtime_checkable
class PoolElement(Protocol):
    """What the pool saves, moves and restores (see the module doc)."""

    def to_bytes(self) -> bytes: ...

    @classmethod
    def from_bytes(cls, data: bytes) -> "PoolElement": ...


@runtime_checkable
class StrainElement(PoolElement, Protocol):
    """A strain-driven element (``cpp_dem.DemElement``)."""

    def apply_strain(self, de: Any, **kw: Any) -> Any: ...

    def contact_count(self) -> int: ...

    def stress_scatter(self) -> Any: ...

    def network_tangent(self, **kw: Any) -> Any: ...

    def fd_tangent(self, **kw: Any) -> Any: ...


@runtime_checkable
class TargetElement(PoolElement, Protocol):
    """A target-driven element (``RunnerElement``)."""

    def run(self, initial: Any, final: Any) -> Any: ...


_METHODS = {StrainElement: ("apply_strain", "contact_count", "stress_scatter",
                            "network_tangent", "fd_tangent", "to_bytes", "from_bytes"),
            TargetElement: ("run", "to_bytes", "from_bytes")}


def element_methods(kind: type) -> tuple:
    """The methods an element of ``kind`` (``StrainElement`` or ``TargetElement``) needs."""
    return _METHODS[kind]


def check_element(obj: Any, kind: type, field: str) -> Any:
    """``obj`` (an element, or an element class) if it has every method of ``kind``
    (``StrainElement`` or ``TargetElement``; ``from_bytes`` looked up on its class); else a
    ParameterError naming ``field``, the object's type and the missing methods."""
    if kind not in _METHODS:
        raise ParameterError(f"kind={kind!r}: StrainElement or TargetElement")
    cls = obj if isinstance(obj, type) else type(obj)  # (a class: checked on the class)
    missing = [m for m in _METHODS[kind]
               if not callable(getattr(cls if m == "from_bytes" else obj, m, None))]
    if missing:
        raise ParameterError(
            f"{field}: a {cls.__name__} has no {', '.join(m + '()' for m in missing)} "
            f"method; a {kind.__name__} needs {', '.join(m + '()' for m in _METHODS[kind])} "
            "(cpp_dem.elements.interface)")
    return obj


def check_runner(runner: Any, field: str = "element_runner") -> Any:
    """``runner`` if it can be a ``RunnerElement``'s runner: callable as
    ``runner(name, initial, final)``, with both or neither of ``state()`` and
    ``set_state(bytes)``; else a ParameterError naming ``field`` and what is missing."""
    if not callable(runner):
        raise ParameterError(f"{field}={runner!r:.200}: not callable; a runner is called as "
                             "runner(name, initial, final) and returns the element's answer")
    has = {m: callable(getattr(runner, m, None)) for m in ("state", "set_state")}
    if any(has.values()) and not all(has.values()):
        lacks = [m for m, h in has.items() if not h][0]
        other = [m for m, h in has.items() if h][0]
        raise ParameterError(f"{field}: a {type(runner).__name__} has {other}() but no "
                             f"{lacks}() method; a runner's byte state needs both "
                             "(state() -> bytes, set_state(bytes)), or neither (then a lost "
                             "region runs again from the runner as sent)")
    return runner


def _dumps(obj: Any) -> bytes:
    """Pickles as Dask sends (pickle, else cloudpickle: a runner defined in a script)."""
    from distributed.protocol import pickle as dask_pickle

    return dask_pickle.dumps(obj)


def _loads(data: bytes) -> Any:
    from distributed.protocol import pickle as dask_pickle

    return dask_pickle.loads(data)


#: The kind of a RunnerElement's bytes (cpp_dem.elements.state_format).
_KIND = "cpp_dem.RunnerElement"
#: This process's key for the runners it pickles (made at import, never written anywhere).
_SESSION_KEY = secrets.token_bytes(32)
#: The keys whose signatures this process accepts: its own, and those of the clients whose
#: pools it hosts elements for (``trust_runner_key``).
_TRUSTED_KEYS: list[bytes] = [_SESSION_KEY]


def session_key() -> bytes:
    """This process's key for the RunnerElement bytes it signs (kept in memory only)."""
    return _SESSION_KEY


def trust_runner_key(key: bytes) -> None:
    """Accepts RunnerElement bytes signed with ``key`` in this process (a pool's host on a
    worker is given its client's key)."""
    if not (isinstance(key, bytes) and len(key) == 32):
        raise ParameterError("key: must be 32 bytes (interface.session_key())")
    if key not in _TRUSTED_KEYS:
        _TRUSTED_KEYS.append(key)


def _signature(key: bytes, name: str, has_state: bool, parts: dict) -> str:
    unsigned = state_format.pack(_KIND, {"name": name, "has_state": has_state}, parts)
    return hmac.new(key, unsigned, "sha256").hexdigest()


class RunnerElement:
    """A target-driven element: region ``name`` of a two-way ``runner``. ``run(initial,
    final)`` is ``runner(name, initial, final)``. Its bytes are the runner as it was sent
    (pickled when this element was made, before any run) and, if the runner has
    ``state()``, that state now, signed with ``key`` (default: this process's
    ``session_key()``); ``from_bytes`` checks the signature against the keys this process
    trusts, then unpickles the runner as sent and gives it the state with ``set_state``."""

    #: what its bytes hold, for cpp_dem.elements.state_format
    STATE_KIND = _KIND

    def __init__(self, runner: Any, name: str, *, sent: bytes | None = None,
                 key: bytes | None = None) -> None:
        check_runner(runner)
        self.runner, self.name = runner, name
        self.sent = _dumps(runner) if sent is None else sent
        self.has_state = callable(getattr(runner, "state", None))
        self.key = _SESSION_KEY if key is None else key

    def run(self, initial: Any, final: Any) -> Any:
        return self.runner(self.name, initial, final)

    def to_bytes(self) -> bytes:
        state = self.runner.state() if self.has_state else None
        if state is not None and not isinstance(state, (bytes, bytearray)):
            raise ParameterError(f"{type(self.runner).__name__}.state(): returned "
                                 f"{type(state).__name__}, expected bytes")
        parts = {"runner": bytes(self.sent), "state": b"" if state is None else bytes(state)}
        has = state is not None
        return state_format.pack(_KIND, {"name": self.name, "has_state": has,
                                         "signature": _signature(self.key, self.name, has,
                                                                 parts)}, parts)

    @classmethod
    def from_bytes(cls, data: bytes) -> "RunnerElement":
        """The element of ``to_bytes``, if its signature is one of this session's (else a
        ParameterError, before anything in the bytes is unpickled)."""
        d, parts = state_format.unpack(data, _KIND)
        name, has, sig = d.get("name"), d.get("has_state"), d.get("signature")
        if not (isinstance(name, str) and isinstance(has, bool) and isinstance(sig, str)
                and set(parts) == {"runner", "state"}):
            raise ParameterError("data: a saved RunnerElement without its fields name, "
                                 "has_state, signature and parts runner, state")
        key = next((k for k in _TRUSTED_KEYS
                    if hmac.compare_digest(_signature(k, name, has, parts), sig)), None)
        if key is None:
            raise ParameterError(
                "data: a saved RunnerElement not signed in this session (its signature "
                "matches none of this process's keys): its bytes hold code (the runner), so "
                "they are restored only in the session and pool that made them, never from "
                "elsewhere (a file, another run)")
        runner = _loads(parts["runner"])
        if has:
            runner.set_state(parts["state"])
        return cls(runner, name, sent=parts["runner"], key=key)


class RunnerFactory:
    """A picklable element maker for ``ElementPool.build``: element k is
    ``RunnerElement(runner, names[k])`` (its own copy of the runner, made on its worker),
    signing its bytes with the key of the process that made this factory."""

    def __init__(self, runner: Any, names: list) -> None:
        self.runner, self.names = runner, list(names)
        self.key = _SESSION_KEY

    def __call__(self, index: int) -> RunnerElement:
        trust_runner_key(self.key)
        sent = _dumps(self.runner)  # (a copy of its own, whatever Dask shares between calls)
        return RunnerElement(_loads(sent), self.names[index], sent=sent, key=self.key)
