"""Cell space: neighbour search by mapping block envelopes into rectangular cells.

Each block's envelope (axis-aligned box) enlarged by CTOL is mapped into the cells it covers;
candidate neighbours are the blocks sharing a cell (3DEC "Cell Mapping and Searching"). The cost
per searched block depends on its size, not on the number of blocks, so a full search is linear
in N when the cell volume follows the mean block volume. Blocks are re-searched only when their
accumulated motion u_acc (eq. 1) passes the trigger (see ``solver``), so resting blocks cost
nothing. A block leaving the cell space grows it by 10% (at least enough to hold the block) and
forces a complete remap.
"""

from __future__ import annotations

import numpy as np

from ..jit import kernel


class CellSpace:
    """The grid: ``origin``, ``size`` (cell edge per axis) and ``dims`` (cells per axis)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, cell_size: float):
        self.fit(lo.min(axis=0), hi.max(axis=0), cell_size)

    def fit(self, lo, hi, cell_size):
        span = np.maximum(hi - lo, cell_size)
        self.dims = np.maximum(np.floor(span / cell_size).astype(np.int64), 1)
        # keep the cell count bounded (a huge floor must not create millions of empty cells)
        while np.prod(self.dims) > 8_000_000:
            self.dims = np.maximum(self.dims // 2, 1)
        self.origin = lo.astype(np.float64).copy()
        self.size = span / self.dims
        self.hi = self.origin + self.size * self.dims
        self.cell_size = cell_size

    def grow_to(self, lo: np.ndarray, hi: np.ndarray) -> bool:
        """Grow by 10% in each dimension the envelopes leave; True when the space changed."""
        glo = lo.min(axis=0)
        ghi = hi.max(axis=0)
        if np.all(glo >= self.origin) and np.all(ghi <= self.hi):
            return False
        new_lo = self.origin.copy()
        new_hi = self.hi.copy()
        for k in range(3):
            ext = 0.1 * (self.hi[k] - self.origin[k])
            if glo[k] < new_lo[k]:
                new_lo[k] = min(glo[k], new_lo[k] - ext)
            if ghi[k] > new_hi[k]:
                new_hi[k] = max(ghi[k], new_hi[k] + ext)
        self.fit(new_lo, new_hi, self.cell_size)
        return True

    def candidates(self, lo, hi, active):
        """Pairs (i, j), i < j, whose padded envelopes overlap and one of which is active."""
        return candidate_pairs(lo, hi, active, self.origin, self.size, self.dims)


@kernel
def _cell_ranges(lo, hi, origin, size, dims):
    """(n, 6) cell index ranges (first i, j, k, last i, j, k) of every envelope."""
    n = lo.shape[0]
    r = np.empty((n, 6), np.int64)
    for b in range(n):
        for k in range(3):
            a = int(np.floor((lo[b, k] - origin[k]) / size[k]))
            z = int(np.floor((hi[b, k] - origin[k]) / size[k]))
            r[b, k] = min(max(a, 0), dims[k] - 1)
            r[b, 3 + k] = min(max(z, 0), dims[k] - 1)
    return r


@kernel
def candidate_pairs(lo, hi, active, origin, size, dims):
    """Map every block into the cells (CSR by counting sort), then search from active blocks."""
    n = lo.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    d1 = dims[1]
    d2 = dims[2]
    rng = _cell_ranges(lo, hi, origin, size, dims)
    count = np.zeros(ncell + 1, np.int64)
    for b in range(n):
        for i in range(rng[b, 0], rng[b, 3] + 1):
            for j in range(rng[b, 1], rng[b, 4] + 1):
                for k in range(rng[b, 2], rng[b, 5] + 1):
                    count[(i * d1 + j) * d2 + k + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    fill = count[:-1].copy()
    members = np.empty(count[ncell], np.int64)
    for b in range(n):
        for i in range(rng[b, 0], rng[b, 3] + 1):
            for j in range(rng[b, 1], rng[b, 4] + 1):
                for k in range(rng[b, 2], rng[b, 5] + 1):
                    c = (i * d1 + j) * d2 + k
                    members[fill[c]] = b
                    fill[c] += 1
    cap = 16 * n + 16
    pi = np.empty(cap, np.int64)
    pj = np.empty(cap, np.int64)
    m = 0
    seen = np.full(n, -1, np.int64)
    for b in range(n):
        if not active[b]:
            continue
        lb0, lb1, lb2 = lo[b, 0], lo[b, 1], lo[b, 2]
        hb0, hb1, hb2 = hi[b, 0], hi[b, 1], hi[b, 2]
        for i in range(rng[b, 0], rng[b, 3] + 1):
            for j in range(rng[b, 1], rng[b, 4] + 1):
                for k in range(rng[b, 2], rng[b, 5] + 1):
                    c = (i * d1 + j) * d2 + k
                    for t in range(count[c], count[c + 1]):
                        o = members[t]
                        if o == b or seen[o] == b:
                            continue
                        seen[o] = b
                        # an active pair is found from both sides: keep it once
                        if active[o] and o < b:
                            continue
                        if (lb0 > hi[o, 0] or lo[o, 0] > hb0 or lb1 > hi[o, 1]
                                or lo[o, 1] > hb1 or lb2 > hi[o, 2] or lo[o, 2] > hb2):
                            continue
                        if m == cap:
                            cap *= 2
                            pi2 = np.empty(cap, np.int64)
                            pj2 = np.empty(cap, np.int64)
                            pi2[:m] = pi[:m]
                            pj2[:m] = pj[:m]
                            pi = pi2
                            pj = pj2
                        pi[m] = min(b, o)
                        pj[m] = max(b, o)
                        m += 1
    return pi[:m], pj[:m]
