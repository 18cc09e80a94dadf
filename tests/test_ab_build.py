"""bench/ab_build.py's scenes are built and stepped by the worker each block runs (the
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


def test_the_membrane_scene_is_the_cylindrical_specimen_and_repeats(tmp_path):
    ab = _ab()
    cfg = {"overlay": "", "scene": "membrane", "n": 150, "threads": 1, "warmup": 5,
           "steps": 20, "dump": str(tmp_path / "x.npy")}
    a, b = ab.worker(cfg), ab.worker(cfg)
    assert a["steps_done"] == 20
    assert a["bodies"] > 150  # the grains and the membrane's nodes
    assert a["state_sha256"] == b["state_sha256"]  # the same input, the same bits


def test_an_unknown_scene_is_refused_by_name():
    ab = _ab()
    with pytest.raises(SystemExit, match="membrane"):
        ab.main(["--scenes", "cylinder:100"])
