"""MkDocs hook of the guide pages (named in mkdocs.yml): the site reads them as GitHub does.

The guide pages (``docs/*.md``, and the measured studies of ``docs/studies/*.md``) are written
to be read in the repository as well as in the built site. This hook makes the site read them
the same way:

- heading ids are GitHub's (lower case, punctuation dropped, each space a ``-``), so an anchor
  such as ``speed_accuracy.md#coupled-fem--dem-prs-element`` works in both, and
  tests/test_docs_text.py checks them by the same rule;
- the first page of the navigation is the site's home page (``index.html``) when the docs
  have no ``index.md``: ``start_here.md`` opens the site;
- lists read as on GitHub: a list right under a paragraph line (no blank line between) is a
  list, and a nested list is indented by two spaces (``mdx_truly_sane_lists`` in mkdocs.yml);
- a link to a file of the repository that the site does not publish (outside the docs folder,
  such as ``../examples/x.py`` or ``../CHANGELOG.md``, or excluded from the site, such as
  ``api/reference_pages.py``) becomes its text; a link whose target does not exist is left
  alone, so that the build reports it.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import Files
from mkdocs.structure.pages import Page

_INVALID = re.compile(r"[^\w\- ]")
# An inline link (not an image): [text](target "title").
_LINK = re.compile(r"(?<!!)\[([^\]]*)\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
_FENCE = re.compile(r"^\s*(```|~~~)")
# A list item; one that may start a list under a paragraph line (CommonMark: a bullet, or an
# ordered item numbered 1).
_LIST_ITEM = re.compile(r"^\s*([-*+]|\d{1,9}[.)])\s+\S")
_LIST_START = re.compile(r"^ {0,3}([-*+]|1[.)])\s+\S")


def github_slug(text: str, separator: str = "-") -> str:
    """GitHub's id of a heading ``text``: lower case, ``[^\\w\\- ]`` dropped, spaces to ``-``."""
    return _INVALID.sub("", text.strip().lower()).replace(" ", separator)


def on_config(config: MkDocsConfig) -> MkDocsConfig:
    config.mdx_configs.setdefault("toc", {})["slugify"] = github_slug
    return config


def _first_page(nav) -> str | None:
    for item in nav or []:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        if isinstance(value, str):
            return value
        found = _first_page(value)
        if found:
            return found
    return None


def on_files(files: Files, config: MkDocsConfig) -> Files:
    if files.get_file_from_path("index.md") is not None:
        return files
    first = _first_page(config.nav)
    home = files.get_file_from_path(first) if first else None
    if home is None or not home.is_documentation_page():
        return files
    # Served as index.html and treated as the home page (its links are rewritten to it).
    home.name = "index"
    home.dest_uri = posixpath.join(posixpath.dirname(home.src_uri), "index.html")
    for cached in ("url", "abs_dest_path"):
        home.__dict__.pop(cached, None)
    return files


def _unpublished(target: str, page_dir: Path, docs: Path, root: Path, files: Files) -> bool:
    """Whether relative link ``target`` names an existing file of the repository ``root`` that
    the site does not publish: outside ``docs``, or excluded from it (docs/api/*.py)."""
    if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith(("#", "/")):
        return False
    path = (page_dir / target.split("#", 1)[0]).resolve()
    if not path.exists() or not path.is_relative_to(root):
        return False
    if not path.is_relative_to(docs):
        return True
    file = files.get_file_from_path(path.relative_to(docs).as_posix())
    return path.is_file() and (file is None or file.inclusion.is_excluded())


def on_page_markdown(markdown: str, page: Page, config: MkDocsConfig, files: Files) -> str:
    src = page.file.abs_src_path
    if src is None or page.file.generated_by is not None:
        return markdown
    docs = Path(config.docs_dir).resolve()
    root = Path(config.config_file_path).resolve().parent
    page_dir = Path(src).resolve().parent

    def replace(match: re.Match) -> str:
        text, target = match.group(1), match.group(2)
        if not _unpublished(target, page_dir, docs, root, files):
            return match.group(0)
        return text or f"`{(page_dir / target.split('#', 1)[0]).resolve().relative_to(root)}`"

    out, in_fence, in_list = [], False, False
    for line in markdown.split("\n"):
        if _FENCE.match(line):
            in_fence = not in_fence
        if in_fence:
            out.append(line)
            continue
        # A list right under a paragraph line: a blank line first, as Python-Markdown needs.
        if _LIST_START.match(line) and not in_list and out and out[-1].strip():
            out.append("")
        in_list = (in_list or bool(_LIST_ITEM.match(line))) and bool(line.strip())
        out.append(_LINK.sub(replace, line))
    return "\n".join(out)
