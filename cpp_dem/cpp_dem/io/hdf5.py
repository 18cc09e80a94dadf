"""HDF5 recorder and readers (cpp_dem.io)."""

from __future__ import annotations

import datetime as _dt
import json
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ._files import (PathLike, _ClosesOnExit, _DeallocErrors, _quiet_unraisable,
                     is_write_failure, write_error)
from .series import (CLUMP_SNAPSHOT_FIELDS, SNAPSHOT_FIELDS, Series, _check_overwrite,
                     _evaluate, _metadata_attr,
                     _series_for)


# HDF5 recorder
# ---------------------------------------------------------------------------------------------


class H5Recorder(_ClosesOnExit):
    """Appends time series and snapshots to an HDF5 file as a run goes.

    Layout::

        /                      attrs: run parameters (``metadata``), ``parameters_json``,
                               ``format``, ``created_utc``
        /series                attrs: ``num_records`` (rows that are complete),
                               ``units_json`` (the declared series and their units)
        /series/<name>         dataset (num_records, *shape), maxshape (None, *shape),
                               attrs ``units``; float series are filled with NaN
        /snapshots/NNNNNN      group per snapshot (NNNNNN = snapshot index, 0, 1, ...),
                               attrs ``time`` (s), ``step``, ``complete``; one dataset per
                               field (e.g. ``positions`` (n, 3), m) with attr ``units``

    The file is flushed after every :meth:`record` and :meth:`snapshot`, so a crash loses at
    most the record being written. ``/series`` attribute ``num_records`` is updated last:
    readers (and :func:`read_h5_series`) trust only that many rows.

    Parameters
    ----------
    path : HDF5 file.
    scene : the scene the series callables are evaluated on, or None (then pass ``scene=``
        or the values themselves to :meth:`record`).
    series : name -> callable(scene) or (callable | None, units). A callable returns a scalar
        or a fixed-shape array (e.g. a (3,) wall force); the shape is fixed by the first
        record. Default: :func:`standard_series` of ``scene``.
    snapshot_fields : per-body scene attributes stored by :meth:`snapshot`
        (see ``SNAPSHOT_FIELDS`` for names and units).
    metadata : run parameters, stored as root attributes (nested values as JSON text) and
        all together as ``parameters_json``.
    overwrite : replace an existing file. Without it (and without ``append``) an existing
        file raises ``FileExistsError``: results are never destroyed silently.
    append : continue an existing file: the series must match the stored ones; rows past
        ``num_records`` (a crashed record) are dropped; snapshot numbering continues.
    compression : HDF5 compression for snapshot arrays (e.g. ``"gzip"``) or None.
    """

    FORMAT = "cpp_dem.H5Recorder/1"

    def __init__(self, path: PathLike, scene=None, *, series: Series | None = None,
                 snapshot_fields: Sequence[str] = ("positions", "velocities", "radii"),
                 metadata: Mapping[str, Any] | None = None, overwrite: bool = False,
                 append: bool = False, compression: str | None = None,
                 chunk_rows: int = 256) -> None:
        import h5py

        self.path = Path(path)
        self.scene = scene
        self.series = _series_for(series, scene)
        for f in snapshot_fields:
            if f not in SNAPSHOT_FIELDS:
                raise ValueError(f"snapshot_fields: unknown field {f!r}; known: "
                                 f"{list(SNAPSHOT_FIELDS)}")
        self.snapshot_fields = tuple(snapshot_fields)
        self.compression = compression
        self.chunk_rows = int(chunk_rows)
        mode = _check_overwrite(self.path, overwrite, append, "H5Recorder")
        self._file = h5py.File(self.path, mode)
        try:
            self._open(mode, metadata or {})
        except BaseException as e:
            f, self._file = self._file, None
            with _quiet_unraisable():
                try:
                    f.close()
                except Exception:  # noqa: BLE001  (the file could not be written)
                    pass
            if isinstance(e, (OSError, RuntimeError)) and is_write_failure(e):
                raise write_error(self.path, e, "the file could not be started") from None
            raise
        self._register()

    def _open(self, mode: str, metadata: Mapping[str, Any]) -> None:
        f = self._file
        if mode == "a":
            if f.attrs.get("format") != self.FORMAT or "series" not in f:
                raise ValueError(f"{self.path}: not a {self.FORMAT} file; cannot append")
            g = f["series"]
            stored = set(json.loads(g.attrs.get("units_json", "{}"))) | set(g.keys())
            if stored != set(self.series):
                raise ValueError(f"{self.path}: stored series {sorted(stored)} differ from "
                                 f"the requested {sorted(self.series)}; cannot append")
            self.num_records = int(g.attrs.get("num_records", 0))
            for name, (_fn, units) in self.series.items():
                if name not in g:  # declared, never recorded
                    continue
                ds = g[name]
                if units and ds.attrs.get("units", "") != units:
                    raise ValueError(f"{self.path}: series {name!r} stored in "
                                     f"{ds.attrs.get('units')!r}, requested {units!r}")
                if ds.shape[0] != self.num_records:  # a crash inside record(): drop the row
                    ds.resize(self.num_records, axis=0)
            snaps = f.require_group("snapshots")
            done = [int(k) for k in snaps.keys() if k.isdigit()]
            self.num_snapshots = max(done) + 1 if done else 0
            old = json.loads(f.attrs.get("parameters_json", "{}"))
            for k, v in metadata.items():
                new = json.loads(json.dumps(v, default=str))
                if k in old and old[k] != new:
                    raise ValueError(f"{self.path}: metadata {k!r}={new!r} differs from the "
                                     f"stored {old[k]!r}; cannot append")
            merged = {**old, **json.loads(json.dumps(dict(metadata), default=str))}
            self._write_metadata(merged)
        else:
            f.attrs["format"] = self.FORMAT
            f.attrs["created_utc"] = _dt.datetime.now(_dt.timezone.utc).isoformat()
            self._write_metadata(json.loads(json.dumps(dict(metadata), default=str)))
            g = f.create_group("series")
            g.attrs["num_records"] = 0
            g.attrs["units_json"] = json.dumps({k: u for k, (_f, u) in self.series.items()})
            f.create_group("snapshots")
            self.num_records = 0
            self.num_snapshots = 0
        f.flush()

    def _write_metadata(self, metadata: Mapping[str, Any]) -> None:
        f = self._file
        for k, v in metadata.items():
            if k in ("format", "created_utc", "parameters_json"):
                raise ValueError(f"metadata key {k!r} is reserved")
            f.attrs[k] = _metadata_attr(v)
        f.attrs["parameters_json"] = json.dumps(dict(metadata), default=str, sort_keys=True)

    # -- writing -------------------------------------------------------------------------------
    def _writing(self, write):
        """Runs ``write`` and returns its result; a write failure (disk full, a file-size
        limit) is raised as the ResultWriteError of :meth:`_failed`, other errors as they are."""
        try:
            return write()
        except (OSError, RuntimeError) as e:
            err = self._failed(e)
            if err is e:
                raise
            raise err from None

    def _failed(self, e: BaseException) -> Exception:
        """The error to raise for ``e`` from a write: a ResultWriteError naming the file (which
        is then closed) when the file could not be written, else ``e`` itself."""
        if not (isinstance(e, (OSError, RuntimeError)) and is_write_failure(e)):
            return e
        kept = (f"closed after {self.num_records} records and {self.num_snapshots} snapshots "
                "(the records flushed before stay readable)")
        err = write_error(self.path, e, kept)
        self._error = err  # raised again by a later write: the file is closed for good
        with _quiet_unraisable():
            e.__traceback__ = None  # frees the failed write's HDF5 objects before the close
            self._abandon()
        return err

    def _abandon(self) -> None:
        """Closes the file without raising (after a failed write). HDF5 can crash when it
        closes a file whose writes failed (it flushes its cache again): the file's descriptor
        is pointed at /dev/null first, so what HDF5 writes on closing goes nowhere and the
        file on disk keeps what was written before."""
        f, self._file = self._file, None
        if f is not None:
            import os

            try:
                fd = f.id.get_vfd_handle()
                null = os.open(os.devnull, os.O_WRONLY)
                os.dup2(null, fd)
                os.close(null)
            except Exception:  # noqa: BLE001  (another driver: close as it is)
                pass
            with _quiet_unraisable():
                try:
                    f.close()
                except Exception:  # noqa: BLE001
                    pass

    def record(self, scene=None, **values: Any) -> None:
        """Appends one row to every series and flushes the file (see :meth:`_record`). A
        failed write (disk full, a file-size limit) raises :class:`ResultWriteError` naming
        the file, and closes it."""
        if getattr(self, "_error", None) is not None:
            raise self._error
        self._writing(lambda: self._guarded(lambda: self._record(scene, **values)))

    def snapshot(self, scene=None, *, fields: Sequence[str] | None = None,
                 extra: Mapping[str, tuple[Any, str]] | None = None) -> str:
        """Stores per-body arrays in a new group (see :meth:`_snapshot`); a failed write raises
        :class:`ResultWriteError` naming the file, and closes it."""
        if getattr(self, "_error", None) is not None:
            raise self._error
        return self._writing(
            lambda: self._guarded(lambda: self._snapshot(scene, fields=fields, extra=extra)))

    #: Room kept free beyond a write's data for HDF5's own metadata, bytes.
    ROOM_MARGIN = 256 * 1024

    def _check_room(self, nbytes: int) -> None:
        """Refuses a write of about ``nbytes`` that the disk or the file-size limit has no room
        for (with ROOM_MARGIN for the metadata) before HDF5 starts it: HDF5 recovers badly
        from a write that fails inside its cache (it can crash when the file is closed)."""
        import errno
        import os
        import resource

        need = int(nbytes) + self.ROOM_MARGIN
        try:
            size = os.path.getsize(self.path)
            st = os.statvfs(self.path.parent)
        except OSError:
            return
        soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        if soft != resource.RLIM_INFINITY and size + need > soft:
            raise OSError(errno.EFBIG, os.strerror(errno.EFBIG), str(self.path))
        if st.f_bavail * st.f_frsize < need:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))

    def _guarded(self, body):
        """Runs ``body`` (which writes), then flushes the file; a write failure that HDF5
        reports only through an object's destructor is raised (and the file not flushed)."""
        with _DeallocErrors() as caught:
            result = body()
        failed = caught.failure()
        if failed is not None:
            raise failed
        with _DeallocErrors() as caught:
            self._file.flush()
        failed = caught.failure()
        if failed is not None:
            raise failed
        return result

    def _record(self, scene=None, **values: Any) -> None:
        """Appends one row to every series and flushes the file.

        Each series is evaluated as ``callable(scene)`` (``scene`` defaults to the recorder's
        scene) unless its value is given by keyword, e.g. ``record(time=0.1, kinetic=2e-3)``.
        """
        if self._file is None:
            raise ValueError(f"{self.path}: recorder is closed")
        sc = scene if scene is not None else self.scene
        row = _evaluate(self.series, sc, values)
        self._check_room(sum(self.chunk_rows * a.nbytes for a in row.values()))
        g = self._file["series"]
        k = self.num_records
        for name, a in row.items():
            if name not in g:
                dtype = np.float64 if a.dtype.kind == "f" else np.int64
                if a.dtype.kind == "b":
                    dtype = np.int8
                ds = g.create_dataset(
                    name, shape=(0,) + a.shape, maxshape=(None,) + a.shape, dtype=dtype,
                    chunks=(self.chunk_rows,) + a.shape,
                    fillvalue=np.nan if dtype == np.float64 else 0)
                ds.attrs["units"] = self.series[name][1]
            ds = g[name]
            if ds.shape[1:] != a.shape:
                raise ValueError(f"series {name!r}: value of shape {a.shape}, the stored "
                                 f"rows have shape {ds.shape[1:]}")
            ds.resize(k + 1, axis=0)
            ds[k] = a
        g.attrs["num_records"] = k + 1
        self.num_records = k + 1

    def _snapshot(self, scene=None, *, fields: Sequence[str] | None = None,
                  extra: Mapping[str, tuple[Any, str]] | None = None) -> str:
        """Stores per-body arrays in a new group ``/snapshots/NNNNNN``; returns its name.

        ``fields`` defaults to the recorder's ``snapshot_fields`` (with clumps in the scene,
        ``clump_ids``, ``clump_positions`` and ``clump_orientations`` too); ``extra`` adds arrays as
        name -> (array, units). The group's attrs hold ``time`` (s) and ``step`` of the scene
        and ``complete`` = True once every array is written. Flushes the file.
        """
        if self._file is None:
            raise ValueError(f"{self.path}: recorder is closed")
        sc = scene if scene is not None else self.scene
        if sc is None and fields:
            raise ValueError("snapshot: no scene to read the fields from")
        fields = self.snapshot_fields if fields is None else tuple(fields)
        name = f"{self.num_snapshots:06d}"
        g = self._file["snapshots"].create_group(name)
        g.attrs["complete"] = False
        if sc is not None:
            g.attrs["time"] = float(sc.time)
            g.attrs["step"] = int(sc.step_count)
        items: list[tuple[str, Any, str]] = []
        for fld in fields if sc is not None else ():
            if fld not in SNAPSHOT_FIELDS:
                raise ValueError(f"fields: unknown field {fld!r}; known: {list(SNAPSHOT_FIELDS)}")
            items.append((fld, getattr(sc, fld), SNAPSHOT_FIELDS[fld]))
        if sc is not None and getattr(sc, "num_clumps", 0):
            for fld in CLUMP_SNAPSHOT_FIELDS:
                if fld not in fields:
                    items.append((fld, np.asarray(getattr(sc, fld)), SNAPSHOT_FIELDS[fld]))
        for k, (arr, units) in (extra or {}).items():
            items.append((k, arr, units))
        self._check_room(sum(np.asarray(arr).nbytes for _k, arr, _u in items))
        for k, arr, units in items:
            ds = g.create_dataset(k, data=np.asarray(arr), compression=self.compression)
            ds.attrs["units"] = units
        g.attrs["complete"] = True
        self.num_snapshots += 1
        return name

    def flush(self) -> None:
        """Flushes the HDF5 file (done after every record and snapshot anyway)."""
        if self._file is not None:
            self._writing(self._file.flush)

    def close(self) -> None:
        """Flushes and closes the file. Idempotent."""
        if self._file is not None:
            f = self._file
            self._writing(lambda: (f.flush(), f.close()))
            self._file = None

    @property
    def closed(self) -> bool:
        return self._file is None


def _open_h5_for_reading(path: PathLike):
    """Opens an HDF5 file read-only. If another process holds it open for writing (a live
    recorder: HDF5 file locking refuses the open), opens it again without locking; that is
    safe for the recorder's files, which are flushed after every record."""
    import h5py

    try:
        return h5py.File(path, "r")
    except OSError as exc:
        if "lock" not in str(exc).lower():
            raise
        return h5py.File(path, "r", locking=False)


def read_h5_series(path: PathLike) -> dict[str, np.ndarray]:
    """Reads the series of an :class:`H5Recorder` file: name -> array (num_records, ...).

    Only the complete rows (``/series`` attr ``num_records``) are returned; a declared series
    without records comes back empty. Works on a file
    that a live recorder is still writing (from another process the file is opened with HDF5
    file locking off) and on the file of a crashed run. Units: ``h5py.File(path)["series"][name].attrs["units"]``.
    """
    with _open_h5_for_reading(path) as f:
        g = f["series"]
        n = int(g.attrs.get("num_records", 0))
        out = {k: np.zeros(0) for k in json.loads(g.attrs.get("units_json", "{}"))}
        out.update({k: g[k][:n] for k in g.keys()})
        return out


def read_h5_snapshot(path: PathLike, index: int = -1) -> dict[str, Any]:
    """Reads snapshot ``index`` (negative counts from the last complete one) of an
    :class:`H5Recorder` file: field -> array, plus ``time`` (s) and ``step``."""
    with _open_h5_for_reading(path) as f:
        g = f["snapshots"]
        names = sorted(k for k in g.keys() if g[k].attrs.get("complete", False))
        if not names:
            raise KeyError(f"{path}: no complete snapshot")
        s = g[names[index]]
        out: dict[str, Any] = {k: s[k][()] for k in s.keys()}
        out["time"] = float(s.attrs.get("time", math.nan))
        out["step"] = int(s.attrs.get("step", -1))
        out["name"] = names[index]
        return out


# ---------------------------------------------------------------------------------------------
