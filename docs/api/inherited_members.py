"""Griffe extension of the API reference (named in mkdocs.yml): a base's member set in ``__init__``.

``cpp_dem.Scene.__init__`` sets ``self.gravity = ...``, which goes through the property
``gravity`` of the compiled base ``cpp_dem._core.Scene``. Griffe, reading the source, takes the
assignment for a new instance attribute of ``Scene`` without a docstring, which hides the
documented member of the base (the page lists the inherited members, but not a name the class
seems to define itself).

Here, a class's instance attribute (assigned in a method, not declared in the class body)
without a docstring, whose name a base class defines, is dropped from the class: the page then
shows the base's member, with its docstring, among the inherited members. An attribute with a
docstring of its own, or one no base defines, stays.
"""

from __future__ import annotations

import logging
from typing import Any

from griffe import Class, Extension, Module, Object

log = logging.getLogger("mkdocs.plugins.griffe.inherited_members")


def _classes(obj: Object):
    for member in obj.members.values():
        if member.is_alias:
            continue
        if isinstance(member, Class):
            yield member
        if isinstance(member, (Class, Module)):
            yield from _classes(member)


def base_member_shadows(cls: Class) -> list[str]:
    """Names of ``cls``'s undocumented instance attributes that a base class defines."""
    try:
        bases = cls.mro()
    except Exception:  # noqa: BLE001  (a base outside the loaded packages: nothing to show)
        return []
    names = []
    for name, member in cls.members.items():
        if member.is_alias or not member.is_attribute or member.docstring is not None:
            continue
        if "instance-attribute" not in member.labels:
            continue
        if any(name in base.members for base in bases):
            names.append(name)
    return names


class BaseMembersSetInInit(Extension):
    """Drops a class's undocumented instance attributes that a base class defines."""

    def on_package(self, *, pkg: Module, **kwargs: Any) -> None:
        for cls in _classes(pkg):
            for name in base_member_shadows(cls):
                log.debug("%s.%s: set in a method, defined by a base: the base's shown",
                          cls.path, name)
                cls.del_member(name)
