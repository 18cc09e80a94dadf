"""MkDocs hook of the API reference (named in mkdocs.yml): the module pages and their import check.

The packages to document are listed in mkdocs.yml under ``extra: api_reference: packages``
(package name -> its folder, relative to mkdocs.yml). For every module found there:

- the module is imported first; a module that fails to import stops the build with an error
  naming the module and the exception (the reference itself is read from the source by griffe,
  which would otherwise describe a module that cannot be used);
- a page ``<folder>/<package>/<sub>/<module>.md`` holding ``::: <module>`` is generated (a
  package gets ``.../index.md``; ``<folder>`` is ``api_reference: folder`` under the docs, where
  the landing page ``index.md`` of the reference is), and the navigation gets a section "API
  reference": the landing page, then the pages package by package, after the pages of the
  ``nav`` of mkdocs.yml (the guide).

Private modules (a name part starting with ``_``) are imported but get no page, except those
listed under ``api_reference: private_pages`` (the compiled core, read from its ``.pyi`` stub).

A class bound from C++ has its members on the compiled class, which the Python package
re-exports or subclasses (``cpp_dem.Scene`` derives from ``cpp_dem._core.Scene``). The modules
listed under ``api_reference: bound_modules`` are those compiled ones: a page holding a class
of theirs, or a subclass of one, lists the inherited members as well (mkdocstrings'
``inherited_members``), each with its docstring. So does a page holding a class composed of
parts, the modules listed under ``api_reference: part_modules`` (``femcoupling.fem.model.
FemModel`` and the modules of its parts).
"""

from __future__ import annotations

import importlib
import inspect
import logging
import traceback
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files

log = logging.getLogger("mkdocs.hooks.api_reference")

_PAGES: dict[str, str] = {}  # module name -> page path (src_uri) of the current build
_INHERITED: set[str] = set()  # modules whose page lists inherited members


def find_modules(name: str, folder: Path) -> list[tuple[str, bool]]:
    """The modules of package ``name`` in ``folder``: (dotted name, is a package), sorted.

    A ``.py`` file is a module, a folder with ``__init__.py`` a package, and a ``.pyi`` stub
    without a ``.py`` beside it a compiled module.
    """
    if not (folder / "__init__.py").is_file():
        raise PluginError(f"api_reference: packages: {name}: {folder} is not a package folder "
                          "(no __init__.py)")
    found: dict[str, bool] = {}
    for path in sorted(folder.rglob("*.py*")):
        rel = path.relative_to(folder)
        if "__pycache__" in rel.parts or path.suffix not in (".py", ".pyi"):
            continue
        if path.suffix == ".pyi" and path.with_suffix(".py").exists():
            continue
        parts = [name, *rel.with_suffix("").parts]
        if parts[-1] == "__init__":
            found[".".join(parts[:-1])] = True
        elif all((folder.joinpath(*rel.parts[:i]) / "__init__.py").is_file()
                 for i in range(len(rel.parts))):
            found.setdefault(".".join(parts), False)
    return sorted(found.items())


def import_failures(modules: list[str]) -> list[str]:
    """``module: ExceptionType: message`` for each module that fails to import."""
    failed = []
    for module in modules:
        try:
            importlib.import_module(module)
        except BaseException as exc:  # noqa: BLE001  (SystemExit of a script-like module too)
            if isinstance(exc, KeyboardInterrupt):
                raise
            log.debug("import of %s failed:\n%s", module, traceback.format_exc())
            failed.append(f"{module}: {type(exc).__name__}: {exc}")
    return failed


def page_path(module: str, is_package: bool) -> str:
    """The page (docs-relative path) of a module: a/b/c.md, or a/b/index.md for package a.b."""
    parts = module.split(".")
    return "/".join(parts) + ("/index.md" if is_package else ".md")


def bound_classes(module: str, bound_modules: set[str]) -> list[str]:
    """The public classes of (imported) ``module`` that are, or derive from, a class of one of
    ``bound_modules``: its ``__all__`` if it has one, otherwise the names it defines."""
    mod = importlib.import_module(module)
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n, obj in vars(mod).items()
                 if not n.startswith("_") and getattr(obj, "__module__", None) == module]
    found = []
    for name in names:
        obj = getattr(mod, name, None)
        if inspect.isclass(obj) and any(c.__module__ in bound_modules for c in obj.__mro__):
            found.append(name)
    return found


def _settings(config: MkDocsConfig) -> tuple[dict[str, Path], set[str], str, set[str]]:
    ref = (config.extra or {}).get("api_reference")
    if not isinstance(ref, dict) or not isinstance(ref.get("packages"), dict) or not ref["packages"]:
        raise PluginError("mkdocs.yml: extra: api_reference: packages must map each package name "
                          "to its folder (relative to mkdocs.yml)")
    base = Path(config.config_file_path).parent
    packages = {str(k): (base / str(v)).resolve() for k, v in ref["packages"].items()}
    lists = {}
    for key in ("private_pages", "bound_modules", "part_modules"):
        value = ref.get(key) or []
        if not isinstance(value, list):
            raise PluginError(f"mkdocs.yml: extra: api_reference: {key}={value!r}: must be a "
                              "list of module names")
        lists[key] = set(map(str, value))
    folder = str(ref.get("folder") or "").strip("/")
    return (packages, lists["private_pages"], folder,
            lists["bound_modules"] | lists["part_modules"])


def on_config(config: MkDocsConfig) -> MkDocsConfig:
    packages, private_pages, folder, bound_modules = _settings(config)
    prefix = f"{folder}/" if folder else ""
    _PAGES.clear()
    _INHERITED.clear()
    nav: list = [{"Overview": f"{prefix}index.md"}]
    all_modules: list[str] = []
    for name, folder_path in packages.items():
        section = []
        for module, is_package in find_modules(name, folder_path):
            all_modules.append(module)
            private = any(part.startswith("_") for part in module.split("."))
            if private and module not in private_pages:
                continue
            _PAGES[module] = prefix + page_path(module, is_package)
            section.append({module: _PAGES[module]})
        nav.append({name: section})
    for key, names, known in (("private_pages", private_pages, _PAGES),
                              ("bound_modules", bound_modules, all_modules)):
        missing = sorted(set(names) - set(known))
        if missing:
            raise PluginError(f"mkdocs.yml: extra: api_reference: {key}: {missing} not found "
                              "in the packages listed")
    failed = import_failures(all_modules)
    if failed:
        raise PluginError(f"API reference: {len(failed)} of {len(all_modules)} modules fail to "
                          "import:\n  " + "\n  ".join(failed))
    if bound_modules:
        _INHERITED.update(m for m in _PAGES if bound_classes(m, bound_modules))
    log.info("API reference: %d modules import, %d pages (%d with inherited members: %s)",
             len(all_modules), len(_PAGES), len(_INHERITED), ", ".join(sorted(_INHERITED)))
    guide = list(config.nav or [])
    config.nav = [*guide, {"API reference": nav}] if guide else nav
    return config


def on_files(files: Files, config: MkDocsConfig) -> Files:
    for module, src_uri in _PAGES.items():
        content = f"::: {module}\n"
        if module in _INHERITED:
            content += "    options:\n      inherited_members: true\n"
        files.append(File.generated(config, src_uri, content=content))
    return files
