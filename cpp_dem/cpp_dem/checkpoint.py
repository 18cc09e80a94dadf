"""Checkpoints to HDF5 and exact restart.

``save_checkpoint(path, scene)`` writes the whole state of the scene and of its controllers
(the binary blob of the C++ ``Checkpoint``, dataset ``/checkpoint/blob``) plus readable copies
of the main arrays (positions, velocities, radii, walls) and ``extra`` metadata.
``load_checkpoint(path, scene)`` restores it into a scene that holds the same controllers
(same number and kinds, added in the same order — they are code, the checkpoint restores their
state); running n steps after loading gives bitwise the same state as running on.
"""

from __future__ import annotations

import json
import os

import numpy as np

from . import _core

FORMAT = "cpp_dem.checkpoint/1"


def save_checkpoint(path: str | os.PathLike, scene, *, extra: dict | None = None) -> None:
    """Writes the scene's full state to the HDF5 file ``path`` (replaced atomically)."""
    import h5py

    blob = _core._checkpoint_save(scene)
    tmp = f"{os.fspath(path)}.tmp"
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["step"] = int(scene.step_count)
            f.attrs["time"] = float(scene.time)
            f.attrs["extra_json"] = json.dumps(extra or {})
            g = f.create_group("checkpoint")
            g.create_dataset("blob", data=np.frombuffer(blob, dtype=np.uint8))
            r = f.create_group("readable")
            r.create_dataset("positions", data=np.asarray(scene.positions))
            r.create_dataset("velocities", data=np.asarray(scene.velocities))
            r.create_dataset("radii", data=np.asarray(scene.radii))
            r.create_dataset("wall_positions", data=np.asarray(scene.wall_positions))
            r.create_dataset("wall_velocities", data=np.asarray(scene.wall_velocities))
        os.replace(tmp, path)
    except (OSError, RuntimeError) as e:
        # A full disk or a file-size limit (h5py reports either); nothing partial is left.
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise OSError(f"{os.fspath(path)}: the checkpoint could not be written ({e}); the disk "
                      "may be full or a file-size limit reached; no partial file was left") from e


def load_checkpoint(path: str | os.PathLike, scene) -> dict:
    """Restores the state saved in ``path`` into ``scene``; returns the ``extra`` dict."""
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise _core.ParameterError(f"{os.fspath(path)}: not a readable checkpoint (an HDF5 file "
                                   f"written by save_checkpoint): {e}") from None
    with f:
        if f.attrs.get("format") != FORMAT:
            raise _core.ParameterError(f"{path}: format {f.attrs.get('format')!r}, expected "
                                       f"{FORMAT!r}")
        blob = f["checkpoint/blob"][()].tobytes()
        extra = json.loads(f.attrs["extra_json"])
    _core._checkpoint_load(scene, blob)
    return extra
