"""Files written whole and atomically, and recorders that close on exit (cpp_dem.io)."""

from __future__ import annotations

import contextlib
import errno as _errno
import os
import re
import sys
import tempfile
import weakref
from pathlib import Path

PathLike = str | os.PathLike


def _current_umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _current_umask()


#: errno values that mean "the disk (or the quota, or the file-size limit) is full".
_FULL = {_errno.ENOSPC, _errno.EFBIG, getattr(_errno, "EDQUOT", -1)}
_WHY = {_errno.ENOSPC: "no space left on the device",
        _errno.EFBIG: "the file-size limit (ulimit -f) is reached",
        getattr(_errno, "EDQUOT", -1): "the disk quota is exceeded"}


class ResultWriteError(OSError):
    """A result file could not be written (disk full, a file-size limit, an I/O error).
    ``filename`` is the file, ``errno`` the system's code where known; the message says which
    file, why, and what the file holds (what was written before stays readable)."""

    def __init__(self, path: PathLike, err: int | None, why: str, kept: str = "") -> None:
        super().__init__(err or 0, why, str(path))
        self.kept = kept

    def __str__(self) -> str:
        code = f" (errno {self.errno})" if self.errno else ""
        tail = f"; {self.kept}" if self.kept else ""
        return f"{self.filename}: could not be written: {self.strerror}{code}{tail}"


def errno_of(exc: BaseException) -> int | None:
    """The system error code of a failed write: ``OSError.errno``, or the ``errno = N`` that
    HDF5 puts into the message of h5py's RuntimeError."""
    if isinstance(exc, OSError) and exc.errno:
        return exc.errno
    m = re.search(r"errno = (\d+)", str(exc))
    return int(m.group(1)) if m else None


def is_write_failure(exc: BaseException) -> bool:
    """True for an error of the operating system or of HDF5's file driver while writing."""
    if isinstance(exc, OSError):
        return True
    text = str(exc)
    return isinstance(exc, RuntimeError) and (errno_of(exc) is not None
                                             or "write failed" in text
                                             or "unable to extend file" in text)


def write_error(path: PathLike, exc: BaseException, kept: str = "") -> ResultWriteError:
    """The ResultWriteError naming ``path`` for the failure ``exc``."""
    code = errno_of(exc)
    if code in _WHY:
        why = _WHY[code]
    elif code:
        why = os.strerror(code)
    else:
        why = str(exc).split("\n")[0]
    return ResultWriteError(path, code, why, kept)


def _interrupt_of(u) -> BaseException | None:
    """The KeyboardInterrupt (a Ctrl-C, or a SIGTERM the cases turn into one) that an
    unraisable report ``u`` carries, or None. One that lands in an h5py destructor reaches
    ``sys.unraisablehook``, not the caller: the guards below raise it again on the way out,
    or the run would go on, unstopped."""
    if u.exc_type is not None and issubclass(u.exc_type, KeyboardInterrupt):
        return u.exc_value or KeyboardInterrupt()
    return None


@contextlib.contextmanager
def _quiet_unraisable():
    """Silences the reports that h5py's object destructors print (to ``sys.stderr``, or
    through ``sys.unraisablehook``) when a file whose writes failed is closed: the failure is
    reported once, by the caller."""
    import gc
    import io

    old = sys.unraisablehook
    interrupted: list[BaseException] = []

    def hook(u):  # (the rest is silenced)
        got = _interrupt_of(u)
        if got is not None:
            interrupted.append(got)

    sys.unraisablehook = hook
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            try:
                yield
            finally:
                gc.collect()
    finally:
        sys.unraisablehook = old
    if interrupted:
        raise KeyboardInterrupt from interrupted[0]


class _DeallocErrors:
    """Catches what h5py's object destructors report while a block runs (a write that failed
    inside HDF5's cache is reported there, not raised): ``text`` is what they said. The file
    is then not flushed again (HDF5 can crash on a flush after such a failure)."""

    def __enter__(self):
        import io

        self._old_hook, self._old_err = sys.unraisablehook, sys.stderr
        self._buf = io.StringIO()
        self._hooked: list[str] = []
        self._interrupt: BaseException | None = None

        def hook(u):
            got = _interrupt_of(u)
            if got is None:
                self._hooked.append(f"{u.exc_type.__name__}: {u.exc_value}")
            elif self._interrupt is None:
                self._interrupt = got

        sys.unraisablehook = hook
        sys.stderr = self._buf
        return self

    def __exit__(self, exc_type, *exc) -> None:
        sys.unraisablehook, sys.stderr = self._old_hook, self._old_err
        self.text = "\n".join(self._hooked) + self._buf.getvalue()
        if self.text and not self.failure():  # not ours: pass it on as it came
            self._old_err.write(self._buf.getvalue())
        if self._interrupt is not None and exc_type is None:
            raise KeyboardInterrupt from self._interrupt

    def failure(self) -> RuntimeError | None:
        """The write failure reported, as a RuntimeError carrying HDF5's message, or None."""
        m = re.search(r"RuntimeError: ([^\n]*(?:\n,[^\n]*)?errno = \d+[^\n]*)", self.text)
        return RuntimeError(m.group(1)) if m else None


def _atomic_write_bytes(path: PathLike, data: bytes) -> None:
    """Writes ``data`` to ``path`` through a temporary file in the same directory and
    ``os.replace``, so readers never see a half-written file. A failed write (a full disk,
    a file-size limit) raises :class:`ResultWriteError` naming ``path``; the earlier file, if
    any, is left as it was."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix="." + path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_UMASK)  # as open() would (mkstemp makes it 0600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(e, OSError) and not isinstance(e, ResultWriteError):
            raise write_error(path, e, "not written (an earlier version, if any, is kept)") \
                from None
        raise



#: The writers open in this process (closed by close_all_writers on an interrupted run).
_OPEN_WRITERS: "weakref.WeakSet[_ClosesOnExit]" = weakref.WeakSet()


def close_all_writers() -> int:
    """Flushes and closes every recorder and PVD writer of this process that is still open
    (an interrupted or failed run: what was written stays readable); errors of a writer
    whose file cannot be written any more are swallowed. Returns how many were closed."""
    n = 0
    with _quiet_unraisable():
        for w in list(_OPEN_WRITERS):
            try:
                w.close()
            except Exception:  # noqa: BLE001  (a failed file: closed as far as it goes)
                w._abandon()
            n += 1
            _OPEN_WRITERS.discard(w)
    return n


class _ClosesOnExit:
    """Context-manager protocol for the writers here: ``with`` closes, and so (best effort)
    does garbage collection. Subclasses define an idempotent ``close()`` and register
    themselves in ``_OPEN_WRITERS`` (``_register``)."""

    def _register(self) -> None:
        _OPEN_WRITERS.add(self)

    def _abandon(self) -> None:  # pragma: no cover - overridden
        """Closes the file without raising (after a failed write)."""

    def close(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass
