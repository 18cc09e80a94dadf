"""Shared helpers for the test suite."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PYTHON = sys.executable


def sphere_mass(density: float, radius: float) -> float:
    """Mass of a sphere, kg."""
    return density * 4.0 / 3.0 * math.pi * radius**3


@pytest.fixture
def linear_mat():
    import cpp_dem as dem

    return dem.Material(model="linear", density=2600.0, young=1e7, poisson=0.3,
                        friction_angle_deg=30.0)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
