"""The byte format of saved element states: parsed, never executed.

``DemElement.to_bytes``, ``LinearElement.to_bytes``, ``RunnerElement.to_bytes`` and a region
runner's ``state()`` (``femcoupling.materials.dem_elements.PeriodicRegionElement``) write
this format, and their ``from_bytes`` / ``set_state`` read it back. Nothing in it is
unpickled: its plain values are JSON, its binary parts (a scene's checkpoint blob) raw
bytes.

    offset      size  what
    0           8     magic ``b"CPDEMREC"``
    8           4     format version (uint32, little-endian): 1
    12          8     n, the size of the JSON part (uint64, little-endian)
    20          n     JSON (UTF-8), an object: ``{"kind": K, "fields": {...},
                      "parts": [[name, size], ...]}`` (``kind`` names what the bytes hold,
                      e.g. ``"cpp_dem.DemElement"``; ``fields`` its plain parameters and state;
                      floats as Python writes them, exact, ``NaN``/``Infinity`` allowed)
    20 + n      ...   the parts' bytes, one after the other, in the order of ``parts``
    end - 32    32    SHA-256 of every byte before it

:func:`unpack` checks, in this order and before anything else is read, the magic, the version,
the checksum, then parses the JSON (``json.loads``: data only) and the parts' sizes, and the
kind; each refusal is a ``ParameterError`` naming the field (``data``) and what is wrong. So a
pickle (or any other bytes) is refused at its first eight bytes: no code in it runs.
"""

from __future__ import annotations

import hashlib
import json
import struct
from typing import Any

from cpp_dem._core import ParameterError

__all__ = ["MAGIC", "VERSION", "pack", "unpack"]

MAGIC = b"CPDEMREC"
VERSION = 1
_HEAD = struct.Struct("<8sIQ")  # magic, version, JSON size
_SUM = 32  # SHA-256


def pack(kind: str, fields: dict[str, Any], parts: dict[str, bytes] | None = None) -> bytes:
    """``fields`` (JSON values: numbers, strings, booleans, None, lists and dicts of them) and
    ``parts`` (name -> bytes) as the bytes of ``kind``. Deterministic: the same values give
    the same bytes."""
    parts = {} if parts is None else parts
    try:
        text = json.dumps({"kind": kind, "fields": fields,
                           "parts": [[k, len(v)] for k, v in parts.items()]},
                          sort_keys=True, separators=(",", ":")).encode()
    except (TypeError, ValueError) as e:
        raise ParameterError(f"fields of {kind}: not plain JSON values ({e})") from None
    body = b"".join([_HEAD.pack(MAGIC, VERSION, len(text)), text,
                     *(bytes(v) for v in parts.values())])
    return body + hashlib.sha256(body).digest()


def unpack(data: Any, kind: str, *, field: str = "data"
           ) -> tuple[dict[str, Any], dict[str, bytes]]:
    """(fields, parts) of bytes :func:`pack` wrote for ``kind``; refuses anything else by name
    (see the module doc), without running anything in it."""
    what = f"a saved {kind.rsplit('.', 1)[-1]}"
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise ParameterError(f"{field}: a {type(data).__name__}, expected the bytes of {what}")
    data = bytes(data)
    if len(data) < _HEAD.size + _SUM or data[:8] != MAGIC:
        raise ParameterError(
            f"{field}: not {what} (starts with {data[:8]!r}, expected {MAGIC!r}, the magic of "
            "cpp_dem's element format; cpp_dem.elements.state_format). Bytes of another format, "
            "e.g. a pickle, are never unpickled (they could run code)")
    _magic, version, n_json = _HEAD.unpack_from(data)
    if version != VERSION:
        raise ParameterError(f"{field}: element format version {version}, this build reads "
                             f"version {VERSION}")
    body, digest = data[:-_SUM], data[-_SUM:]
    if hashlib.sha256(body).digest() != digest:
        raise ParameterError(f"{field}: {what} whose SHA-256 checksum does not match (the "
                             "bytes were changed or cut after they were written)")
    end = _HEAD.size + n_json
    try:
        if end > len(body):
            raise ValueError(f"its JSON part of {n_json} bytes runs past the end")
        head = json.loads(body[_HEAD.size:end].decode())
        if not isinstance(head, dict) or not isinstance(head.get("fields"), dict):
            raise ValueError("its JSON part is not an object with 'fields'")
        sizes = head.get("parts")
        if not (isinstance(sizes, list) and all(
                isinstance(p, list) and len(p) == 2 and isinstance(p[0], str)
                and isinstance(p[1], int) and p[1] >= 0 for p in sizes)):
            raise ValueError("its 'parts' are not a list of [name, size]")
        if end + sum(p[1] for p in sizes) != len(body):
            raise ValueError("its parts' sizes do not add up to its length")
    except (ValueError, UnicodeDecodeError, RecursionError) as e:
        raise ParameterError(f"{field}: {what} that cannot be read: {e}") from None
    if head.get("kind") != kind:
        raise ParameterError(f"{field}: the bytes of {head.get('kind')!r}, expected {kind!r}")
    parts, at = {}, end
    for name, size in sizes:
        parts[name] = body[at:at + size]
        at += size
    return head["fields"], parts
