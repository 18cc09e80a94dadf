"""MkDocs hook of the API reference (named in mkdocs.yml): the module pages and their import check.

The packages to document are listed in mkdocs.yml under ``extra: api_reference: packages``
(package name -> its folder, relative to mkdocs.yml). For every module found there:

- the module is imported first; a module that fails to import stops the build with an error
  naming the module and the exception (the reference itself is read from the source by griffe,
  which would otherwise describe a module that cannot be used);
- a page ``<package>/<sub>/<module>.md`` holding ``::: <module>`` is generated (a package gets
  ``.../index.md``), and the navigation lists the pages package by package.

Private modules (a name part starting with ``_``) are imported but get no page, except those
listed under ``api_reference: private_pages`` (the compiled core, read from its ``.pyi`` stub).
"""

from __future__ import annotations

import importlib
import logging
import traceback
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files

log = logging.getLogger("mkdocs.hooks.api_reference")

_PAGES: dict[str, str] = {}  # module name -> page path (src_uri) of the current build


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


def _settings(config: MkDocsConfig) -> tuple[dict[str, Path], set[str]]:
    ref = (config.extra or {}).get("api_reference")
    if not isinstance(ref, dict) or not isinstance(ref.get("packages"), dict) or not ref["packages"]:
        raise PluginError("mkdocs.yml: extra: api_reference: packages must map each package name "
                          "to its folder (relative to mkdocs.yml)")
    base = Path(config.config_file_path).parent
    packages = {str(k): (base / str(v)).resolve() for k, v in ref["packages"].items()}
    private = ref.get("private_pages") or []
    if not isinstance(private, list):
        raise PluginError(f"mkdocs.yml: extra: api_reference: private_pages={private!r}: must be a "
                          "list of module names")
    return packages, set(map(str, private))


def on_config(config: MkDocsConfig) -> MkDocsConfig:
    packages, private_pages = _settings(config)
    _PAGES.clear()
    nav: list = [{"Overview": "index.md"}]
    all_modules: list[str] = []
    for name, folder in packages.items():
        section = []
        for module, is_package in find_modules(name, folder):
            all_modules.append(module)
            private = any(part.startswith("_") for part in module.split("."))
            if private and module not in private_pages:
                continue
            _PAGES[module] = page_path(module, is_package)
            section.append({module: _PAGES[module]})
        nav.append({name: section})
    missing = sorted(private_pages - set(_PAGES))
    if missing:
        raise PluginError(f"mkdocs.yml: extra: api_reference: private_pages: {missing} not found "
                          "in the packages listed")
    failed = import_failures(all_modules)
    if failed:
        raise PluginError(f"API reference: {len(failed)} of {len(all_modules)} modules fail to "
                          "import:\n  " + "\n  ".join(failed))
    log.info("API reference: %d modules import, %d pages", len(all_modules), len(_PAGES))
    config.nav = nav
    return config


def on_files(files: Files, config: MkDocsConfig) -> Files:
    for module, src_uri in _PAGES.items():
        files.append(File.generated(config, src_uri, content=f"::: {module}\n"))
    return files
