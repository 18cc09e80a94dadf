"""Griffe extension of the API reference (named in mkdocs.yml): reads the project's docstrings as written.

The docstrings are plain text with a few reStructuredText habits, rendered here as Markdown.
Nothing in the source changes; before a docstring is parsed:

- a Python role (``:func:`x```, ``:meth:``, ``:class:``, ``:mod:``, ``:attr:``, ``:data:``,
  ``:exc:``, ``:obj:``, with or without ``py:``) becomes the code span ```x```, linked to
  ``x``'s entry where the name resolves (as Python would, from the object's scope) and the
  target has one (a leading ``~`` or ``!`` of the target is dropped);
- a literal block (a paragraph ending in ``::``, then an indented block) becomes a fenced code
  block, and the ``::`` a single ``:`` (a ``::`` alone on its line goes);
- in a Google-style ``Args:`` section, an item for several names (``a, b: text``, which numpy
  style allows and Google style does not) becomes one item per name with the same text;

and after it is parsed (numpy style):

- a parameter or attribute written ``name : description`` (the project's way; numpy style
  reads the text after the colon as the type) gets that text back in front of its
  description, and its type from the signature or the attribute's annotation. Text after the
  colon counts as a type only when it parses as a Python expression (``int``, ``np.ndarray``).
"""

from __future__ import annotations

import re
from typing import Any

from griffe import Docstring, DocstringSectionKind, Extension, Object

ROLE = re.compile(r":(?:py:)?(?:func|meth|class|mod|attr|data|exc|obj|const|type):`[~!]?([^`]+)`")
# A numpy section whose items have names (only docstrings with one are parsed early).
NAMED_SECTION = re.compile(r"^\s*(Parameters|Other Parameters|Attributes)\n\s*-{3,}\s*$", re.MULTILINE)
_SECTIONS_WITH_NAMES = (DocstringSectionKind.parameters, DocstringSectionKind.other_parameters,
                        DocstringSectionKind.attributes)


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def literal_blocks_to_fences(text: str) -> str:
    """Each reST literal block (``para::``, blank line, indented lines) as a fenced code block."""
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.rstrip()
        j = i + 1
        while j < len(lines) and not lines[j].strip():
            j += 1
        base = _indent(line)
        if (stripped.endswith("::") and j > i + 1 and j < len(lines)
                and _indent(lines[j]) > base):
            head = stripped[:-2].rstrip()
            if head.strip():
                out.append(head + ":" if not head.endswith(":") else head)
                out.append("")
            end = j
            while end < len(lines) and (not lines[end].strip() or _indent(lines[end]) > base):
                end += 1
            while end > j and not lines[end - 1].strip():
                end -= 1
            block = lines[j:end]
            cut = min(_indent(b) for b in block if b.strip())
            pad = " " * base
            out.append(pad + "```text")
            out += [(pad + b[cut:]) if b.strip() else "" for b in block]
            out.append(pad + "```")
            i = end
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


GOOGLE_ARGS = re.compile(r"^(\s*)(Args|Arguments|Parameters|Keyword Args|Keyword Arguments|Attributes):\s*$")
SHARED_ITEM = re.compile(r"^(\s+)([A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)+)(\s*(?:\([^)]*\))?:(?:\s.*)?)$")


def split_shared_google_items(text: str) -> str:
    """In a Google ``Args:`` section, ``a, b: text`` becomes one item per name, same text."""
    lines = text.split("\n")
    out: list[str] = []
    section_indent: int | None = None
    i = 0
    while i < len(lines):
        line = lines[i]
        head = GOOGLE_ARGS.match(line)
        if head:
            section_indent = len(head.group(1))
        elif line.strip() and section_indent is not None and _indent(line) <= section_indent:
            section_indent = None
        item = SHARED_ITEM.match(line) if section_indent is not None else None
        if item and _indent(line) > section_indent:
            j = i + 1
            while j < len(lines) and lines[j].strip() and _indent(lines[j]) > _indent(line):
                j += 1
            for name in re.split(r"\s*,\s*", item.group(2)):
                out.append(item.group(1) + name + item.group(3))
                out += lines[i + 1:j]
            i = j
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


def role_target(obj: Object | None, target: str) -> str | None:
    """The full path a role's target names, seen from ``obj`` (None when not found).

    The first part of the name is looked up as Python would in ``obj``'s scope (its members,
    its module's names and imports); a dotted name not found there is taken as a full path.
    """
    first, _, rest = target.partition(".")
    if obj is not None and first.isidentifier():
        try:
            base = obj.resolve(first)
        except Exception:  # noqa: BLE001  (griffe's NameResolutionError and lookup errors)
            base = None
        if base:
            return base + ("." + rest if rest else "")
        scope = obj
        while scope is not None and not scope.is_class:
            scope = scope.parent
        if scope is not None and first in scope.all_members:  # inherited from a base class
            member = scope.all_members[first]
            return (member.target_path if member.is_alias else member.path) + ("." + rest if rest else "")
    return target if rest and all(p.isidentifier() for p in target.split(".")) else None


def normalise_text(text: str, obj: Object | None = None) -> str:
    """The docstring text with roles as code spans, literal blocks fenced, shared items split.

    With ``obj``, a role whose target is found becomes an optional cross-reference: a link
    where the target has a page, the code span alone where it has none (never a warning).
    """
    def role(match: re.Match) -> str:
        shown = match.group(1)
        path = role_target(obj, shown) if obj is not None else None
        if path is None:
            return f"`{shown}`"
        return f'<autoref identifier="{path}" optional><code>{shown}</code></autoref>'

    return split_shared_google_items(literal_blocks_to_fences(ROLE.sub(role, text)))


def _signature_annotation(obj: Object, name: str) -> Any:
    if obj.is_function:
        params = obj.parameters
    elif obj.is_class and "__init__" in obj.members and obj.members["__init__"].is_function:
        params = obj.members["__init__"].parameters
    else:
        params = None
    if params is not None and name in params:
        return params[name].annotation
    return None


def _attribute_annotation(obj: Object, name: str) -> Any:
    member = obj.members.get(name) if hasattr(obj, "members") else None
    if member is not None and not member.is_alias and member.is_attribute:
        return member.annotation
    return None


def restore_descriptions(obj: Object, docstring: Docstring) -> int:
    """Moves a ``name : description`` text back to the description; returns how many."""
    moved = 0
    for section in docstring.parsed:
        if section.kind not in _SECTIONS_WITH_NAMES:
            continue
        for item in section.value:
            if not isinstance(item.annotation, str) or not item.annotation.strip():
                continue
            text = item.annotation.strip()
            item.description = text + ("\n" + item.description if item.description else "")
            if section.kind is DocstringSectionKind.attributes:
                item.annotation = _attribute_annotation(obj, item.name)
            else:
                item.annotation = _signature_annotation(obj, item.name)
            moved += 1
    return moved


class FreeFormDocstrings(Extension):
    """Reads the free-form docstrings of cpp_dem, femcoupling and geogrid_dem (module docstring)."""

    def on_object(self, *, obj: Object, **kwargs: Any) -> None:
        self._read(obj)

    def on_package(self, *, pkg: Object, **kwargs: Any) -> None:
        self._read(pkg)  # the top package gets no on_object of its own

    @staticmethod
    def _read(obj: Object) -> None:
        # Once the whole tree is built (names resolve), and before the docstring is parsed.
        if obj.docstring is None:
            return
        obj.docstring.value = normalise_text(obj.docstring.value, obj)
        if obj.docstring.parser is not None and NAMED_SECTION.search(obj.docstring.value):
            restore_descriptions(obj, obj.docstring)
