"""Every block's spec in gid order, with the family members a rank does not build kept as runs.

At set-up each rank builds the shapes of its share of the gids only (pdem.state.build_share);
the members of an ``array:`` or ``random:`` family outside it are known by their scene entry
and index alone (name ``entry[k]``, one convex piece, the entry's group and material). A
Python object for each of them was ~250 bytes of every scene block on every rank until the
spec table was built (bench/scale.py's ``spec_bytes``): 10 GB a rank at 4·10⁷ blocks. Here
they are a run ``(entry, first index, count)``; indexing and iteration still give a
:class:`pdem.model.build.BlockSpec` (made on the fly, without pieces), and the spec table
and the block store read the runs as such (:meth:`SpecList.parts`).
"""

from __future__ import annotations

import bisect
from collections.abc import Iterator, Sequence
from typing import NamedTuple


class UnbuiltRun(NamedTuple):
    """Members ``k0 .. k0 + count - 1`` of family entry ``block`` (index ``entry`` in
    ``scene.blocks``), outside this rank's share: each one convex piece, named
    ``block.name[k]``, its own parent."""

    block: object
    entry: int
    k0: int
    count: int

    def name(self, j: int) -> str:
        return f"{self.block.name}[{self.k0 + j}]"


class SpecList(Sequence):
    """A sequence of block specs in gid order: built specs, and runs of unbuilt family
    members (:class:`UnbuiltRun`)."""

    def __init__(self):
        self._parts: list = []  # lists of BlockSpec, and UnbuiltRun
        self._starts: list[int] = [0]  # gid of each part's first block, then the total

    def append(self, spec) -> None:
        if not self._parts or isinstance(self._parts[-1], UnbuiltRun):
            self._parts.append([])
            self._starts.append(self._starts[-1])
        self._parts[-1].append(spec)
        self._starts[-1] += 1

    def extend(self, specs) -> None:
        for s in specs:
            self.append(s)

    def append_unbuilt(self, block, entry: int, k0: int, count: int) -> None:
        """Members ``k0 .. k0 + count - 1`` of ``block``, not built here."""
        if count <= 0:
            return
        last = self._parts[-1] if self._parts else None
        if isinstance(last, UnbuiltRun) and last.entry == entry and last.k0 + last.count == k0:
            self._parts[-1] = last._replace(count=last.count + count)
        else:
            self._parts.append(UnbuiltRun(block, entry, k0, count))
            self._starts.append(self._starts[-1])
        self._starts[-1] += count

    def parts(self) -> Iterator[tuple[int, object]]:
        """``(first gid, part)``: a list of built specs or an :class:`UnbuiltRun`."""
        return zip(self._starts[:-1], self._parts, strict=True)

    def n_pieces_before(self, gid: int) -> int:
        """The convex pieces of the blocks before ``gid`` (an unbuilt member has one)."""
        total = 0
        for start, part in self.parts():
            if start >= gid:
                break
            take = min(gid - start, len(part) if isinstance(part, list) else part.count)
            total += sum(s.n_pieces for s in part[:take]) if isinstance(part, list) else take
        return total

    def groups(self) -> set[str]:
        """The group names of every block."""
        out: set[str] = set()
        for _, part in self.parts():
            if isinstance(part, list):
                out.update(s.group for s in part)
            else:
                out.add(part.block.group)
        return out

    def __len__(self) -> int:
        return self._starts[-1]

    def _spec(self, gid: int):
        p = bisect.bisect_right(self._starts, gid) - 1
        part = self._parts[p]
        j = gid - self._starts[p]
        if isinstance(part, list):
            return part[j]
        from .build import unbuilt_spec

        return unbuilt_spec(part.block, part.entry, part.k0 + j)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self._spec(g) for g in range(*i.indices(len(self)))]
        g = int(i)
        if g < 0:
            g += len(self)
        if not 0 <= g < len(self):
            raise IndexError(f"block {int(i)} of {len(self)}")
        return self._spec(g)

    def __iter__(self):
        from .build import unbuilt_spec

        for _, part in self.parts():
            if isinstance(part, list):
                yield from part
            else:
                for j in range(part.count):
                    yield unbuilt_spec(part.block, part.entry, part.k0 + j)


def spec_parts(specs: Sequence) -> Iterator[tuple[int, object]]:
    """``(first gid, part)`` of any sequence of specs: a :class:`SpecList`'s parts, or the
    whole list as one built part."""
    if isinstance(specs, SpecList):
        return specs.parts()
    return iter([(0, specs)])
