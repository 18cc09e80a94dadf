"""Sphere packings as CSV files: columns ``x,y,z,r`` (m) with a header line."""

from __future__ import annotations

import os

import numpy as np

from ._core import ParameterError

CSV_HEADER = "x,y,z,r"


def write_packing_csv(path: str | os.PathLike, centers, radii) -> None:
    """Writes centres (n, 3) and radii (n,) in m to ``path`` as CSV with header ``x,y,z,r``."""
    c = np.asarray(centers, dtype=float).reshape(-1, 3)
    r = np.asarray(radii, dtype=float).reshape(-1)
    if len(c) != len(r):
        raise ParameterError(f"radii: has {len(r)} values for {len(c)} centres")
    data = np.column_stack([c, r])
    np.savetxt(path, data, delimiter=",", header=CSV_HEADER, comments="", fmt="%.17g")


def read_packing_csv(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Reads a packing CSV (header ``x,y,z,r``, m); returns (centres (n, 3), radii (n,)).

    Raises ParameterError naming the file, line and problem for bad content.
    """
    with open(path, encoding="utf-8") as fh:
        header = fh.readline().strip().replace(" ", "").lower()
        if header != CSV_HEADER:
            raise ParameterError(f"{path}: header is '{header}', expected '{CSV_HEADER}'")
        rows = []
        for lineno, line in enumerate(fh, start=2):
            line = line.strip()
            if not line:
                continue
            parts = line.split(",")
            if len(parts) != 4:
                raise ParameterError(f"{path}:{lineno}: expected 4 values x,y,z,r, got {len(parts)}")
            try:
                vals = [float(p) for p in parts]
            except ValueError as exc:
                raise ParameterError(f"{path}:{lineno}: not a number ({exc})") from None
            if not np.all(np.isfinite(vals)):
                raise ParameterError(f"{path}:{lineno}: values must be finite")
            if vals[3] <= 0:
                raise ParameterError(f"{path}:{lineno}: r={vals[3]}: must be > 0 (m)")
            rows.append(vals)
    if not rows:
        raise ParameterError(f"{path}: no spheres")
    data = np.asarray(rows, dtype=float)
    return data[:, :3].copy(), data[:, 3].copy()
