"""Registries by name: a scene string selects an entry, an unknown name is a clear error."""

from __future__ import annotations

import difflib
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

T = TypeVar("T")


class Registry(Generic[T]):
    """An ordered name -> entry map with one place that reports unknown names.

    ``kind`` names what is registered ("joint law", "damping mode", ...) in messages.
    """

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, T] = {}
        self._watchers: list[Callable[[], None]] = []

    def register(self, name: str, entry: T) -> T:
        if name in self._entries:
            raise ValueError(f"{self.kind} {name!r} is registered twice")
        self._entries[name] = entry
        try:
            self._changed()
        except Exception:
            # a watcher refused it (a scene key taken, a model of the wrong kind): undone, so
            # the registry and what follows it stay as they were
            del self._entries[name]
            self._changed()
            raise
        return entry

    def unregister(self, name: str) -> T:
        """Remove an entry (a test's, or a plugin's that is unloaded); returns it."""
        entry = self[name]
        del self._entries[name]
        self._changed()
        return entry

    def watch(self, callback: Callable[[], None]) -> None:
        """Call ``callback()`` after every change of the entries: what is derived from them
        elsewhere (the scene grammar's union of joint laws) follows a registration made from
        outside pdem's tree."""
        self._watchers.append(callback)

    def follow(self, source: Registry, project: Callable[[object], T]) -> None:
        """Keep this registry's entries ``project(entry)`` of ``source``'s, by the same names
        in the same order, now and after every change of ``source``: a registry of a higher
        floor (the boundary-condition kinds with their run-time hooks) drives one of a lower
        floor (the scene grammar's condition models), whose watchers rebuild what follows it,
        so one registration in ``source`` from outside pdem's tree is all a kind needs."""

        def sync() -> None:
            want = [(name, project(entry)) for name, entry in source.items()]
            have = list(self._entries.items())
            same = 0
            while same < min(len(want), len(have)) and want[same][0] == have[same][0] \
                    and want[same][1] == have[same][1]:
                same += 1
            for name, _ in reversed(have[same:]):
                self.unregister(name)
            for name, entry in want[same:]:
                self.register(name, entry)

        source.watch(sync)
        sync()

    def _changed(self) -> None:
        for callback in self._watchers:
            callback()

    def __getitem__(self, name: str) -> T:
        try:
            return self._entries[name]
        except KeyError:
            close = difflib.get_close_matches(name, list(self._entries), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise KeyError(f"unknown {self.kind} {name!r} (known: {', '.join(self._entries)})"
                           f"{hint}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def items(self):
        return self._entries.items()

    def values(self):
        return self._entries.values()

    def names(self) -> tuple[str, ...]:
        return tuple(self._entries)
