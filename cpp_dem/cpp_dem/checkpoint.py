"""Checkpoints to HDF5 and exact restart.

``save_checkpoint(path, scene)`` writes the whole state of the scene and of its controllers
(the binary blob of the C++ ``Checkpoint``, dataset ``/checkpoint/blob``) plus readable copies
of the main arrays (positions, velocities, radii, walls) and ``extra`` metadata.
``load_checkpoint(path, scene)`` restores it into the scene it came from — the same kind
(periodic or not), bodies (count, each one's kind and clump), clumps and walls (count, axis and
side), materials and pair laws (every value) — or into a new, empty ``Scene()``; ``replace=True`` lets it replace another scene. The
scene must hold the same controllers (same number and kinds, added in the same order — they are
code, the checkpoint restores their state), and the stored values must pass the checks of the
API's setters. Running n steps after loading gives bitwise the same state as running on.

Every dataset carries the SHA-256 of its bytes (attribute ``sha256``), and the file the SHA-256
of its header (format, step, time and ``extra_json``: attribute ``header_sha256``).
``load_checkpoint`` checks them before it touches the scene: a file changed after it was
written (one flipped byte) is refused with a ``ParameterError`` naming the file and the
dataset. The file holds no time stamps and the state's records no uninitialised padding, so
two identical runs write byte-identical checkpoints.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings

import numpy as np

from cpp_dem import _core

FORMAT = "cpp_dem.checkpoint/2"
#: Checkpoints written before checksums were added: still read, with a warning.
_FORMAT_UNCHECKED = "cpp_dem.checkpoint/1"
#: The dataset holding the scene's state, and the readable copies (not read by the restart).
_BLOB = "checkpoint/blob"
_READABLE = ("positions", "velocities", "radii", "wall_positions", "wall_velocities")


def _sha256(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def _header_sha256(fmt: str, step: int, time: float, extra_json: str) -> str:
    text = json.dumps([fmt, int(step), float(time).hex(), extra_json])
    return hashlib.sha256(text.encode()).hexdigest()


def save_checkpoint(path: str | os.PathLike, scene, *, extra: dict | None = None) -> None:
    """Writes the scene's full state to the HDF5 file ``path`` (replaced atomically).

    ``extra`` is a dict of JSON values kept with the state (returned by ``load_checkpoint``)."""
    import h5py

    try:
        extra_json = json.dumps(extra or {})
    except (TypeError, ValueError) as e:
        raise _core.ParameterError(f"extra={extra!r}: must be a dict of JSON values (numbers, "
                                   f"strings, lists, dicts): {e}") from None
    blob = np.frombuffer(_core._checkpoint_save(scene), dtype=np.uint8)
    step, time = int(scene.step_count), float(scene.time)
    tmp = f"{os.fspath(path)}.tmp"

    def dataset(group, name, data):
        a = np.ascontiguousarray(data)
        # No modification times: two identical runs write byte-identical files.
        d = group.create_dataset(name, data=a, track_times=False)
        d.attrs["sha256"] = _sha256(a)

    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["step"] = step
            f.attrs["time"] = time
            f.attrs["extra_json"] = extra_json
            f.attrs["header_sha256"] = _header_sha256(FORMAT, step, time, extra_json)
            dataset(f.create_group("checkpoint"), "blob", blob)
            r = f.create_group("readable")
            dataset(r, "positions", np.asarray(scene.positions))
            dataset(r, "velocities", np.asarray(scene.velocities))
            dataset(r, "radii", np.asarray(scene.radii))
            dataset(r, "wall_positions", np.asarray(scene.wall_positions))
            dataset(r, "wall_velocities", np.asarray(scene.wall_velocities))
        os.replace(tmp, path)
    except (OSError, RuntimeError) as e:
        # A full disk or a file-size limit (h5py reports either); nothing partial is left.
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise OSError(f"{os.fspath(path)}: the checkpoint could not be written ({e}); the disk "
                      "may be full or a file-size limit reached; no partial file was left") from e


def _checked(path: str, f, name: str, *, required: bool) -> np.ndarray | None:
    """The dataset ``name`` of the open checkpoint ``f``, its checksum verified."""
    bad = _core.ParameterError if required else None
    if name not in f or not hasattr(f[name], "dtype"):
        msg = (f"{path}: no dataset {name}" + (" (the scene's state)" if required else "")
               + "; the file is not a complete checkpoint written by save_checkpoint")
        if bad:
            raise bad(msg)
        warnings.warn(msg, UserWarning, stacklevel=3)
        return None
    d = f[name]
    try:
        a = d[()]
    except (OSError, RuntimeError) as e:  # a damaged chunk or header
        msg = f"{path}: dataset {name} cannot be read ({e}); the file is damaged"
        if bad:
            raise bad(msg) from None
        warnings.warn(msg, UserWarning, stacklevel=3)
        return None
    if f.attrs.get("format") == _FORMAT_UNCHECKED:
        return a
    want = d.attrs.get("sha256")
    if want is None:
        msg = (f"{path}: dataset {name} carries no checksum (attribute sha256); the file was not "
               "written by save_checkpoint or was altered")
    elif _sha256(a) != want:
        msg = (f"{path}: dataset {name} does not match its checksum (SHA-256 {_sha256(a)[:16]}…, "
               f"recorded {str(want)[:16]}…): the file changed after it was written (a damaged "
               "disk or copy, or an edit)")
    else:
        return a
    if bad:
        raise bad(msg + "; restart from another checkpoint")
    warnings.warn(msg + "; the state is intact, this readable copy is not", UserWarning,
                  stacklevel=3)
    return None


def _header(path, f) -> dict:
    """The checked header of the open checkpoint ``f``: its format, and its extra JSON
    against the header's checksum (ParameterError naming ``path`` otherwise)."""
    fmt = f.attrs.get("format")
    if fmt not in (FORMAT, _FORMAT_UNCHECKED):
        raise _core.ParameterError(f"{path}: format {fmt!r}, expected {FORMAT!r} (a file "
                                   "written by save_checkpoint)")
    if fmt == _FORMAT_UNCHECKED:
        warnings.warn(f"{path}: a checkpoint of format {fmt!r}, written before checkpoints "
                      "carried checksums: it is loaded unverified", UserWarning, stacklevel=3)
    missing = [k for k in ("step", "time", "extra_json") if k not in f.attrs]
    if missing:
        raise _core.ParameterError(f"{path}: attribute {missing[0]} missing; the file is not "
                                   "a complete checkpoint written by save_checkpoint")
    extra_json = f.attrs["extra_json"]
    if fmt == FORMAT:
        want = f.attrs.get("header_sha256")
        try:
            got = _header_sha256(fmt, f.attrs["step"], f.attrs["time"], extra_json)
        except (TypeError, ValueError):
            got = None
        if want is None or got != want:
            raise _core.ParameterError(
                f"{path}: the header (attributes step, time, extra_json) "
                + ("carries no checksum (attribute header_sha256)" if want is None else
                   "does not match its checksum (attribute header_sha256)")
                + "; the file changed after it was written; restart from another checkpoint")
    try:
        extra = json.loads(extra_json)
    except (TypeError, ValueError) as e:
        raise _core.ParameterError(f"{path}: attribute extra_json is not readable JSON "
                                   f"({e}): {str(extra_json)[:80]!r}") from None
    if not isinstance(extra, dict):
        raise _core.ParameterError(f"{path}: attribute extra_json holds a "
                                   f"{type(extra).__name__}, expected a JSON object (dict)")
    return extra


def _open(path: str):
    """The checkpoint ``path`` open for reading (h5py), or a ParameterError naming it."""
    import h5py

    try:
        return h5py.File(path, "r")
    except OSError as e:
        raise _core.ParameterError(f"{path}: not a readable checkpoint (an HDF5 file "
                                   f"written by save_checkpoint): {e}") from None


def checkpoint_extra(path: str | os.PathLike) -> dict:
    """The ``extra`` dict of the checkpoint ``path`` (its header checked against its
    checksum, as ``load_checkpoint`` checks it), without loading its state."""
    path = os.fspath(path)
    with _open(path) as f:
        return _header(path, f)


def load_checkpoint(path: str | os.PathLike, scene, *, replace: bool = False) -> dict:
    """Restores the state saved in ``path`` into ``scene``; returns the ``extra`` dict.

    ``scene`` is the scene the checkpoint came from (rebuilt the same way: its kind, bodies,
    clumps, walls and controllers) or a new, empty ``Scene()`` holding the same controllers;
    ``replace=True`` lets the checkpoint replace a scene of another kind or size.

    Every problem of the file (not a checkpoint, a missing part, a checksum that does not match,
    unreadable ``extra_json``, another build's layout, other controllers, another scene without
    ``replace``, a stored value the API's setters refuse) raises a ``ParameterError`` naming
    the file and leaves ``scene`` as it was."""
    if not isinstance(replace, bool):
        raise _core.ParameterError(f"replace={replace!r}: must be True or False")
    path = os.fspath(path)
    with _open(path) as f:
        extra = _header(path, f)
        a = _checked(path, f, _BLOB, required=True)
        if a.dtype != np.uint8 or a.ndim != 1:
            raise _core.ParameterError(f"{path}: dataset {_BLOB} holds {a.dtype} of shape "
                                       f"{a.shape}, expected bytes (uint8, one dimension)")
        blob = a.tobytes()
        for name in _READABLE:  # not used by the restart: a damaged copy is only reported
            _checked(path, f, f"readable/{name}", required=False)
    try:
        _core._checkpoint_load(scene, blob, replace=replace)
    except _core.ParameterError as e:
        raise _core.ParameterError(f"{path}: {e}") from None
    return extra
