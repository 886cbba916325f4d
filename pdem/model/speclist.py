"""Every block's spec in gid order, with the family members a rank does not build kept as runs.

At set-up each rank builds the shapes of its share of the gids only (pdem.state.build_share);
the members of an ``array:`` or ``random:`` family outside it are known by their scene entry
and index alone (name ``entry[k]``, one convex piece, the entry's group and material). A
Python object for each of them was ~250 bytes of every scene block on every rank until the
spec table was built (bench/scale.py's ``spec_bytes``): 10 GB a rank at 4·10⁷ blocks. Here
they are a run ``(entry, first index, count)``; indexing and iteration still give a
:class:`pdem.model.spec.BlockSpec` (made on the fly, without pieces), and the spec table
and the block store read the runs as such (:meth:`SpecList.parts`).
"""

from __future__ import annotations

import bisect
from collections.abc import Iterator, Sequence
from typing import NamedTuple

import numpy as np

from .names import NameColumn
from .spec import BlockSpec, unbuilt_spec


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


class RemoteRun(NamedTuple):
    """Blocks another rank built, of a scene whose cuts, joins, excavations or meshes make
    its blocks (spread over the ranks, pdem.model.spread): their names and scalars as
    columns (:func:`spec_summary`), no pieces. ``parent``, ``group``, ``material``: indices
    into ``parents`` (-1: the block's own name), ``groups`` and ``materials`` (each in
    order of first use); ``excavate_at`` NaN and ``excavate_stage`` -1 for none."""

    count: int
    names: object  # pdem.model.names.NameColumn
    parents: list
    parent: np.ndarray
    groups: list
    group: np.ndarray
    materials: list
    material: np.ndarray
    entry: np.ndarray
    n_pieces: np.ndarray
    excavate_at: np.ndarray
    excavate_stage: np.ndarray
    blocks: list  # the scene's ``blocks:`` entries (not sent: each rank's own)

    def spec(self, j: int):
        """Block ``j`` of the run as a released :class:`pdem.model.spec.BlockSpec`."""
        entry = int(self.entry[j])
        name = self.names[j]
        k = int(self.parent[j])
        t = float(self.excavate_at[j])
        stage = int(self.excavate_stage[j])
        spec = BlockSpec(name, entry, None, self.blocks[entry],
                         parent=name if k < 0 else self.parents[k],
                         excavate_at=None if np.isnan(t) else t,
                         excavate_stage=None if stage < 0 else stage,
                         group_name=self.groups[self.group[j]],
                         material_name=self.materials[self.material[j]])
        spec._n_pieces = int(self.n_pieces[j])
        return spec


def _indexed(values) -> tuple[list, np.ndarray]:
    """The distinct ``values`` in order of first appearance, and each value's index."""
    table: dict = {}
    index = np.fromiter((table.setdefault(v, len(table)) for v in values), np.int32)
    return list(table), index


def spec_summary(specs: list) -> dict:
    """The fields of a :class:`RemoteRun` (but ``blocks``) of built ``specs``: what the other
    ranks keep of them (~30 bytes a block and the names' runs, pdem.model.names)."""
    parents, parent = _indexed(s.parent for s in specs if s.parent != s.name)
    own = np.array([s.parent == s.name for s in specs], bool)
    full = np.full(len(specs), -1, np.int32)
    full[~own] = parent
    groups, group = _indexed(s.group for s in specs)
    materials, material = _indexed(s.material for s in specs)
    return dict(
        count=len(specs), names=NameColumn(s.name for s in specs), parents=parents,
        parent=full, groups=groups, group=group, materials=materials, material=material,
        entry=np.fromiter((s.entry for s in specs), np.int32, len(specs)),
        n_pieces=np.fromiter((len(s.pieces) for s in specs), np.int32, len(specs)),
        excavate_at=np.fromiter((np.nan if s.excavate_at is None else s.excavate_at
                                 for s in specs), float, len(specs)),
        excavate_stage=np.fromiter((-1 if s.excavate_stage is None else s.excavate_stage
                                    for s in specs), np.int32, len(specs)))


class SpecList(Sequence):
    """A sequence of block specs in gid order: built specs, and runs of unbuilt family
    members (:class:`UnbuiltRun`)."""

    def __init__(self):
        self._parts: list = []  # lists of BlockSpec, and UnbuiltRun
        self._starts: list[int] = [0]  # gid of each part's first block, then the total

    def append(self, spec) -> None:
        if not self._parts or not isinstance(self._parts[-1], list):
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

    @classmethod
    def spread(cls, local: list, start: int, total: int, summaries: list, rank: int,
               blocks: list) -> SpecList:
        """The list of a rank holding the built specs ``local`` (gids ``start ..``) of
        ``total``, the other ranks' blocks as runs of their ``summaries`` (one per rank, in
        rank order: :func:`spec_summary`)."""
        out = cls()
        mine = -1
        for r, summary in enumerate(summaries):
            if r == rank:
                mine = len(out)
                out.extend(local)
            elif summary["count"]:
                out._parts.append(RemoteRun(**summary, blocks=blocks))
                out._starts.append(out._starts[-1] + summary["count"])
        if len(out) != total or mine != start:
            raise RuntimeError(f"SpecList.spread: {len(out)} blocks of {total}, this rank's "
                               f"from {mine}, not {start}")
        return out

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
            if isinstance(part, list):
                total += sum(s.n_pieces for s in part[:take])
            elif isinstance(part, RemoteRun):
                total += int(part.n_pieces[:take].sum(dtype=np.int64))
            else:
                total += take
        return total

    def groups(self) -> set[str]:
        """The group names of every block."""
        out: set[str] = set()
        for _, part in self.parts():
            if isinstance(part, list):
                out.update(s.group for s in part)
            elif isinstance(part, RemoteRun):
                out.update(part.groups)
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
        if isinstance(part, RemoteRun):
            return part.spec(j)
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
        for _, part in self.parts():
            if isinstance(part, list):
                yield from part
            elif isinstance(part, RemoteRun):
                yield from (part.spec(j) for j in range(part.count))
            else:
                for j in range(part.count):
                    yield unbuilt_spec(part.block, part.entry, part.k0 + j)


def spec_parts(specs: Sequence) -> Iterator[tuple[int, object]]:
    """``(first gid, part)`` of any sequence of specs: a :class:`SpecList`'s parts, or the
    whole list as one built part."""
    if isinstance(specs, SpecList):
        return specs.parts()
    return iter([(0, specs)])
