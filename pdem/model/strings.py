"""Many short strings kept as one buffer: the block names every rank holds for every block.

A Python ``str`` of a block name ("stack_12_3_7") is an object of ~60 bytes plus an 8-byte slot
in its list; every rank keeps one per scene block (names in messages, selections by name), so
at 10^6 blocks that alone is ~70 MB a rank. Here a name costs its UTF-8 bytes and an 8-byte
end offset: read back one at a time (:meth:`StringColumn.__getitem__`), which is all its users
do (a message, a selection's comparison, the output's names at open).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np


class StringColumn:
    """An immutable sequence of strings stored as one UTF-8 buffer and their end offsets."""

    __slots__ = ("_buf", "_end")

    def __init__(self, strings: Iterable[str]):
        encoded = [s.encode("utf-8") for s in strings]
        self._end = np.cumsum(np.fromiter(map(len, encoded), np.int64, len(encoded)))
        self._buf = b"".join(encoded)

    def __len__(self) -> int:
        return len(self._end)

    def __getitem__(self, i) -> str:
        i = int(i)
        n = len(self._end)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError(f"string {i} of {n}")
        start = int(self._end[i - 1]) if i else 0
        return self._buf[start:int(self._end[i])].decode("utf-8")

    def __iter__(self) -> Iterator[str]:
        start = 0
        buf = self._buf
        for end in self._end.tolist():
            yield buf[start:end].decode("utf-8")
            start = end

    def __eq__(self, other) -> bool:
        if isinstance(other, StringColumn):
            return self._buf == other._buf and np.array_equal(self._end, other._end)
        if isinstance(other, (list, tuple)):
            return len(other) == len(self) and all(a == b for a, b in zip(self, other, strict=True))
        return NotImplemented

    __hash__ = None  # mutable-looking container semantics: equal by content, not hashable

    def positions(self, wanted: Iterable[str]) -> dict[str, int]:
        """The first index of each string of ``wanted`` that is in the column (one pass)."""
        want = set(wanted)
        found: dict[str, int] = {}
        for i, s in enumerate(self):
            if s in want and s not in found:
                found[s] = i
                if len(found) == len(want):
                    break
        return found

    def lengths(self) -> np.ndarray:
        """Each string's length in UTF-8 bytes."""
        return np.diff(self._end, prepend=0)

    @property
    def max_bytes(self) -> int:
        """The longest string's length in UTF-8 bytes (0 for none)."""
        return int(self.lengths().max(initial=0))

    @property
    def nbytes(self) -> int:
        return len(self._buf) + self._end.nbytes
