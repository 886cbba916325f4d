"""Key paths into a scene mapping (``"joints.bedding.friction"``, ``"stages.strength.solve.ratio"``,
``"blocks[2].fixed"``): read and replace one value, for ``Scene.with_`` and a study's cases.

A part of a path names a mapping's key, or an entry of a list by its index (``[2]`` or ``.2``) or
by its ``name`` (``stages.strength``: the stage called "strength"). Missing mapping keys on the
way are created (the scene's validation then says whether they exist in the schema); a list
entry that is not there is an error naming the path.
"""

from __future__ import annotations

import copy
import re
from typing import Any

from .errors import ConfigError

__all__ = ["get_path", "parse_path", "with_overrides"]

_PART = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def parse_path(path: str) -> list[str | int]:
    """``"a.b[2].c"`` -> ``["a", "b", 2, "c"]`` (a bare digit part is an index too)."""
    if not isinstance(path, str) or not path.strip():
        raise ConfigError([f"{path!r}: a key path is text such as 'joints.bedding.friction'"])
    parts: list[str | int] = []
    pos = 0
    for m in _PART.finditer(path):
        gap = path[pos:m.start()]
        if gap not in ("", ".") or (gap == "" and pos and m.group(1) is not None):
            raise ConfigError([f"{path}: not a key path (at {path[pos:]!r})"])
        key, index = m.groups()
        parts.append(int(index) if index is not None else int(key) if key.isdigit() else key)
        pos = m.end()
    if pos != len(path):
        raise ConfigError([f"{path}: not a key path (at {path[pos:]!r})"])
    return parts


def _entry(items: list, part: str | int, path: str, done: str):
    """The index of ``part`` (an index or an entry's name) in the list ``items``."""
    if isinstance(part, int):
        if not 0 <= part < len(items):
            raise ConfigError([f"{path}: {done} has {len(items)} entries, no [{part}]"])
        return part
    for k, item in enumerate(items):
        if isinstance(item, dict) and item.get("name") == part:
            return k
    names = [str(it.get("name")) for it in items if isinstance(it, dict) and "name" in it]
    raise ConfigError([f"{path}: {done} has no entry named {part!r} (names: "
                       f"{', '.join(names) or 'none'})"])


def _walk(data: Any, parts: list, path: str, create: bool):
    """The container holding the last part, and that part (a key or an index)."""
    node, done = data, ""
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(node, list):
            part = _entry(node, part, path, done or "(top level)")
        elif isinstance(node, dict):
            if not isinstance(part, str):
                part = str(part)
            if part not in node and not last:
                if not create:
                    raise ConfigError([f"{path}: {done or 'the scene'} has no key {part!r}"])
                node[part] = {}
        else:
            raise ConfigError([f"{path}: {done} is a value ({node!r}), not a mapping or list"])
        if last:
            return node, part
        done = f"{done}.{part}" if isinstance(part, str) and done else \
            f"{done}[{part}]" if isinstance(part, int) else str(part)
        node = node[part]
    raise ConfigError([f"{path}: an empty key path"])


def get_path(data: dict, path: str) -> Any:
    """The value at ``path`` in the mapping ``data`` (KeyError-free: a ConfigError naming it)."""
    holder, part = _walk(data, parse_path(path), path, create=False)
    if isinstance(holder, dict) and part not in holder:
        raise ConfigError([f"{path}: not given in the scene (its default applies)"])
    return holder[part]


def with_overrides(data: dict, overrides: dict[str, Any]) -> dict:
    """A deep copy of the scene mapping ``data`` with each ``path: value`` of ``overrides``
    replaced (validate the result: an unknown key is found there, with its path)."""
    out = copy.deepcopy(data)
    for path, value in overrides.items():
        holder, part = _walk(out, parse_path(path), path, create=True)
        holder[part] = copy.deepcopy(value)
    return out
