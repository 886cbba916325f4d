"""A list of block specs spread over the ranks in gid order: each rank holds one contiguous
slice of it, the slices in rank order.

The rock mass's cuts, sliver joining, joins and excavations (pdem.model.rockmass) work on
such a list, each rank on the blocks of its slice, so that no rank holds every piece: a cut
piece is ~2.3 KB of geometry, every piece on every rank was ~3.5 GB a rank for 10^6 cut
blocks whatever the rank count. Before each joint set the slices are moved to even out that
set's work (:meth:`Spread.rebalance`); a piece that needs another rank's neighbour asks for
it (:meth:`Spread.fetch`). Concatenated in rank order the slices are the very list one
process builds, so gids, names and pieces do not depend on the rank count.

``comm`` None: this process holds the whole list (one rank of the same code).
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from ..mpi import LOCAL, allgather, allgather_rows, alltoall, weighted_share


class Spread:
    """This rank's slice ``local`` (gids ``start .. start + len(local) - 1``) of a list of
    ``total`` specs; ``starts[r]`` is rank r's first gid (``starts[-1] == total``)."""

    def __init__(self, comm, local: list):
        self.comm = LOCAL if comm is None else comm
        self.local = local
        counts = allgather(self.comm, len(local))
        self.starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.start = int(self.starts[self.comm.rank])
        self.total = int(self.starts[-1])

    @classmethod
    def from_whole(cls, comm, specs: list) -> Spread:
        """The spread of a list every rank holds whole: an even slice each."""
        comm = LOCAL if comm is None else comm
        n = len(specs)
        return cls(comm, list(specs[comm.rank * n // comm.size:(comm.rank + 1) * n // comm.size]))

    @classmethod
    def from_segments(cls, comm, segments) -> Spread:
        """The spread of a list made of segments in order, each ``(whole, specs)``: a list
        every rank holds whole (``whole``), or this rank's slice of one spread over the ranks
        in rank order; an even slice each (collective)."""
        comm = LOCAL if comm is None else comm
        if all(whole for whole, _ in segments):
            return cls.from_whole(comm, [s for _, part in segments for s in part])
        rank, size = comm.rank, comm.size
        held, offset = [], 0  # (first gid, specs) this rank sends on
        for whole, part in segments:
            if whole:  # an even slice of it is sent by each rank
                n = len(part)
                a = rank * n // size
                held.append((offset + a, part[a:(rank + 1) * n // size]))
                offset += n
            else:
                counts = allgather(comm, len(part))
                held.append((offset + sum(counts[:rank]), part))
                offset += sum(counts)
        send: list[list] = [[] for _ in range(size)]
        for r in range(size):
            a, b = r * offset // size, (r + 1) * offset // size
            for first, part in held:
                lo, hi = max(a, first), min(b, first + len(part))
                if lo < hi:
                    send[r].append((lo, part[lo - first:hi - first]))
        del held
        got = sorted((chunk for part in alltoall(comm, send) for chunk in part),
                     key=lambda chunk: chunk[0])
        return cls(comm, [s for _, part in got for s in part])

    def with_local(self, local: list) -> Spread:
        """The spread after each rank replaced its slice (collective)."""
        return Spread(self.comm, local)

    def owner_of(self, gids) -> np.ndarray:
        """The rank holding each of ``gids``."""
        return np.searchsorted(self.starts, np.asarray(gids, np.int64), side="right") - 1

    def gathered(self, values) -> np.ndarray:
        """A per-spec column of this slice, every rank's concatenated (gid order)."""
        return allgather_rows(self.comm, np.asarray(values))

    def counts(self, key) -> Counter:
        """How many specs of the whole list give each value of ``key(spec)``."""
        total: Counter = Counter()
        for part in allgather(self.comm, Counter(key(s) for s in self.local)):
            total.update(part)
        return total

    def counts_before(self, key) -> Counter:
        """How many specs of the ranks before this one give each value of ``key(spec)``."""
        parts = allgather(self.comm, Counter(key(s) for s in self.local))
        before: Counter = Counter()
        for part in parts[:self.comm.rank]:
            before.update(part)
        return before

    def move_to(self, ranges) -> Spread:
        """The same list with rank r holding gids ``ranges[r]`` (contiguous, in rank order,
        covering the list; collective): each rank sends the specs of its slice to the ranks
        whose new slice holds them."""
        comm = self.comm
        lo, hi = self.start, self.start + len(self.local)
        send = [self.local[max(a, lo) - lo:max(min(b, hi), lo) - lo] if a < hi and b > lo else []
                for a, b in ranges]
        self.local = []  # the slice is in the messages now
        got = alltoall(comm, send)
        del send
        return Spread(comm, [s for part in got for s in part])

    def rebalance(self, weights) -> Spread:
        """The same list with each rank holding a contiguous slice of about an even share of
        the total weight (``weights``: this slice's, one per spec; collective)."""
        w = self.gathered(np.asarray(weights, np.float64))
        size = self.comm.size
        return self.move_to([weighted_share(r, size, w) for r in range(size)])

    def fetch(self, gids) -> dict:
        """The specs ``gids`` (any rank's; collective: every rank calls, with its own),
        by gid."""
        comm = self.comm
        gids = np.unique(np.asarray(gids, np.int64))
        owners = self.owner_of(gids)
        asked = alltoall(comm, [gids[owners == r].tolist() for r in range(comm.size)])
        sent = alltoall(comm, [[self.local[g - self.start] for g in part] for part in asked])
        return {int(g): s for r in range(comm.size) for g, s in zip(gids[owners == r], sent[r],
                                                                   strict=True)}

    def whole(self) -> list:
        """Every spec, on every rank (collective)."""
        return [s for part in allgather(self.comm, self.local) for s in part]
