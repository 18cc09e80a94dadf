"""The API reference (``make docs``, docs/api.md) builds with no warning and holds the objects.

The real reference is built once (MkDocs, ``--strict``: a warning fails the build) into a
temporary folder. A synthetic package, built with the same configuration, shows that the checks
bite: a docstring naming a parameter the function does not have, a cross-reference to nothing,
and a module that fails to import each make the build fail, while the same package without the
fault builds.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "mkdocs.yml"
HOOK = ROOT / "docs" / "api" / "reference_pages.py"
EXTENSION = ROOT / "docs" / "api" / "docstring_style.py"


def build(config: Path, site: Path, pythonpath: Path | None = None) -> subprocess.CompletedProcess:
    """``mkdocs build --strict`` of ``config`` into ``site`` (run from the repository root)."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(pythonpath), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config),
                           "-d", str(site)], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("api_docs") / "html"
    run = build(CONFIG, out)
    assert run.returncode == 0, f"mkdocs build --strict failed:\n{run.stderr[-6000:]}"
    return out, run.stderr


def _ids(page: Path) -> str:
    assert page.is_file(), f"{page} was not built"
    return page.read_text(encoding="utf-8")


def test_reference_builds_without_a_warning(site):
    _, log = site
    assert "WARNING" not in log and "ERROR" not in log, log
    assert "modules import" in log  # the import check of the hook ran


@pytest.mark.parametrize("page, objects", [
    ("cpp_dem/index.html", ["cpp_dem.Scene", "cpp_dem.Scene.run", "cpp_dem.Material"]),
    ("cpp_dem/scene.html", ["cpp_dem.scene.Scene.run", "cpp_dem.scene.linear_material"]),
    ("cpp_dem/_core.html", ["cpp_dem._core.Scene", "cpp_dem._core.Material"]),
    ("cpp_dem/elements/pool.html", ["cpp_dem.elements.pool.ElementPool"]),
    ("femcoupling/hierarchical.html", ["femcoupling.hierarchical"]),
    ("geogrid_dem/cli.html", ["geogrid_dem.cli", "geogrid_dem.cli.main"]),
])
def test_pages_hold_the_objects(site, page, objects):
    html = _ids(site[0] / page)
    missing = [o for o in objects if f'id="{o}"' not in html]
    assert not missing, f"{page} lacks {missing}"


def test_every_public_module_has_a_page(site):
    spec = importlib.util.spec_from_file_location("_api_reference_pages", HOOK)
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    packages = yaml.safe_load(CONFIG.read_text(encoding="utf-8"))["extra"]["api_reference"]["packages"]
    missing = []
    for name, folder in packages.items():
        modules = hook.find_modules(name, ROOT / folder)
        assert len(modules) > 3, f"{name}: found only {modules}"
        for module, is_package in modules:
            if any(p.startswith("_") for p in module.split(".")) and module != "cpp_dem._core":
                continue
            page = site[0] / hook.page_path(module, is_package).replace(".md", ".html")
            if not page.is_file() or f'id="{module}"' not in page.read_text(encoding="utf-8"):
                missing.append(module)
    assert not missing, f"modules without a page: {missing}"


def test_docstrings_read_as_written(site):
    """``name : description`` stays a description (type from the signature); ``::`` is code."""
    core = _ids(site[0] / "cpp_dem/_core.html")
    start = core.index('id="cpp_dem._core.Material"')
    material = core[start:core.index('id="cpp_dem._core.Material.density"', start)]
    assert "mass density, kg/m^3 (&gt; 0)." in material
    assert "1–6) or" in material and "Cundall–Strack, 000 eqs" in material  # one sentence
    package = _ids(site[0] / "cpp_dem/index.html")
    assert "Quick start:</p>" in package and "<pre><code" in package
    assert ":func:" not in _ids(site[0] / "cpp_dem/io/vtk.html")


# --- the checks bite: a synthetic package built with the same configuration --------------------

GOOD_MODULE = '''
"""A module of the synthetic package."""


def double(x: float) -> float:
    """Twice ``x``; see [synth.mod.half][].{note}

    Parameters
    ----------
    x : the number, m.
    {extra}
    """
    return 2 * x


def half(x: float) -> float:
    """Half of ``x`` (:func:`double` undone)."""
    return x / 2
'''

FAULTS = {
    # The fault the reference had: free text after a numpy section reads as a parameter.
    "docstring names a parameter the function lacks": (
        {"extra": "\n    Returns the doubled number."},
        "Parameter 'Returns' does not appear in the function signature"),
    "cross-reference to nothing": (
        {"note": " Compare [synth.mod.nowhere][]."},
        "Could not find cross-reference target 'synth.mod.nowhere'"),
    "module fails to import": ({"bad": "import not_a_module_of_this_project\n"},
                               "synth.bad: ModuleNotFoundError"),
}


def _synthetic(tmp_path: Path, extra: str = "", note: str = "", bad: str | None = None) -> Path:
    src = tmp_path / "src" / "synth"
    src.mkdir(parents=True)
    (src / "__init__.py").write_text('"""A synthetic package."""\n')
    (src / "mod.py").write_text(GOOD_MODULE.format(extra=extra, note=note))
    if bad is not None:
        (src / "bad.py").write_text(f'"""Fails to import."""\n{bad}')
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "index.md").write_text("# Synthetic\n")
    config = yaml.safe_load(CONFIG.read_text(encoding="utf-8"))
    config.update(docs_dir=str(docs), site_dir=str(tmp_path / "site"), hooks=[str(HOOK)])
    config["extra"]["api_reference"] = {"packages": {"synth": str(src)}, "private_pages": []}
    for plugin in config["plugins"]:
        if isinstance(plugin, dict) and "mkdocstrings" in plugin:
            python = plugin["mkdocstrings"]["handlers"]["python"]
            python["paths"] = [str(src.parent)]
            python["options"]["extensions"] = [f"{EXTENSION}:FreeFormDocstrings"]
    path = tmp_path / "mkdocs.yml"
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    return path


def test_synthetic_package_without_a_fault_builds(tmp_path):
    run = build(_synthetic(tmp_path), tmp_path / "site", tmp_path / "src")
    assert run.returncode == 0, run.stderr[-4000:]
    html = (tmp_path / "site" / "synth" / "mod.html").read_text(encoding="utf-8")
    assert 'id="synth.mod.double"' in html and 'href="#synth.mod.half"' in html


@pytest.mark.parametrize("fault", list(FAULTS))
def test_a_fault_fails_the_build(tmp_path, fault):
    files, message = FAULTS[fault]
    config = _synthetic(tmp_path, **files)
    run = build(config, tmp_path / "site", tmp_path / "src")
    assert run.returncode != 0, f"{fault}: the build passed:\n{run.stderr[-3000:]}"
    assert message in run.stderr, run.stderr[-3000:]


def test_literal_blocks_become_fences():
    spec = importlib.util.spec_from_file_location("_api_docstring_style", EXTENSION)
    ext = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ext)
    text = textwrap.dedent("""\
        Layout::

            / attrs
              /series

        After :meth:`~a.b.run` and :py:class:`C`.""")
    assert ext.normalise_text(text) == textwrap.dedent("""\
        Layout:

        ```text
        / attrs
          /series
        ```

        After `a.b.run` and `C`.""")
