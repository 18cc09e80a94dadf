"""bench/ab_build.py's membrane scene is built and stepped, and an unknown scene refused (the
builds themselves are not made here: CI does not run the A/B)."""

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _ab():
    spec = importlib.util.spec_from_file_location("ab_build", ROOT / "bench" / "ab_build.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["ab_build"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_the_membrane_scene_is_the_cylindrical_specimen_in_its_membrane():
    ab = _ab()
    scene, advance = ab.membrane_scene(100)
    n0 = scene.step_count
    advance(20)
    assert scene.step_count == n0 + 20
    assert scene.num_bodies > 100  # the grains and the membrane's nodes
    assert len(scene.grid_contacts()["sphere"]) > 0  # the membrane holds the grains
    assert scene.wall_velocities[1][2] < 0  # the lid moves down


def test_an_unknown_scene_is_refused_by_name():
    ab = _ab()
    with pytest.raises(SystemExit, match="membrane"):
        ab.main(["--scenes", "cylinder:100"])
