"""The site (``make docs``, docs/api.md): the guide and the API reference, built with no warning.

The real site is built once (MkDocs, ``--strict``: a warning fails the build) into a temporary
folder: its navigation holds the guide pages (docs/*.md, and the measured studies of
docs/studies/*.md) grouped as docs/start_here.md leads
through them, then the API reference, whose pages hold the objects; a class bound from C++
(``cpp_dem.Scene``, a subclass of ``cpp_dem._core.Scene``) lists its inherited members. A
synthetic package, built with the same configuration, shows that the checks bite: a docstring
naming a parameter the function does not have, a cross-reference to nothing, and a module that
fails to import each make the build fail, while the same package without the fault builds.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "mkdocs.yml"
DOCS = ROOT / "docs"
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
    out = tmp_path_factory.mktemp("site") / "html"
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
    ("api/cpp_dem/index.html", ["cpp_dem.Scene", "cpp_dem.Scene.run", "cpp_dem.Material"]),
    ("api/cpp_dem/scene.html", ["cpp_dem.scene.Scene.run", "cpp_dem.scene.linear_material"]),
    ("api/cpp_dem/_core.html", ["cpp_dem._core.Scene", "cpp_dem._core.Material"]),
    ("api/cpp_dem/elements/pool.html", ["cpp_dem.elements.pool.ElementPool"]),
    ("api/femcoupling/fem/model.html", ["femcoupling.fem.model.FemModel",
                                       "femcoupling.fem.model.FemModel.step"]),
    ("api/geogrid_dem/cli.html", ["geogrid_dem.cli", "geogrid_dem.cli.main"]),
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
            page = site[0] / "api" / hook.page_path(module, is_package).replace(".md", ".html")
            if not page.is_file() or f'id="{module}"' not in page.read_text(encoding="utf-8"):
                missing.append(module)
    assert not missing, f"modules without a page: {missing}"


def test_docstrings_read_as_written(site):
    """``name : description`` stays a description (type from the signature); ``::`` is code."""
    core = _ids(site[0] / "api/cpp_dem/_core.html")
    start = core.index('id="cpp_dem._core.Material"')
    material = core[start:core.index('id="cpp_dem._core.Material.density"', start)]
    # (the parameters' lines, generated from the field list: cpp_dem.material_fields)
    assert "mass density; kg/m^3; &gt; 0; required." in material
    assert "contact friction angle (stored in radians); deg; in [0, 90); required." in material
    package = _ids(site[0] / "api/cpp_dem/index.html")
    assert "Quick start:</p>" in package and re.search(r"<pre[^>]*><code", package)
    assert ":func:" not in _ids(site[0] / "api/cpp_dem/io/vtk.html")


# --- the guide in the same site, its navigation following docs/start_here.md ----------------

CAPTION = re.compile(r'<p class="caption"><span class="caption-text">([^<]*)</span></p>')
HREF = re.compile(r'href="([^"]*)"')


def navigation(site: Path, page: str = "index.html") -> tuple[list[str], list[tuple[str, list]]]:
    """The navigation of ``page`` (at the top of the site): the pages before the first
    section, then (section title, its pages in order); a page is its path in the site
    (``pullout.html``), the page itself included (its link is ``#``)."""
    html = _ids(site / page)
    start = html.index('class="wy-menu wy-menu-vertical"')
    menu = html[start:html.index("</nav>", start)]

    def pages(part: str) -> list[str]:
        hrefs = [page if h == "#" else h.split("#")[0] for h in HREF.findall(part)]
        return [h for h in hrefs if h]  # not the headings of the page itself (#id)

    parts = CAPTION.split(menu)
    return pages(parts[0]), [(unescape(parts[i]), pages(parts[i + 1]))
                             for i in range(1, len(parts), 2)]


def unescape(text: str) -> str:
    return text.replace("&amp;", "&").replace("&gt;", ">").replace("&lt;", "<")


def start_here_sections() -> tuple[set[str], list[tuple[str, set[str]]]]:
    """docs/start_here.md: the pages its introduction links, and its numbered sections (title
    up to its first colon, the pages it links)."""
    text = (DOCS / "start_here.md").read_text(encoding="utf-8")
    chunks = re.split(r"^## (\d+\. .*)$", text, flags=re.MULTILINE)

    def pages(chunk: str) -> set[str]:
        return set(re.findall(r"\]\(([\w.-]+)\.md(?:#[^)]*)?\)", chunk))

    intro = pages(re.split(r"^## ", chunks[0], flags=re.MULTILINE)[0])
    return intro, [(chunks[i].split(":")[0].strip(), pages(chunks[i + 1]))
                   for i in range(1, len(chunks), 2)]


def test_navigation_holds_the_guide_as_start_here_orders_it(site):
    root = site[0]
    top, sections = navigation(root)
    assert top[:1] == ["index.html"], top  # the home page
    assert 'id="start-here"' in _ids(root / "index.html")  # is docs/start_here.md
    linked = set(top) | {page for _, pages in sections for page in pages}
    guide = {"index.html" if p.stem == "start_here" else f"{p.stem}.html"
             for p in DOCS.glob("*.md")}
    guide |= {f"studies/{p.stem}.html" for p in (DOCS / "studies").glob("*.md")}
    assert {"pullout.html", "triaxial.html", "prs_element_002.html", "multiscale.html"} <= guide
    assert {"coupling_newton.html", "studies/footing_multiscale.html"} <= guide
    missing = sorted(g for g in guide if g not in linked or not (root / g).is_file())
    assert not missing, f"guide pages not built or not in the navigation: {missing}"
    # The pages the introduction of start_here.md names come right after it; the numbered
    # sections, in order, are those of start_here.md, each holding pages that section names;
    # every page a numbered section names is under one.
    intro, expected = start_here_sections()
    named = set().union(*(n for _, n in expected)) - {"start_here"}
    assert {f"{p}.html" for p in intro - named} <= set(top), (intro, top)
    numbered = [(t, pages) for t, pages in sections if re.match(r"\d+\. ", t)]
    assert [t for t, _ in numbered] == [t for t, _ in expected]
    placed = {page for _, pages in numbered for page in pages}
    for (title, pages), (_, names) in zip(numbered, expected):
        assert pages and all(p.removesuffix(".html") in names for p in pages), (title, pages)
    assert not sorted(p for p in named if f"{p}.html" not in placed), placed
    # The API reference is its own section, last.
    assert sections[-1][0] == "API reference"
    api = set(sections[-1][1])
    assert {"api/index.html", "api/cpp_dem/scene.html", "api/cpp_dem/_core.html"} <= api
    # Links to repository files the site does not hold became text (no link out of the site).
    # (A page one folder down, docs/studies/, leaves the site with ../../.)
    leaving = {g: re.findall(r'href="(?:\.\./){%d}[^"]*"' % (g.count("/") + 1), _ids(root / g))
               for g in guide}
    assert not any(leaving.values()), {g: h for g, h in leaving.items() if h}


def test_guide_headings_have_githubs_ids(site):
    """A heading's id in the site is GitHub's (as tests/test_docs_text.py computes it), so an
    anchor works in both; a repeated heading (GitHub ``-1``, the site ``_1``) aside."""
    checker = ROOT / "tests" / "test_docs_text.py"
    spec = importlib.util.spec_from_file_location("_docs_text", checker)
    docs_text = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(docs_text)
    differing = {}
    for page in [*sorted(DOCS.glob("*.md")), *sorted((DOCS / "studies").glob("*.md"))]:
        built = page.relative_to(DOCS).with_suffix(".html").as_posix()
        html = _ids(site[0] / ("index.html" if page.stem == "start_here" else built))
        main = html[html.index('role="main"'):]
        made = set(re.findall(r'<h[1-6] id="([^"]+)"', main))
        ids = docs_text.heading_ids(page)
        repeated = {i for i in ids if re.sub(r"-\d+$", "", i) in ids - {i}}
        github = ids - repeated
        if github - made:
            differing[page.name] = sorted(github - made)
    assert not differing, differing


def _members(html: str, cls: str) -> set[str]:
    return set(re.findall(rf'id="{re.escape(cls)}\.(\w+)"', html))


def test_scene_page_lists_the_members_of_the_compiled_scene(site):
    core = _ids(site[0] / "api/cpp_dem/_core.html")
    compiled = _members(core, "cpp_dem._core.Scene")
    assert {"positions", "velocities", "gravity"} <= compiled
    for page, cls in [("api/cpp_dem/scene.html", "cpp_dem.scene.Scene"),
                      ("api/cpp_dem/index.html", "cpp_dem.Scene")]:
        html = _ids(site[0] / page)
        members = _members(html, cls)
        assert {"run", "add_box", "add_spheres", "positions"} <= members, page
        assert not compiled - members, f"{page} lacks {sorted(compiled - members)}"
        # An inherited member with its docstring: gravity, set in Scene.__init__, is _core's.
        start = html.index(f'id="{cls}.gravity"')
        assert "Gravitational acceleration, m/s^2" in html[start:start + 3000], page


def test_every_bound_class_lists_its_inherited_members(site):
    """A class of cpp_dem._core re-exported by cpp_dem has the members its page there has;
    a subclass within the core (ServoWall of Controller) those of its base too."""
    core = _ids(site[0] / "api/cpp_dem/_core.html")
    package = _ids(site[0] / "api/cpp_dem/index.html")
    classes = sorted(set(re.findall(r'id="cpp_dem\._core\.([A-Z]\w*)"', core)))
    assert {"Scene", "Material", "Controller", "ServoWall", "CellController"} <= set(classes)
    base = _members(core, "cpp_dem._core.Controller")
    assert base and base <= _members(core, "cpp_dem._core.ServoWall")
    exported = [c for c in classes if f'id="cpp_dem.{c}"' in package]
    assert {"Scene", "Material", "ServoWall", "CellController"} <= set(exported)
    for c in exported:
        lacking = _members(core, f"cpp_dem._core.{c}") - _members(package, f"cpp_dem.{c}")
        assert not lacking, f"cpp_dem.{c} lacks {sorted(lacking)}"


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
    config.pop("nav", None)  # the reference alone, without the guide
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
