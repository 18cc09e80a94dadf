"""CSV recorder and reader (cpp_dem.io)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ._files import PathLike, _ClosesOnExit, write_error
from .series import Series, _check_overwrite, _evaluate, _series_for


# CSV recorder
# ---------------------------------------------------------------------------------------------


class CsvRecorder(_ClosesOnExit):
    """Writes series as CSV rows, one per :meth:`record`, flushed per row (and fsync'ed with
    ``fsync=True``).

    A plain CSV: the first line is the header, then one row per record; any CSV reader opens
    it as it is. The units are those of the series (``units``, the same as the ``units``
    attributes of an :class:`H5Recorder` file with the same series; for
    :func:`standard_series` see its docstring). A series with vector values (e.g. a (3,) wall
    force) takes one column per
    component: ``<name>_x``, ``<name>_y``, ``<name>_z`` for a (3,) vector, else ``<name>_0``,
    ``<name>_1``, ... over the flattened value (the shape is fixed by the first record). Read
    back with :func:`read_csv_series` (or ``numpy.genfromtxt(path, delimiter=",",
    names=True)``, ``pandas.read_csv(path)``).

    Parameters are those of :class:`H5Recorder`: ``path``, ``scene``, ``series``,
    ``overwrite``, ``append`` (the header must match).
    """

    def __init__(self, path: PathLike, scene=None, *, series: Series | None = None,
                 overwrite: bool = False, append: bool = False, fsync: bool = False) -> None:
        self.path = Path(path)
        self.scene = scene
        self.series = _series_for(series, scene)
        self.fsync = fsync
        #: series name -> units
        self.units = {k: u for k, (_f, u) in self.series.items()}
        mode = _check_overwrite(self.path, overwrite, append, "CsvRecorder")
        self._columns: list[str] | None = None
        self._stored_header: list[str] | None = None
        self.num_records = 0
        if mode == "a":
            with open(self.path, encoding="utf-8") as fh:
                header = [ln.rstrip("\n") for ln in fh if ln.strip()]
            if header:
                self._stored_header = header[0].split(",")
                self.num_records = len(header) - 1
            self._fh = open(self.path, "a", encoding="utf-8", newline="")
        else:
            self._fh = open(self.path, "w" if mode == "w" else "x", encoding="utf-8", newline="")
        self._register()

    def _flush(self) -> None:
        self._fh.flush()
        if self.fsync:
            os.fsync(self._fh.fileno())

    def _abandon(self) -> None:
        """Closes the file without raising (after a failed write)."""
        fh, self._fh = self._fh, None
        if fh is not None:
            try:
                fh.close()
            except OSError:
                pass

    def record(self, scene=None, **values: Any) -> None:
        """Appends one row (series evaluated as in :meth:`H5Recorder.record`) and flushes. A
        failed write (disk full, a file-size limit) raises :class:`ResultWriteError` naming
        the file, and closes it: the rows flushed before stay readable."""
        if getattr(self, "_error", None) is not None:
            raise self._error  # an earlier write failed: the file is closed for good
        n = self.num_records
        try:
            self._record(scene, **values)
        except OSError as e:
            self._abandon()
            self._error = write_error(self.path, e, f"closed after {n} rows (they stay "
                                      "readable)")
            raise self._error from None

    def _record(self, scene=None, **values: Any) -> None:
        if self._fh is None:
            raise ValueError(f"{self.path}: recorder is closed")
        sc = scene if scene is not None else self.scene
        row = _evaluate(self.series, sc, values)
        cols: list[str] = []
        cells: list[str] = []
        for name, a in row.items():
            flat = a.reshape(-1)
            if a.ndim == 0:
                cols.append(name)
            elif a.shape == (3,):
                cols += [f"{name}_{c}" for c in "xyz"]
            else:
                cols += [f"{name}_{i}" for i in range(flat.size)]
            for v in flat:
                cells.append(str(int(v)) if a.dtype.kind in "biu" else repr(float(v)))
        if self._columns is None:
            if self._stored_header is not None:
                if self._stored_header != cols:
                    raise ValueError(f"{self.path}: stored columns {self._stored_header} differ "
                                     f"from {cols}; cannot append")
            else:
                self._fh.write(",".join(cols) + "\n")
            self._columns = cols
        elif cols != self._columns:
            raise ValueError(f"{self.path}: columns changed from {self._columns} to {cols}")
        self._fh.write(",".join(cells) + "\n")
        self.num_records += 1
        self._flush()

    def close(self) -> None:
        """Flushes and closes the file. Idempotent."""
        if self._fh is not None:
            try:
                self._fh.flush()
                self._fh.close()
            except OSError as e:
                n = self.num_records
                self._abandon()
                raise write_error(self.path, e, f"closed after {n} rows") from None
            self._fh = None


def read_csv_series(path: PathLike) -> dict[str, np.ndarray]:
    """Reads a :class:`CsvRecorder` file: column name -> 1-D float array. Vector series come
    back as one column per component (``<name>_x`` ... or ``<name>_0`` ...). Lines with the
    wrong number of fields or non-numbers (e.g. a line cut by a crash) are skipped."""
    with open(path, encoding="utf-8") as fh:
        lines = [ln.rstrip("\n") for ln in fh if ln.strip()]
    if not lines:
        return {}
    cols = lines[0].split(",")
    rows = []
    for ln in lines[1:]:
        parts = ln.split(",")
        if len(parts) != len(cols):
            continue
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            continue
    data = np.asarray(rows, dtype=float).reshape(-1, len(cols))
    return {c: data[:, i].copy() for i, c in enumerate(cols)}
