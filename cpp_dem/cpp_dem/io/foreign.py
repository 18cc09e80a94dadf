"""Sphere packings in other codes' files, so a state from Yade, LIGGGHTS or PFC is continued
here as it is (and ours there). Centres and radii in m; read_* return (centres (n, 3),
radii (n,)); write_* take them.

- **Yade text** (``yade.ymport.text`` / ``yade.export.text``): one sphere per line,
  ``x y z r``; lines starting with ``#`` are comments (Yade writes ``#format x_y_z_r``).
- **LIGGGHTS / LAMMPS data file** (``read_data`` / ``write_data``, atom style ``granular`` or
  ``sphere``): the header (``N atoms``, ``xlo xhi`` ...) and the ``Atoms`` section,
  ``id type diameter density x y z`` per line. The box of the header is returned by
  :func:`read_liggghts_box`.
- **PFC ball list**: one ball per line, ``id x y z radius`` (the order a FISH loop over
  ``ball.list`` writes with ``ball.id``, ``ball.pos`` and ``ball.radius``), whitespace or
  commas; a first line that is not numbers is taken as a header.

Errors name the file and the line (cpp_dem.ParameterError).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._core import ParameterError

PathLike = str | os.PathLike


def _lines(path: PathLike) -> list[str]:
    try:
        return Path(path).read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise ParameterError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None


def _numbers(path, lineno: int, fields: list[str], n: int, what: str) -> list[float]:
    if len(fields) < n:
        raise ParameterError(f"{path}:{lineno}: expected {n} values ({what}), got {len(fields)}")
    try:
        vals = [float(f) for f in fields[:n]]
    except ValueError:
        raise ParameterError(f"{path}:{lineno}: not numbers ({what}): {' '.join(fields)!r}") from None
    if not np.all(np.isfinite(vals)):
        raise ParameterError(f"{path}:{lineno}: values must be finite ({what})")
    return vals


def _checked(path, c: list, r: list) -> tuple[np.ndarray, np.ndarray]:
    if not r:
        raise ParameterError(f"{path}: no sphere in the file")
    radii = np.asarray(r, dtype=float)
    bad = np.flatnonzero(radii <= 0)
    if bad.size:
        raise ParameterError(f"{path}: sphere {int(bad[0])} has radius {radii[bad[0]]}: must be > 0 (m)")
    return np.asarray(c, dtype=float).reshape(-1, 3), radii


# ---- Yade ----------------------------------------------------------------------------------

def read_yade_text(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Spheres of a Yade text file (``x y z r`` per line, ``#`` comments)."""
    c, r = [], []
    for k, line in enumerate(_lines(path), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        x, y, z, rad = _numbers(path, k, s.replace(",", " ").split(), 4, "x y z r")
        c.append((x, y, z))
        r.append(rad)
    return _checked(path, c, r)


def write_yade_text(path: PathLike, centers, radii) -> None:
    """Writes a Yade text file (``#format x_y_z_r``, as ``yade.export.text``)."""
    c, r = _validated(centers, radii)
    with open(path, "w") as f:
        f.write("#format x_y_z_r\n")
        for (x, y, z), rad in zip(c.tolist(), r.tolist()):
            f.write(f"{x!r} {y!r} {z!r} {rad!r}\n")


# ---- LIGGGHTS / LAMMPS data file ------------------------------------------------------------

def _liggghts_sections(path):
    lines = _lines(path)
    header, atoms, section = {}, [], None
    for k, line in enumerate(lines, start=1):
        s = line.split("#")[0].strip()
        if not s:
            continue
        if s in ("Atoms", "Velocities", "Masses") or s.startswith("Atoms"):
            section = s.split()[0]
            continue
        if section is None:
            parts = s.split()
            if len(parts) >= 2 and parts[-1] == "atoms":
                header["atoms"] = int(float(parts[0]))
            elif len(parts) == 4 and parts[2].endswith("lo") and parts[3].endswith("hi"):
                header[parts[2][0]] = (float(parts[0]), float(parts[1]))
        elif section == "Atoms":
            atoms.append((k, s.split()))
    return header, atoms


def read_liggghts_data(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Spheres of a LIGGGHTS/LAMMPS data file (``Atoms``: id type diameter density x y z),
    in the order of their ids."""
    header, atoms = _liggghts_sections(path)
    if not atoms:
        raise ParameterError(f"{path}: no 'Atoms' section (a LIGGGHTS data file, atom style "
                             "granular: id type diameter density x y z)")
    rows = []
    for k, fields in atoms:
        vals = _numbers(path, k, fields, 7, "id type diameter density x y z")
        rows.append((int(vals[0]), vals[4], vals[5], vals[6], 0.5 * vals[2]))
    if "atoms" in header and header["atoms"] != len(rows):
        raise ParameterError(f"{path}: the header says {header['atoms']} atoms, the Atoms "
                             f"section has {len(rows)}")
    rows.sort()
    return _checked(path, [row[1:4] for row in rows], [row[4] for row in rows])


def read_liggghts_box(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """The box (lo, hi) of a LIGGGHTS/LAMMPS data file's header, m."""
    header, _ = _liggghts_sections(path)
    if not all(a in header for a in "xyz"):
        raise ParameterError(f"{path}: the header lacks the 'xlo xhi', 'ylo yhi', 'zlo zhi' lines")
    lo = np.array([header[a][0] for a in "xyz"])
    hi = np.array([header[a][1] for a in "xyz"])
    return lo, hi


def write_liggghts_data(path: PathLike, centers, radii, *, density: float, lo, hi) -> None:
    """Writes a LIGGGHTS data file (atom style granular: id type diameter density x y z),
    with the box [lo, hi] (m) and one atom type; density in kg/m^3."""
    c, r = _validated(centers, radii)
    if not (np.isfinite(density) and density > 0):
        raise ParameterError(f"density={density}: must be > 0 (kg/m^3)")
    lo, hi = np.asarray(lo, float).tolist(), np.asarray(hi, float).tolist()
    density = float(density)
    with open(path, "w") as f:
        f.write("LIGGGHTS data file written by geogrid-dem (SI units)\n\n")
        f.write(f"{len(r)} atoms\n1 atom types\n\n")
        for a, name in enumerate("xyz"):
            f.write(f"{lo[a]!r} {hi[a]!r} {name}lo {name}hi\n")
        f.write("\nAtoms\n\n")
        for k, ((x, y, z), rad) in enumerate(zip(c.tolist(), r.tolist()), start=1):
            f.write(f"{k} 1 {2 * rad!r} {density!r} {x!r} {y!r} {z!r}\n")


# ---- PFC ---------------------------------------------------------------------------------------

def read_pfc_balls(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Balls of a PFC ball list (``id x y z radius`` per line), in the order of their ids."""
    rows = []
    for k, line in enumerate(_lines(path), start=1):
        s = line.strip()
        if not s or s.startswith(("#", ";")):
            continue
        fields = s.replace(",", " ").split()
        if not rows and k == 1:
            try:
                float(fields[0])
            except ValueError:
                continue  # a header line
        vals = _numbers(path, k, fields, 5, "id x y z radius")
        rows.append((int(vals[0]), vals[1], vals[2], vals[3], vals[4]))
    rows.sort()
    return _checked(path, [row[1:4] for row in rows], [row[4] for row in rows])


def write_pfc_balls(path: PathLike, centers, radii) -> None:
    """Writes a PFC ball list (header, then ``id x y z radius`` per ball, ids from 1)."""
    c, r = _validated(centers, radii)
    with open(path, "w") as f:
        f.write("id x y z radius\n")
        for k, ((x, y, z), rad) in enumerate(zip(c.tolist(), r.tolist()), start=1):
            f.write(f"{k} {x!r} {y!r} {z!r} {rad!r}\n")


def _validated(centers, radii) -> tuple[np.ndarray, np.ndarray]:
    try:
        c = np.asarray(centers, dtype=float).reshape(-1, 3)
        r = np.asarray(radii, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ParameterError("centers, radii: must be numbers, (n, 3) and (n,) (m)") from None
    if len(c) != len(r):
        raise ParameterError(f"radii: {len(r)} values for {len(c)} centres")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(r)) and np.all(r > 0)):
        raise ParameterError("centers, radii: must be finite, radii > 0 (m)")
    return c, r
