"""The results folder of a case run, shared by the cases' command lines.

- ``--out DIR`` names the folder. Without it, every run gets a new numbered folder
  ``results/<case>/run_001``, ``run_002``, ... (created atomically), so no run replaces
  another.
- A folder that holds a completed (or an interrupted) run is refused unless ``--overwrite``
  is given; the folder is checked completely before anything in it is deleted, and only the
  files that the earlier run recorded are removed (a file it did not record, e.g. one of
  yours, makes the run refuse and nothing is deleted).
- While a run writes into a folder, a lock file there (``.geogrid-dem.lock``: pid, host,
  case, start) refuses a second run into it, naming the holder; the lock of a process that
  no longer runs is taken over, with a message.
- The manifest ``.geogrid-dem-run.json`` says what the folder holds: ``status`` ``running``,
  ``complete``, ``interrupted`` (Ctrl-C / SIGINT) or ``failed`` (an error, a full disk), the
  reason, and the files written; for a case that resumes, also its parameters (``params``:
  the case's Params as plain values, those in :data:`RESUME_FREE` left out) and the SHA-256
  of each checkpoint it wrote (``checkpoints``, recorded as they are written).
- ``--resume`` continues the same run or refuses: the parameters must be the recorded ones
  (the first that differs is named with both values), each checkpoint kept must be the very
  file the run wrote (its SHA-256), and a completed run is left as it is ("already
  complete", exit status 0).

:func:`run_main` runs a case's work inside this: an interrupted run closes its files, marks
the folder ``interrupted``, writes its ``summary.json`` marked ``interrupted`` with what it
finished and draws the figures of the finished parts (what the case gave
:func:`on_interrupt`), prints one line saying where the results are and returns 130; a full
disk or a file-size limit gives one error line naming the file and marks it ``failed``. A
run that completes has ``"status": "finished"`` in its ``summary.json`` (:func:`end_run`).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import errno as _errno
import fnmatch
import hashlib
import json
import os
import re
import signal
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Sequence

MANIFEST = ".geogrid-dem-run.json"
LOCK = ".geogrid-dem.lock"
#: Files a results folder may hold without being an earlier run's: the command's run file,
#: the manifest (and its temporary) and the lock.
_FREE = {"run.toml", MANIFEST, LOCK}
#: Exit status of a run stopped by SIGINT (128 + 2, as a shell reports it).
EXIT_INTERRUPTED = 130
#: the exit status of a case the core stopped (a BlowUpError: an overlap beyond
#: max_overlap_ratio, a body tunnelling, a value not finite)
EXIT_STOPPED = 6

#: Folders this process began (begin_run) and has not ended: marked on an interrupt.
_ACTIVE: list[Path] = []
#: The summary of a case's results folder (the case's numbers; on an interrupt, what it
#: finished).
SUMMARY = "summary.json"
#: The files an interrupted run's summary lists as its ``figures`` (of those its figures()
#: wrote: a table it writes beside them is among its ``files``).
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps")
#: What the case in a folder says when it is interrupted: folder -> (summary, figures), the
#: callables given to on_interrupt.
_ON_INTERRUPT: dict[Path, tuple] = {}
#: --overwrite of this process's command line (run_main sets it for the nested runs too).
_OVERWRITE = False


class RunFolderError(SystemExit):
    """A results folder that cannot be used (the message names it and says why)."""

    def __init__(self, msg: str) -> None:
        super().__init__(f"error: {msg}")


class RunComplete(SystemExit):
    """``--resume`` of a run that completed: nothing to do (exit status 0; begin_run has said
    so)."""

    def __init__(self) -> None:
        super().__init__(0)


#: Parameters that may differ between a run and its --resume (they do not change what the run
#: computes): left out of the recorded fingerprint.
RESUME_FREE = ("resume", "workers", "threads", "overwrite", "allow_large", "out")
#: Guards the manifest of this process's runs (the checkpoint recorder writes it from its own
#: thread).
_MANIFEST_LOCK = threading.RLock()


def plain(v):
    """``v`` as plain JSON values: a dataclass as the dict of its fields, tuples as lists,
    paths as strings, NumPy arrays and scalars as lists and numbers."""
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
    if isinstance(v, dict):
        return {str(k): plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, Path):
        return str(v)
    if hasattr(v, "tolist"):  # NumPy arrays and scalars
        return plain(v.tolist())
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    return repr(v)


def params_record(params) -> dict:
    """The fingerprint of a run's parameters: ``params`` (a dataclass or a dict) as plain
    values, without the :data:`RESUME_FREE` ones, as JSON reads it back."""
    d = plain(params)
    if not isinstance(d, dict):
        raise TypeError(f"params: a dataclass or a dict, not {type(params).__name__}")
    return json.loads(json.dumps({k: v for k, v in d.items() if k not in RESUME_FREE}))


def _short(v) -> str:
    t = json.dumps(v)
    return t if len(t) <= 120 else t[:117] + "..."


def params_difference(old: dict, new: dict) -> str | None:
    """The first parameter (in ``new``'s order) whose recorded value ``old`` differs, said
    with both values; None when they are the same."""
    for k in list(new) + [k for k in old if k not in new]:
        if k not in old:
            return f"the parameter {k} = {_short(new[k])} is not in the earlier run's record"
        if k not in new:
            return f"the earlier run's parameter {k} = {_short(old[k])} is not one of this run"
        if json.dumps(old[k]) != json.dumps(new[k]):
            return (f"the parameter {k} differs: {_short(old[k])} in the earlier run, "
                    f"{_short(new[k])} now")
    return None


def sha256_file(path) -> str:
    """The SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _matches(rel: str, patterns) -> bool:
    return any(fnmatch.fnmatchcase(rel, pat) for pat in patterns)


def _scan_checkpoints(out: Path, manifest: dict) -> bool:
    """Records in ``manifest`` (in place) the SHA-256, size and mtime of each file of ``out``
    matching its ``checkpoint_patterns`` that is new or changed since last recorded; True
    when something changed."""
    pats = manifest.get("checkpoint_patterns") or []
    rec = manifest.setdefault("checkpoints", {})
    changed = False
    for pat in pats:
        for p in sorted(out.glob(pat)):
            try:
                st = p.stat()
                if not p.is_file():
                    continue
                rel = p.relative_to(out).as_posix()
                old = rec.get(rel)
                if old and old.get("size") == st.st_size and \
                        old.get("mtime_ns") == st.st_mtime_ns:
                    continue
                rec[rel] = {"sha256": sha256_file(p), "size": st.st_size,
                            "mtime_ns": st.st_mtime_ns}
                changed = True
            except OSError:
                continue  # (being replaced just now: the next pass takes it)
    return changed


def record_checkpoints(out) -> None:
    """Records the SHA-256 of the checkpoints in ``out`` written since the last call (the
    files matching the patterns begin_run was given) in its manifest. run_main calls it about
    once a second while the case runs, and end_run once more; a case may call it right after
    writing a checkpoint."""
    out = Path(out)
    with _MANIFEST_LOCK:
        manifest = _read_json(out / MANIFEST)
        if manifest is None or not manifest.get("checkpoint_patterns"):
            return
        if _scan_checkpoints(out, manifest):
            write_atomic(out / MANIFEST, json.dumps(manifest, indent=1) + "\n")


class _CheckpointRecorder(threading.Thread):
    """Calls record_checkpoints(out) every ``period_s`` until stopped: a checkpoint's SHA-256
    is in the manifest within about a second of its writing, so a run killed after it can
    still be resumed from it."""

    def __init__(self, out: Path, period_s: float = 1.0) -> None:
        super().__init__(name="geogrid-dem checkpoint recorder", daemon=True)
        self.out, self.period_s, self._stop_event = out, period_s, threading.Event()

    def run(self) -> None:
        while not self._stop_event.wait(self.period_s):
            try:
                record_checkpoints(self.out)
            except Exception:  # noqa: BLE001  (end_run records them all the same)
                pass

    def stop(self) -> None:
        self._stop_event.set()
        if self.ident is not None:  # (started)
            self.join()


def add_out_args(ap: argparse.ArgumentParser, case: str, *, help_extra: str = "") -> None:
    """``--out`` (default: a new numbered folder results/<case>/run_NNN) and ``--overwrite``."""
    ap.add_argument("--out", type=Path, default=None,
                    help=f"results folder (default: a new folder results/{case}/run_NNN per "
                         "run); a folder holding an earlier run is refused without "
                         f"--overwrite{help_extra}")
    ap.add_argument("--overwrite", action="store_true",
                    help="replace the earlier run in --out (only the files it recorded are "
                         "removed, after the whole folder is checked)")


def _writable_or_error(out: Path) -> str | None:
    """Why ``out`` cannot be the results folder, or None."""
    if out.exists():
        if not out.is_dir():
            return "exists and is not a directory; name a folder (created if missing)"
        if not os.access(out, os.W_OK | os.X_OK):
            return "is a folder you cannot write into (permissions); name another folder"
        return None
    parent = out.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        return f"cannot be created: {parent} is a file, not a folder"
    if not os.access(parent, os.W_OK | os.X_OK):
        return (f"cannot be created: {parent.resolve()} is not writable (permissions or a "
                "read-only file system); name a folder you can write into")
    return None


#: Environment variables an MPI launcher sets to the number of ranks (MPICH's and Intel's
#: Hydra, Open MPI, PMIx).
MPI_SIZE_VARS = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "PMIX_SIZE")


def mpi_ranks() -> int:
    """The number of MPI ranks this process was started among (1 outside ``mpiexec``), read
    from the launcher's environment, without starting MPI."""
    import os

    for name in MPI_SIZE_VARS:
        v = os.environ.get(name, "")
        if v.isdigit() and int(v) > 0:
            return int(v)
    return 1


#: The largest seed a case takes: its runs record it as a 64-bit signed integer (HDF5
#: attributes, the manifest), so a larger one would fail only when the first record is written.
MAX_SEED = 2**63 - 1

#: The bound on ``--threads`` and on a local ``--workers``: this many times the machine's
#: cores (``os.cpu_count()``). The threads of a run, and the worker processes of a local
#: cluster, share the machine's cores: beyond a few per core they only slow a run down (256
#: threads take 20 x as long as 1 on 2 cores), and tens of thousands crash it.
PER_CORE = 4


def cores() -> int:
    """The machine's cores (``os.cpu_count()``; 1 when it cannot say)."""
    return os.cpu_count() or 1


def local_bound() -> int:
    """The most ``--threads`` of a run and ``--workers`` of a local cluster: :data:`PER_CORE`
    x :func:`cores`."""
    return PER_CORE * cores()


def local_bound_error(flag: str, value: int, low: int, what: str) -> str | None:
    """The refusal of ``flag=value`` above :func:`local_bound` (``what`` says what the count
    is), or None within it."""
    bound = local_bound()
    if value <= bound:
        return None
    return (f"{flag}={value}: more than {bound} ({PER_CORE} x the {cores()} cores of this "
            f"machine); {what} share its cores, and more than {PER_CORE} a core only slow the "
            f"run down (or exhaust the machine); allowed: {low} to {bound}")


def seed_error(flag: str, value) -> str | None:
    """The refusal of a seed outside [0, :data:`MAX_SEED`], or None."""
    if isinstance(value, int) and 0 <= value <= MAX_SEED:
        return None
    return (f"{flag}={value}: must be a whole number in [0, {MAX_SEED}] (0 to 2**63 - 1: a "
            "run records its seed as a 64-bit integer)")


def check_common_args(ap: argparse.ArgumentParser, a: argparse.Namespace) -> None:
    """Refuses (through ``ap.error``, naming the flag and the value) a ``--threads`` below 0 or
    above :func:`local_bound`, a ``--workers`` (a local cluster's processes) above it, a
    ``--seed`` outside [0, :data:`MAX_SEED`], an ``--out`` that is a file or cannot be
    written into, and a start as more than one MPI rank (:func:`mpi_ranks`); records
    ``--overwrite`` (where the parser has it) for :func:`run_main` and the runs of this
    process."""
    global _OVERWRITE
    ranks = mpi_ranks()
    if ranks > 1:
        ap.error(f"started as {ranks} MPI ranks (mpiexec -n {ranks}): a case runs as one "
                 f"process, so each rank would run it whole and the {ranks} would write the "
                 "same results; run it without mpiexec (a case's DEM elements run on Dask "
                 "workers: --workers), or drive femcoupling's models from your own script "
                 "under mpiexec (docs/fem.md, \"Under MPI\")")
    _OVERWRITE = bool(getattr(a, "overwrite", False))
    threads = getattr(a, "threads", None)
    if threads is not None and threads < 0:
        ap.error(f"--threads={threads}: must be >= 0 (0 = the default)")
    if threads is not None:
        why = local_bound_error("--threads", threads, 0, "the threads of a run")
        if why:
            ap.error(why.replace("allowed: 0 to", "allowed: 0 (automatic) to"))
    workers = getattr(a, "workers", None)
    if isinstance(workers, int):
        why = local_bound_error("--workers", workers, 1, "the worker processes")
        if why:
            ap.error(why)
    if hasattr(a, "seed"):
        why = seed_error("--seed", a.seed)
        if why:
            ap.error(why)
    for dest, v in vars(a).items():
        # (a name that is not UTF-8 text, from a file system's bytes, cannot be written into
        # the run file or the manifest)
        if isinstance(v, (str, Path)):
            try:
                str(v).encode("utf-8")
            except UnicodeEncodeError:
                ap.error(f"--{dest.replace('_', '-')}={str(v)!r}: not valid UTF-8 text; give "
                         "a name in UTF-8 (the run file and the manifest record it)")
    out = getattr(a, "out", None)
    if out is not None:
        why = _writable_or_error(Path(out))
        if why:
            ap.error(f"--out={out}: {why}")


def default_base(case: str) -> Path:
    """The folder under which runs without --out get their numbered folders."""
    return Path("results") / case


def numbered_run_dir(base: Path) -> Path:
    """A new folder ``base/run_NNN`` (NNN one above the highest there), created atomically: two
    runs started at once get two folders."""
    why = _writable_or_error(base)
    if why:
        raise RunFolderError(f"the default results folder {base} {why}; give --out DIR")
    try:
        base.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RunFolderError(f"the default results folder {base} cannot be made: {e.strerror}; "
                             "give --out DIR") from None
    nums = [int(m.group(1)) for p in base.iterdir()
            if (m := re.fullmatch(r"run_(\d+)", p.name))]
    k = max(nums, default=0) + 1
    while True:
        d = base / f"run_{k:03d}"
        try:
            d.mkdir()
            return d
        except FileExistsError:
            k += 1


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def _read_json(path: Path) -> dict | None:
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) else None


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs: a zombie (killed, not yet reaped: a sweep row's case
    after its Dask worker was killed) writes nothing and holds no folder."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat[stat.rindex(")") + 2:].split()[0] != "Z"
    except (OSError, ValueError, IndexError):
        return True


def lock_holder_gone(lock: dict | None) -> bool:
    """Whether the run that wrote ``lock`` (a lock file's content) is gone: its process, on
    this host, no longer runs. A lock of another host cannot be judged here: it counts as
    live, as does an unreadable one (None)."""
    return bool(lock) and lock.get("host") == socket.gethostname() and \
        isinstance(lock.get("pid"), int) and not _pid_alive(lock["pid"])


def live_status(out) -> str:
    """The status of the run in the results folder ``out``, from its manifest: "running",
    "complete", "interrupted", "failed", or "killed" (the manifest says running but no lock
    is left, or its process on this host is gone); "unknown" without a manifest."""
    m = run_status(out)
    if m is None:
        return "unknown"
    status = str(m.get("status", "unknown"))
    if status == "running":
        lock_path = Path(out) / LOCK
        lock = _read_json(lock_path) if lock_path.exists() else None
        if lock is None or lock_holder_gone(lock):
            return "killed"
    return status


def _files(out: Path) -> list[Path]:
    """The files of ``out`` but its own run file, manifest and lock (those of sub-folders, a
    run of several, count as files of the run)."""
    return sorted(p for p in out.rglob("*")
                  if p.is_file() and not (p.parent == out and p.name in _FREE)
                  and not is_temporary(p))


def is_temporary(path: Path) -> bool:
    """Whether ``path`` is a temporary file of :func:`write_atomic` (left only by a writer
    killed between its write and its rename): not a result."""
    return path.name.startswith(".") and path.name.endswith(".tmp")


def write_atomic(path: Path, text: str) -> None:
    """``text`` at ``path``, written whole or not at all: a temporary file of this process and
    thread, renamed (so processes and threads may write the same path at once; the last
    rename wins)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def _lock_text(case: str) -> str:
    return json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "case": case,
                       "started": _now()}) + "\n"


def _holder(lock: dict) -> str:
    return (f"pid {lock.get('pid')} on {lock.get('host')} ({lock.get('case', '?')}, since "
            f"{lock.get('started', '?')})")


def _ours(lock: dict | None) -> bool:
    return bool(lock) and lock.get("pid") == os.getpid() and \
        lock.get("host") == socket.gethostname()



def _unrecorded(out, files, manifest, status):
    """The files of ``files`` that the earlier run of ``manifest`` did not write: a run that
    completed, failed or was interrupted lists its files; a killed run could not, so its files
    are those written since it started (an older file is not its)."""
    if status == "killed":
        t0 = float(manifest.get("started_unix", 0.0))
        listed = {str(p.relative_to(out)) for p in files if p.stat().st_mtime >= t0 - 1}
    else:
        listed = set(manifest.get("files", []))
    return [p for p in files if str(p.relative_to(out)) not in listed]


def _code() -> dict:
    from geogrid_dem.provenance import code_record

    return code_record()


def _check_resume(out: Path, case: str, manifest: dict | None, status: str | None,
                  keep: Sequence[str], params, checkpoints: Sequence[str], log) -> dict:
    """The checks of a --resume (see begin_run); returns the recorded checkpoints of the files
    kept (carried into the new manifest). Raises RunFolderError naming what differs, or
    RunComplete (having said so) for a completed run of the same parameters."""
    if manifest is None or manifest.get("case") != case:
        what = "no run" if manifest is None else f"a run of {manifest.get('case')}"
        raise RunFolderError(f"--out={out}: --resume: holds {what}; --resume continues an "
                             f"interrupted or failed run of {case}")
    if params is not None:
        old = manifest.get("params")
        if not isinstance(old, dict):
            raise RunFolderError(
                f"--out={out}: --resume: the earlier run recorded no parameters (an older "
                "version wrote it), so it cannot be told to be the same run; run it again with "
                "--overwrite (nothing was removed)")
        diff = params_difference(old, params_record(params))
        if diff:
            raise RunFolderError(
                f"--out={out}: --resume: {diff}; a resume continues the same run: give the "
                "earlier run's parameters, or run again with --overwrite (nothing was removed)")
    if status == "complete":
        log(f"[{case}] --out {out}: --resume: the run is already complete (finished "
            f"{manifest.get('finished', '?')}); nothing to do")
        raise RunComplete
    missing = [k for k in keep[:1] if not (out / k).is_file()]
    if missing:
        raise RunFolderError(f"--out={out}: --resume: {missing[0]} is not there (the run "
                             "stopped before its checkpoint); run it again with "
                             "--overwrite")
    pats = list(manifest.get("checkpoint_patterns") or []) + \
        [c for c in checkpoints if c not in (manifest.get("checkpoint_patterns") or [])]
    recorded = manifest.get("checkpoints") or {}
    carried = {}
    for k in keep:
        rel = Path(k).as_posix()
        if not _matches(rel, pats) or not (out / k).is_file():
            continue
        rec = recorded.get(rel)
        if not isinstance(rec, dict) or "sha256" not in rec:
            raise RunFolderError(
                f"--out={out}: --resume: {rel} has no SHA-256 in the run's record (an older "
                "version, or the run was killed as it wrote it), so it cannot be told to be "
                "this run's checkpoint; run it again with --overwrite (nothing was removed)")
        now = sha256_file(out / k)
        if now != rec["sha256"]:
            raise RunFolderError(
                f"--out={out}: --resume: {rel} is not the file this run wrote (SHA-256 "
                f"{now[:12]}..., recorded {rec['sha256'][:12]}...): a checkpoint of another run "
                "or sample? Nothing was removed; put the run's own file back, or run again "
                "with --overwrite")
        st = (out / k).stat()
        carried[rel] = dict(rec, size=st.st_size, mtime_ns=st.st_mtime_ns)
    code = manifest.get("code")
    if params is not None and isinstance(code, dict) and code.get("commit") not in (
            None, "unknown"):
        now_code = _code()
        if now_code["commit"] not in ("unknown", code.get("commit")):
            log(f"[{case}] --out {out}: --resume: note: the code changed since the earlier "
                f"run ({code.get('commit')}, now {now_code['commit']}): the rest runs with "
                "the new code")
    return carried


def begin_run(out, case: str, log=print, *, overwrite: bool | None = None,
              keep: Sequence[str] | None = None, params=None,
              checkpoints: Sequence[str] = ()) -> Path:
    """Prepares the results folder of a case run and returns it (``out`` None: a new numbered
    folder ``results/<case>/run_NNN``). Refuses (:class:`RunFolderError`, naming the folder
    and why) a folder another live run is writing into, a folder holding an earlier run
    without ``overwrite`` (default: the process's ``--overwrite``), and a folder holding files
    no run recorded; with ``overwrite`` the earlier run's recorded files are removed, only
    after the whole folder was checked. Then takes the lock and marks the folder ``running``.
    A second call from the same process for the same folder returns it unchanged.
    ``keep`` (a case's --resume): the folder must hold an unfinished run of ``case`` with the
    files ``keep`` (its checkpoint first); they are kept and the run's other files removed.
    ``params`` (the case's Params, or a dict): recorded in the manifest (params_record); on a
    --resume they must equal the recorded ones, or the first that differs is named. A --resume
    of a completed run with the same parameters says "already complete" and raises
    RunComplete (exit status 0). ``checkpoints``: glob patterns (relative to the folder) of
    the files the run writes to resume from; their SHA-256 goes into the manifest as they are
    written (record_checkpoints), and a --resume keeps one only when its bytes are the
    recorded ones."""
    if overwrite is None:
        overwrite = _OVERWRITE
    if out is None:
        out = numbered_run_dir(default_base(case))
    out = Path(out)
    why = _writable_or_error(out)
    if why:
        raise RunFolderError(f"--out={out}: {why}")
    lock_path, manifest_path = out / LOCK, out / MANIFEST
    lock = _read_json(lock_path) if lock_path.exists() else None
    if _ours(lock):
        return out
    stale = None
    if lock_path.exists():
        if lock_holder_gone(lock):
            stale = lock
        else:
            raise RunFolderError(
                f"--out={out}: another run is writing into it: "
                f"{_holder(lock) if lock else 'an unreadable lock file'} (lock file {lock_path}; "
                "remove it if that run is gone); wait for it to end, or name another folder")
    manifest = _read_json(manifest_path) if manifest_path.exists() else None
    files = _files(out) if out.is_dir() else []
    carried: dict = {}
    if keep is not None:
        status = (manifest or {}).get("status")
        if status == "running" or stale is not None:
            status = "killed"
        carried = _check_resume(out, case, manifest, status, keep, params, checkpoints, log)
        unlisted = _unrecorded(out, files, manifest, status)
        if unlisted:
            raise RunFolderError(
                f"--out={out}: holds {len(unlisted)} files that the earlier run did not record "
                f"(e.g. {unlisted[0].relative_to(out)}); nothing was removed")
        drop = [p for p in files if str(p.relative_to(out)) not in set(keep)]
        for p in drop:
            p.unlink()
        log(f"[{case}] --out {out}: --resume: kept {', '.join(k for k in keep if (out / k).is_file())}"
            f"; removed the {len(drop)} other files of the {status} run")
        files = []
    if files:
        if manifest is None:
            raise RunFolderError(
                f"--out={out}: holds {len(files)} files that no run recorded (e.g. "
                f"{files[0].relative_to(out)}): files of yours or of an older version; name a "
                "new or empty folder (nothing was removed)")
        status = manifest.get("status", "complete")
        if stale is not None or status == "running":
            status = "killed"
        what = {"complete": "a completed run", "interrupted": "an interrupted run",
                "failed": "a failed run", "killed": "a run that was killed while running"}.get(
                    status, f"a run ({status})")
        when = manifest.get("finished") or manifest.get("started") or "?"
        if not overwrite:
            raise RunFolderError(
                f"--out={out}: holds {what} of {manifest.get('case', '?')} ({when}, "
                f"{len(files)} files); add --overwrite to replace it, or name another folder "
                "(without --out every run gets its own folder results/<case>/run_NNN)")
        unlisted = _unrecorded(out, files, manifest, status)
        if unlisted:
            raise RunFolderError(
                f"--out={out}: holds {len(unlisted)} files that the earlier run did not record "
                f"(e.g. {unlisted[0].relative_to(out)}): files of yours? Nothing was removed; "
                "move them, or name another folder")
        for p in files:
            p.unlink()
        for d in sorted((p for p in out.rglob("*") if p.is_dir()), reverse=True):
            try:
                d.rmdir()  # the earlier run's folders, where empty now
            except OSError:
                pass
        (out / "run.toml").unlink(missing_ok=True)  # the earlier run's record
        log(f"[{case}] --out {out}: --overwrite: removed the {len(files)} files of the "
            f"earlier run ({what}, {when})")
    if stale is not None:
        log(f"[{case}] --out {out}: taking over the lock of {_holder(stale)}, which no longer "
            "runs")
        lock_path.unlink(missing_ok=True)
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        lock = _read_json(lock_path)
        raise RunFolderError(f"--out={out}: another run started writing into it just now: "
                             f"{_holder(lock) if lock else '?'}; name another folder") from None
    except OSError as e:
        raise RunFolderError(f"--out={out}: cannot be written into: {e.strerror} "
                             f"({e.filename or out}); name a folder you can write into") \
            from None
    with os.fdopen(fd, "w") as fh:
        fh.write(_lock_text(case))
    rec = {"status": "running", "complete": False, "case": case, "pid": os.getpid(),
           "host": socket.gethostname(), "started": _now(), "started_unix": time.time()}
    if params is not None:
        rec["params"] = params_record(params)
        rec["code"] = _code()
    if checkpoints:
        rec["checkpoint_patterns"] = list(checkpoints)
        rec["checkpoints"] = carried
    write_atomic(manifest_path, json.dumps(rec, indent=1) + "\n")
    if out not in _ACTIVE:
        _ACTIVE.append(out)
    return out


def end_run(out, status: str = "complete", reason: str | None = None) -> None:
    """Records the files in ``out`` and the run's ``status`` (``complete``, ``interrupted`` or
    ``failed``, with the ``reason``) in the manifest begin_run reads; releases the lock. A
    completed run's ``summary.json`` gets ``"status": "finished"`` (one written as the run went
    may say ``running``); the folder's on_interrupt callables are forgotten."""
    out = Path(out)
    manifest_path = out / MANIFEST
    _ON_INTERRUPT.pop(out.absolute(), None)
    if status == "complete":
        _mark_summary_finished(out)
    with _MANIFEST_LOCK:
        old = _read_json(manifest_path) or {}
        files = [str(p.relative_to(out)) for p in _files(out)] if out.is_dir() else []
        rec = {"status": status, "complete": status == "complete",
               **{k: old[k] for k in ("case", "host", "started", "started_unix") if k in old},
               "finished": _now()}
        if reason:
            rec["reason"] = reason
        rec["files"] = files
        for k in ("params", "code", "checkpoint_patterns", "checkpoints"):
            if k in old:
                rec[k] = old[k]
        if rec.get("checkpoint_patterns") and out.is_dir():
            try:
                _scan_checkpoints(out, rec)  # (the last ones written)
            except OSError:
                pass
        try:
            write_atomic(manifest_path, json.dumps(rec, indent=1) + "\n")
        except OSError:
            if status == "complete":
                raise
    lock_path = out / LOCK
    if lock_path.exists() and _ours(_read_json(lock_path)):
        lock_path.unlink(missing_ok=True)
    if out in _ACTIVE:
        _ACTIVE.remove(out)


def _mark_summary_finished(out: Path) -> None:
    """``"status": "finished"`` first in ``out/summary.json``, if the case wrote one (a JSON
    object) without a status, or with ``running`` (written as the run went)."""
    path = out / SUMMARY
    if not path.is_file():
        return
    d = _read_json(path)
    if d is None or d.get("status", "running") != "running":
        return
    d.pop("status", None)
    write_atomic(path, json.dumps({"status": "finished", **d}, indent=2) + "\n")


def on_interrupt(out, *, summary=None, figures=None) -> None:
    """What the case running in the results folder ``out`` reports if it is interrupted
    (Ctrl-C, SIGINT, SIGTERM; :func:`run_main`): ``summary()`` returns a dict of what it
    finished (its ``finished`` entry, by convention, names the finished parts: stages, rows,
    packings; the other entries are their numbers), written into ``out/summary.json``
    beside the ``status`` ``interrupted``, the ``reason``, the ``case``, the ``figures``
    drawn and the ``files`` written so far; ``figures()`` draws the figures of the finished
    parts into ``out``. Both are called once, on an interrupt only, after the recorders are
    closed (their files hold every row written), and are best effort: an error in either is
    said in one line and recorded under ``report_errors``, and the run still stops with
    130 / 143. A summary.json the case wrote as it went is kept and updated. A later call for
    the same folder replaces the callables; :func:`end_run` forgets them. A case that gives
    none still leaves ``{status, reason, case, files}``."""
    _ON_INTERRUPT[Path(out).absolute()] = (summary, figures)


def _one_line(e: BaseException) -> str:
    text = str(e).strip().split("\n")[0]
    return f"{type(e).__name__}: {text[:300]}" if text else type(e).__name__


def _stamps(out: Path) -> dict:
    """relative name -> (size, mtime_ns) of the files of ``out``."""
    found = {}
    for p in _files(out) if out.is_dir() else []:
        try:
            st = p.stat()
        except OSError:
            continue
        found[p.relative_to(out).as_posix()] = (st.st_size, st.st_mtime_ns)
    return found


def write_interrupted_summary(out, case: str, reason: str, *, err=None) -> Path:
    """Writes ``out/summary.json`` of a run that was interrupted (run_main does, for every
    folder of the run, before it marks them): ``status`` ``interrupted``, the ``reason``,
    the ``case`` (its manifest's), the time (``interrupted_at``, UTC), what the case's
    on_interrupt ``summary()`` returns (over a summary.json the case wrote as it went),
    then the ``figures`` its ``figures()`` drew and the ``files`` of the folder. Each part
    that fails is said in one line on ``err`` (default stderr) and skipped; returns the
    path."""
    out = Path(out)
    if err is None:
        def err(msg: str) -> None:
            print(msg, file=sys.stderr, flush=True)
    summary_fn, figures_fn = _ON_INTERRUPT.pop(out.absolute(), (None, None))
    path = out / SUMMARY
    case = (_read_json(out / MANIFEST) or {}).get("case") or case
    head = {"status": "interrupted", "reason": reason, "case": case, "interrupted_at": _now()}
    body = {k: v for k, v in (_read_json(path) or {}).items() if k != "status"}
    errors: list[str] = []

    def write(extra: dict) -> None:
        rec = {**head, **{k: v for k, v in body.items() if k not in head}, **extra}
        files = sorted(set(_stamps(out)) | {SUMMARY})
        write_atomic(path, json.dumps(plain({**rec, "files": files}), indent=2) + "\n")

    if summary_fn is not None:
        try:
            body.update(summary_fn() or {})
        except BaseException as e:  # noqa: BLE001  (best effort: the interrupt goes on)
            errors.append(f"the summary of the finished parts: {_one_line(e)}")
            err(f"[{case}] interrupted: could not say what finished ({_one_line(e)}); "
                f"{SUMMARY} holds the status and the files")
    write({"report_errors": errors} if errors else {})
    if figures_fn is None:
        return path
    before = _stamps(out)
    try:
        figures_fn()
    except BaseException as e:  # noqa: BLE001
        errors.append(f"the figures of the finished parts: {_one_line(e)}")
        err(f"[{case}] interrupted: could not draw the figures of the finished parts "
            f"({_one_line(e)}); the summary and the files written are kept")
    after = _stamps(out)
    drawn = sorted(k for k, v in after.items() if before.get(k) != v
                   and Path(k).suffix.lower() in FIGURE_SUFFIXES)
    write({"figures": drawn, **({"report_errors": errors} if errors else {})})
    return path


def run_status(out) -> dict | None:
    """The manifest of the results folder ``out`` (status, reason, files), or None."""
    return _read_json(Path(out) / MANIFEST)


def _full_disk(e: BaseException) -> bool:
    return isinstance(e, OSError) and e.errno in (_errno.ENOSPC, _errno.EFBIG,
                                                  getattr(_errno, "EDQUOT", -1))


def _from_interrupt(e: BaseException) -> bool:
    """True when ``e`` was raised because of a KeyboardInterrupt (in its chain of causes and
    contexts): a Ctrl-C that arrived while a C extension initialised (matplotlib's
    ``ft2font`` gives ``ImportError: initialization failed``, caused by it)."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def run_main(case: str, out, work, *, overwrite: bool | None = None, log=None,
             own_folder: bool = True, keep: Sequence[str] | None = None, params=None,
             checkpoints: Sequence[str] = ()) -> int:
    """Runs ``work(out)`` for a case's command line in its results folder (begin_run: ``out``
    None makes a numbered one; ``overwrite`` None: the ``--overwrite`` that
    check_common_args recorded) and returns the exit status: 0 when it completed, 130 when it
    was interrupted (Ctrl-C, SIGINT, SIGTERM), 1 when a file could not be written (a full
    disk, a file-size limit), 6 (EXIT_STOPPED) when the core stopped the simulation (a
    BlowUpError: one line on stderr gives its message). On an interrupt or a failure every
    recorder still open is closed (what was written stays readable), every folder of the run
    is marked ``interrupted`` or ``failed`` in its manifest, and one line says so and where
    the results are; any other error is re-raised after that. SIGTERM stops the run as
    SIGINT does (status 143).
    ``own_folder`` False: ``out`` is a folder of several runs (each begins its own
    sub-folder), not locked or recorded itself. ``keep``: a --resume (see begin_run; one of a
    completed run returns 0 without running ``work``). ``params``, ``checkpoints``: the run's
    parameters and the patterns of its checkpoints (begin_run), whose SHA-256 is recorded
    about once a second while ``work`` runs and once more at its end. Warnings are shown one
    line each, a repeated one once and then counted (geogrid_dem.warnings_display).

    On an interrupt each folder of the run also gets its ``summary.json`` marked
    ``interrupted`` (write_interrupted_summary): what the case finished and the figures of
    the finished parts, where ``work`` said how with :func:`on_interrupt`, else the status,
    the reason, the case and the files."""
    from geogrid_dem.warnings_display import shown_once

    with shown_once():
        return _run_main(case, out, work, overwrite=overwrite, log=log, own_folder=own_folder,
                         keep=keep, params=params, checkpoints=checkpoints)


def write_views(out: Path) -> list[Path]:
    """ParaView state files beside every folder of VTK files under ``out``
    (cpp_dem.io.paraview_state.write_states: ``<run>_view.py`` per run of series); a folder
    that cannot take one is said on stderr, and the run goes on. Returns the paths."""
    from cpp_dem.io.paraview_state import write_states

    out = Path(out)
    if not out.is_dir():
        return []
    written = []
    for folder in sorted({f.parent for f in out.rglob("*.pvd")}
                         | {f.parent for f in out.rglob("*.vtp")}):
        try:
            written += write_states(folder)
        except OSError as e:
            print(f"[views] {folder}: no ParaView state written ({_one_line(e)})",
                  file=sys.stderr, flush=True)
    return written


def _run_main(case, out, work, *, overwrite, log, own_folder, keep, params, checkpoints) -> int:
    global _OVERWRITE
    from cpp_dem.io import close_all_writers

    if log is None:
        def log(msg: str) -> None:
            print(msg, flush=True)
    if overwrite is not None:
        _OVERWRITE = bool(overwrite)
    if own_folder:
        try:
            out = begin_run(out, case, log=log, keep=keep, params=params,
                            checkpoints=checkpoints)
        except RunComplete:
            return 0
    else:
        out = Path(out) if out is not None else default_base(case)
        out.mkdir(parents=True, exist_ok=True)
    log(f"[{case}] results in {out}")
    import threading

    main_thread = threading.current_thread() is threading.main_thread()
    old_term = signal.getsignal(signal.SIGTERM) if main_thread else None
    old_int = signal.getsignal(signal.SIGINT) if main_thread else None
    got: list[int] = []

    def _term(sig, _frame):  # a polite kill stops as Ctrl-C does
        got.append(sig)
        raise KeyboardInterrupt

    if main_thread and old_term == signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _term)

    def _mark(status: str, reason: str) -> list[Path]:
        close_all_writers()
        folders = list(_ACTIVE) or ([out] if own_folder else [])
        for d in reversed(folders):  # (a run inside another first: the outer lists its files)
            write_views(d)
            if status == "interrupted":
                try:
                    write_interrupted_summary(d, case, reason)
                except Exception as e:  # noqa: BLE001  (e.g. a full disk: the mark goes on)
                    print(f"[{case}] interrupted: {d / SUMMARY} could not be written "
                          f"({_one_line(e)})", file=sys.stderr, flush=True)
            end_run(d, status, reason)
        return folders

    recorder = _CheckpointRecorder(out) if (own_folder and checkpoints) else None
    try:
        try:
            if recorder is not None:
                recorder.start()
            work(out)
        except Exception as e:  # (Ctrl-C inside an import: CPython raises ImportError from it)
            if _from_interrupt(e):
                raise KeyboardInterrupt from e
            raise
        finally:
            if recorder is not None:
                recorder.stop()
    except KeyboardInterrupt:
        if main_thread:  # a second Ctrl-C (or SIGTERM) does not cut the closing short
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            if old_term == signal.SIG_DFL:
                signal.signal(signal.SIGTERM, signal.SIG_IGN)
        sig = "SIGTERM" if got else "SIGINT / Ctrl-C"
        folders = _mark("interrupted", f"interrupted ({sig}) before the end")
        where = ", ".join(str(d) for d in folders) or str(out)
        print(f"[{case}] interrupted ({sig}): the run is incomplete (marked 'interrupted' in "
              f"{MANIFEST} and {SUMMARY}, with what finished); the files written so far are "
              f"in {where}", file=sys.stderr, flush=True)
        return 128 + signal.SIGTERM if got else EXIT_INTERRUPTED
    except OSError as e:
        if not _full_disk(e):
            _mark("failed", f"{type(e).__name__}: {e}")
            raise
        name = e.filename or "a result file"
        from cpp_dem.io import ResultWriteError

        msg = str(e) if isinstance(e, ResultWriteError) else \
            f"{name}: could not be written: {os.strerror(e.errno)} (errno {e.errno})"
        _mark("failed", msg)
        print(f"error: {msg}; the run is incomplete (marked 'failed' in {MANIFEST}), the files "
              f"written before are in {out}", file=sys.stderr, flush=True)
        return 1
    except BaseException as e:
        if isinstance(e, SystemExit) and e.code in (0, None):
            raise
        from cpp_dem import BlowUpError

        _mark("failed", f"{type(e).__name__}: {e}".split("\n")[0][:500])
        if not isinstance(e, BlowUpError):
            raise
        # The core stopped the run (an overlap, a body tunnelling, a value not finite): what
        # it says names the step, the bodies and the cause; a traceback adds nothing.
        print(f"error: [{case}] the simulation stopped: {str(e).splitlines()[0]}. The run is "
              f"incomplete (marked 'failed' in {MANIFEST}); the files written before are in "
              f"{out}", file=sys.stderr, flush=True)
        return EXIT_STOPPED
    finally:
        if main_thread and old_term == signal.SIG_DFL:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
        if main_thread and old_int is not None:
            # (Ctrl-C was ignored while an interrupted run closed its files; a script or
            # session that called run_main gets its own handler back, and the processes it
            # starts do not inherit the ignore.)
            signal.signal(signal.SIGINT, old_int)
    active = list(_ACTIVE)
    for d in active:
        write_views(d)
        end_run(d)
    if own_folder:
        if out not in active:  # (its views written once)
            write_views(out)
        end_run(out)  # files written after the case's own end_run are listed too
    return 0
