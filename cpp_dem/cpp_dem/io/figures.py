"""Figures for papers: every figure a case draws is saved as a 300 dpi PNG and a PDF beside it."""

from __future__ import annotations

from pathlib import Path

#: Resolution of the PNG figures, dots per inch.
DPI = 300


def save_figure(fig, png_path) -> tuple[Path, Path]:
    """Saves ``fig`` as ``png_path`` (300 dpi) and the same name with ``.pdf`` (vector);
    returns both paths."""
    png = Path(png_path)
    pdf = png.with_suffix(".pdf")
    fig.savefig(png, dpi=DPI)
    fig.savefig(pdf)
    return png, pdf
