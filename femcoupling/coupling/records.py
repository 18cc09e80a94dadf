"""Appending rows to an HDF5 record: one dataset per field, resizable along the first axis,
flushed after every append (a run's records survive its end, whatever ends it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["append_rows"]


def append_rows(path: Path, rows: dict, *, units: str) -> None:
    """Appends ``rows`` (field -> array, the same first length for every field) to the HDF5
    file ``path``, creating it, with ``units`` as its attribute, at the first call."""
    import h5py

    rows = {k: np.asarray(v) for k, v in rows.items()}
    n = len(next(iter(rows.values())))
    with h5py.File(path, "a") as f:
        if not f.keys():
            f.attrs["units"] = units
            for key, v in rows.items():
                f.create_dataset(key, data=v, maxshape=(None,) + v.shape[1:], chunks=True)
        else:
            for key, v in rows.items():
                d = f[key]
                d.resize(d.shape[0] + n, axis=0)
                d[-n:] = v
        f.flush()
