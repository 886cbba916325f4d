"""The block names every rank keeps for every block, as runs of ``prefix[k], prefix[k+1], …``.

pdem names the blocks of a family by their entry (or parent) and a counter: an ``array:``'s
10^6 cubes are ``cube[0]`` … ``cube[999999]``, the pieces cut from ``rock`` are ``rock[0]``,
``rock[1]``, … in gid order. Kept as such runs (a start, a first counter and the prefix), the
names of a scene cost a few bytes per entry at any block count, instead of each name's bytes
and an 8-byte offset on every rank (:class:`pdem.model.strings.StringColumn`, ~18 bytes a
cube, the largest O(N) part of what a rank keeps: docs/parallel.md). A name outside the
pattern is a run of its own; when runs would not be smaller the names stay one plain buffer.
Read like a StringColumn: by index, in order, and by :meth:`NameColumn.positions`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from .strings import StringColumn

# a run costs its start and first counter (16 bytes) and its prefix (bytes + an 8-byte end);
# runs are kept only when at most this fraction of the plain buffer
RUNS_WORTH = 0.5


def _counted(name: str) -> tuple[str, int]:
    """``(prefix, k)`` of a name ``prefix[k]`` (k as str(int) writes it), else ``(name, -1)``
    (string methods: 0.68 s against 0.81 s for a regular expression at 10^6 names)."""
    if name.endswith("]"):
        p, bracket, k = name[:-1].rpartition("[")
        if bracket and k.isascii() and k.isdigit() and len(k) <= 15 \
                and (k[0] != "0" or k == "0"):
            return p, int(k)
    return name, -1


def _digits(k: np.ndarray) -> np.ndarray:
    """Decimal digits of each non-negative int64 ``k`` (exact: compared with powers of ten)."""
    k = np.asarray(k, np.int64)
    return 1 + sum((k >= 10**j).astype(np.int64) for j in range(1, 19))


class NameColumn:
    """An immutable sequence of block names, as runs of counted names or one plain buffer."""

    __slots__ = ("_n", "_starts", "_k0", "_prefixes", "_plain")

    def __init__(self, strings: Iterable[str]):
        starts: list[int] = []
        k0s: list[int] = []
        prefixes: list[str] = []
        prev_prefix, prev_k = None, -2
        n = 0
        for i, s in enumerate(strings):
            n = i + 1
            p, k = _counted(s)
            if k < 0:  # a run of its own, the whole name as its prefix
                starts.append(i)
                k0s.append(-1)
                prefixes.append(s)
                prev_prefix, prev_k = None, -2
                continue
            if k == prev_k + 1 and p == prev_prefix:
                prev_k = k
                continue
            starts.append(i)
            k0s.append(k)
            prefixes.append(p)
            prev_prefix, prev_k = p, k
        self._n = n
        self._starts = np.array(starts, np.int64)
        self._k0 = np.array(k0s, np.int64)
        self._prefixes = StringColumn(prefixes)
        self._plain = None
        if self.nbytes > RUNS_WORTH * self._plain_bytes():
            self._plain = StringColumn(iter(self))
            self._starts = self._k0 = self._prefixes = None

    # ------------------------------------------------------------------ runs
    def _lengths_of_runs(self) -> np.ndarray:
        return np.diff(self._starts, append=self._n)

    def _plain_bytes(self) -> int:
        """What one plain buffer of these names would take (bytes and end offsets), run by
        run: a counted run of L names from ``prefix[k0]`` takes L (prefix + 2) bytes and the
        digits of k0 .. k0 + L - 1, counted by powers of ten (no per-name array: at set-up
        every rank reads every block's name, 10^6 of them a few MB less)."""
        runs = self._lengths_of_runs()
        plen = self._prefixes.lengths()
        counted = self._k0 >= 0
        k0 = np.where(counted, self._k0, 0)
        digits = runs.copy()  # one digit each, then one more for each power of ten passed
        for j in range(1, 19):
            digits += np.maximum(0, k0 + runs - np.maximum(k0, 10**j))
        total = np.where(counted, runs * (plen + 2) + digits, plen)
        return int(total.sum()) + 8 * self._n

    def _name_lengths(self) -> np.ndarray:
        """Each name's length in UTF-8 bytes, from the runs (no name is built)."""
        runs = self._lengths_of_runs()
        plen = self._prefixes.lengths()
        run = np.repeat(np.arange(len(runs)), runs)
        k = self._k0[run] + (np.arange(self._n) - self._starts[run])
        counted = self._k0[run] >= 0
        return plen[run] + np.where(counted, 2 + _digits(np.where(counted, k, 0)), 0)

    @property
    def is_runs(self) -> bool:
        return self._plain is None

    @property
    def nbytes(self) -> int:
        if self._plain is not None:
            return self._plain.nbytes
        return self._starts.nbytes + self._k0.nbytes + self._prefixes.nbytes

    # ------------------------------------------------------------------ sequence
    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i) -> str:
        if self._plain is not None:
            return self._plain[i]
        i = int(i)
        if i < 0:
            i += self._n
        if not 0 <= i < self._n:
            raise IndexError(f"string {i} of {self._n}")
        r = int(np.searchsorted(self._starts, i, side="right")) - 1
        p, k0 = self._prefixes[r], int(self._k0[r])
        return p if k0 < 0 else f"{p}[{k0 + i - int(self._starts[r])}]"

    def __iter__(self) -> Iterator[str]:
        if self._plain is not None:
            yield from self._plain
            return
        for p, k0, length in zip(self._prefixes, self._k0.tolist(),
                                 self._lengths_of_runs().tolist(), strict=True):
            if k0 < 0:
                yield p
            else:
                for k in range(k0, k0 + length):
                    yield f"{p}[{k}]"

    def __eq__(self, other) -> bool:
        if isinstance(other, (NameColumn, StringColumn, list, tuple)):
            return len(other) == len(self) and all(a == b for a, b in zip(self, other,
                                                                          strict=True))
        return NotImplemented

    __hash__ = None

    def positions(self, wanted: Iterable[str]) -> dict[str, int]:
        """The first index of each string of ``wanted`` that is in the column (by the runs:
        no name is built)."""
        if self._plain is not None:
            return self._plain.positions(wanted)
        want = set(wanted)
        by_prefix: dict[str, list[int]] = {}
        for r, p in enumerate(self._prefixes):
            by_prefix.setdefault(p, []).append(r)
        runs = self._lengths_of_runs()
        found: dict[str, int] = {}
        for w in want:
            hits = [int(self._starts[r]) for r in by_prefix.get(w, ()) if self._k0[r] < 0]
            p, k = _counted(w)
            if k >= 0:
                hits += [int(self._starts[r]) + k - int(self._k0[r])
                         for r in by_prefix.get(p, ())
                         if 0 <= self._k0[r] <= k < self._k0[r] + runs[r]]
            if hits:
                found[w] = min(hits)
        return found

    def lengths(self) -> np.ndarray:
        """Each string's length in UTF-8 bytes."""
        if self._plain is not None:
            return self._plain.lengths()
        return self._name_lengths()

    @property
    def max_bytes(self) -> int:
        """The longest string's length in UTF-8 bytes (0 for none): per run, its last name."""
        if self._plain is not None:
            return self._plain.max_bytes
        if not self._n:
            return 0
        last = self._k0 + self._lengths_of_runs() - 1
        counted = self._k0 >= 0
        return int((self._prefixes.lengths()
                    + np.where(counted, 2 + _digits(np.where(counted, last, 0)), 0)).max())
