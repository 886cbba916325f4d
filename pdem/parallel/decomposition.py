"""Domain decomposition: which rank owns which region of space (``parallel.balance``).

A block is owned by the rank whose region holds its centroid; every point of space has exactly
one owner (blocks that fly outside the model's box keep one). Two decompositions:

- ``uniform`` (:class:`Decomposition`): a 3D Cartesian grid of ranks, each owning a brick; the
  bricks split the bounding box of the model at start uniformly along each axis, fixed for the
  run.
- ``rcb`` (:class:`RCBDecomposition`): recursive coordinate bisection weighted by work (a block
  weighs 1 + the contacts it is in), recomputed at a rebuild point when the owned work is
  imbalanced beyond ``parallel.rebalance``.

Which rank owns a block never changes the results (docs/architecture.md, Determinism): the
decomposition is a matter of speed only.
"""

from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger("pdem")


def choose_dims(size: int, extent: np.ndarray, gravity: np.ndarray) -> list[int]:
    """MPI's balanced factorisation of ``size``, the largest factor on the longest axis.

    The axis most aligned with gravity is ranked last: settling blocks collect at the bottom,
    and a cut across gravity would leave the upper ranks empty."""
    from mpi4py import MPI

    factors = sorted(MPI.Compute_dims(size, [0, 0, 0]), reverse=True)
    score = np.asarray(extent, float).copy()
    g = np.abs(np.asarray(gravity, float))
    if g.max() > 0:
        score[int(np.argmax(g))] = -1.0
    order = np.argsort(-score, kind="stable")
    dims = [1, 1, 1]
    for axis, f in zip(order, factors, strict=True):
        dims[int(axis)] = int(f)
    return dims


class Decomposition:
    """Ranks on a ``dims`` grid over ``[lo, hi]``; ``owner_of`` maps points to ranks."""

    balance = "uniform"
    imbalance = None  # rcb only: the work imbalance measured at the last rebuild point

    def __init__(self, comm, lo: np.ndarray, hi: np.ndarray, dims: list[int]):
        self.comm = comm
        self.size = comm.size
        self.rank = comm.rank
        self.dims = np.array(dims, np.int64)
        if int(np.prod(self.dims)) != comm.size:
            raise ValueError(f"parallel.dims {dims} do not multiply to {comm.size} ranks")
        # the Cartesian topology is MPI's (row-major rank order, as computed in owner_of)
        self.cart = comm.Create_cart(list(map(int, self.dims)), periods=[False] * 3, reorder=False)
        lo = np.asarray(lo, float)
        hi = np.asarray(hi, float)
        self.edges = [np.linspace(lo[k], hi[k], self.dims[k] + 1) for k in range(3)]

    def owner_of(self, points: np.ndarray) -> np.ndarray:
        points = np.atleast_2d(points)
        idx = np.empty((len(points), 3), np.int64)
        for k in range(3):
            idx[:, k] = np.searchsorted(self.edges[k][1:-1], points[:, k], side="right")
        return (idx[:, 0] * self.dims[1] + idx[:, 1]) * self.dims[2] + idx[:, 2]

    def ranks_near(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The ranks whose cell (brick; the outer ones unbounded: they own what lies beyond
        the box) meets the box ``[lo, hi]``, ascending; O(those ranks), no array of size P."""
        rng = [np.arange(np.searchsorted(self.edges[k][1:-1], lo[k], side="right"),
                         np.searchsorted(self.edges[k][1:-1], hi[k], side="right") + 1)
               for k in range(3)]
        i, j, k = np.meshgrid(*rng, indexing="ij")
        return np.sort(((i * self.dims[1] + j) * self.dims[2] + k).ravel())

    def brick(self, rank: int) -> tuple[np.ndarray, np.ndarray]:
        c = self.cart.Get_coords(rank)
        lo = np.array([self.edges[k][c[k]] for k in range(3)])
        hi = np.array([self.edges[k][c[k] + 1] for k in range(3)])
        return lo, hi

    def describe(self) -> str:
        return f"a {'x'.join(map(str, self.dims))} grid"

    def rebalance(self, blocks, n_owned: int, contacts, zones=None) -> bool:
        """The grid is fixed: never moves (no collective)."""
        return False

    def free(self):
        self.cart.Free()


# ---------------------------------------------------------------------------------------------
# weighted decomposition: recursive coordinate bisection (parallel.balance: rcb)

HIST_BINS = 256  # bins of one histogram pass of the weighted-quantile search
HIST_PASSES = 3  # passes: a cut lands within extent / 256^3 of the exact weighted quantile


def balance_of(parallel) -> str:
    """The decomposition a scene's ``parallel`` section asks for: ``balance: auto`` is ``rcb``
    unless ``dims`` names a rank grid (then ``uniform``)."""
    if parallel.balance != "auto":
        return parallel.balance
    return "rcb" if parallel.dims == "auto" else "uniform"


# zones per unit of work: a zone-step costs ~70 ns, a rigid block-step with its contacts ~1 us
# (docs/deformable.md, Speed), so a zoned block of Z zones weighs Z / 14 more than a rigid one
ZONES_PER_WORK = 14


def zone_work(zones: np.ndarray) -> np.ndarray:
    """The work of zoned blocks' grids (their zone counts) in RCB's units: integers, so the
    weights' sums stay exact in any order."""
    return np.asarray(zones, np.int64) // ZONES_PER_WORK


def block_work(blocks, n_owned: int, contacts, zones: np.ndarray | None = None) -> np.ndarray:
    """The work weight of each owned block: 1 + the contacts it is in if it is free, 1 if it is
    fixed, 0 if it was deleted (a rank holds every contact of the free blocks it owns, so the
    weight does not depend on the decomposition; a fixed block's contacts are computed by the
    owners of the free blocks it touches); ``zones`` (per held row, owned first, 0 for a
    rigid block; or per owned row): a zoned block's grid adds :func:`zone_work`, and a contact
    with a zoned block adds its gridpoint sub-contacts the same way (a sub-contact's force
    costs about a zone's step: docs/deformable.md, Speed), which rigid contacts, a few
    sub-contacts each, do not."""
    w = (blocks.out[:n_owned] != 2).astype(np.int64)  # 2: deleted (pdem.domain.DELETED)
    if zones is not None:
        w += np.where(w > 0, zone_work(zones[:n_owned]), 0)
    if contacts.n and n_owned:
        free = blocks.fixed[:n_owned] == 0
        each = np.ones(contacts.n, np.int64)
        if zones is not None and len(zones) > n_owned:
            ia = np.asarray(contacts.arrays["ia"], np.int64)
            ib = np.asarray(contacts.arrays["ib"], np.int64)
            zoned = (zones[ia] > 0) | (zones[ib] > 0)
            each += np.where(zoned, zone_work(np.diff(contacts.sc_start)), 0)
        for side in ("ia", "ib"):
            rows = np.asarray(contacts.arrays[side], np.int64)
            mine = (rows < n_owned)
            mine[mine] = free[rows[mine]]
            w += np.bincount(rows[mine], weights=each[mine], minlength=n_owned).astype(np.int64)
    return w


class CutTree:
    """A binary tree of axis-aligned cuts; leaf ``k`` of ``parts`` is rank ``k``. Node ``i``
    splits at ``cut[i]`` along ``axis[i]``: points with ``x[axis] < cut`` go to ``left[i]``,
    the others to ``right[i]``; ``rank[i]`` is the rank of a leaf, -1 for a split. Every point
    of space (outside the model's box, on a cut) has exactly one owner."""

    def __init__(self, axis, cut, left, right, rank, lo, hi, leaf_work):
        self.axis = np.asarray(axis, np.int64)
        self.cut = np.asarray(cut, float)
        self.left = np.asarray(left, np.int64)
        self.right = np.asarray(right, np.int64)
        self.rank = np.asarray(rank, np.int64)
        self.lo = np.asarray(lo, float)  # the region of each node (the root: the model's box)
        self.hi = np.asarray(hi, float)
        self.leaf_work = np.asarray(leaf_work, np.int64)  # the weight each rank got, by rank
        self.depth = _depth(self.left, self.right, self.rank)

    def owner_of(self, points: np.ndarray) -> np.ndarray:
        points = np.atleast_2d(np.asarray(points, float))
        node = np.zeros(len(points), np.int64)
        rows = np.arange(len(points))
        for _ in range(self.depth):
            inner = self.rank[node] < 0
            if not inner.any():
                break
            nd = node[inner]
            right = points[rows[inner], self.axis[nd]] >= self.cut[nd]
            node[inner] = np.where(right, self.right[nd], self.left[nd])
        return self.rank[node]

    def ranks_near(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The ranks whose cell (the leaf's region, unbounded where the model's box bounds it:
        :meth:`owner_of` follows the cuts only) meets the box ``[lo, hi]``, ascending: the
        tree walked down the sides the box reaches, O(those ranks x depth)."""
        out, todo = [], [0]
        while todo:
            i = todo.pop()
            if self.rank[i] >= 0:
                out.append(int(self.rank[i]))
                continue
            a, c = self.axis[i], self.cut[i]
            if lo[a] < c:
                todo.append(int(self.left[i]))
            if hi[a] >= c:
                todo.append(int(self.right[i]))
        return np.array(sorted(out), np.int64)

    def region(self, rank: int) -> tuple[np.ndarray, np.ndarray]:
        i = int(np.nonzero(self.rank == rank)[0][0])
        return self.lo[i].copy(), self.hi[i].copy()


def _depth(left, right, rank) -> int:
    depth, level = 0, [0]
    while True:
        level = [c for i in level if rank[i] < 0 for c in (left[i], right[i])]
        if not level:
            return depth
        depth += 1


def _mpi_op(name: str):
    from mpi4py import MPI

    return getattr(MPI, name)


def _allreduce(comm, a: np.ndarray, op) -> np.ndarray:
    out = np.empty_like(a)
    comm.Allreduce(np.ascontiguousarray(a), out, op=op)
    return out


class _Nodes:
    """The cut tree as :func:`rcb_tree` grows it, in the lists :class:`CutTree` takes: each
    node's cut (``axis`` -1 and ``cut`` 0 until it is split), children and leaf rank (-1: a
    split), the ranks ``r0 .. r1-1`` under it and its region ``rlo .. rhi``; ``work``: the
    weight each leaf's rank got."""

    def __init__(self, parts: int, lo, hi):
        self.axis, self.cut, self.left, self.right, self.rank = [-1], [0.0], [-1], [-1], [-1]
        self.r0, self.r1 = [0], [parts]
        self.rlo, self.rhi = [np.asarray(lo, float)], [np.asarray(hi, float)]
        self.work = np.zeros(parts, np.int64)

    def add(self, r0: int, r1: int, lo: np.ndarray, hi: np.ndarray) -> int:
        """A new node for ranks ``r0 .. r1-1`` (a leaf if one) over ``lo .. hi``: its index."""
        self.axis.append(-1)
        self.cut.append(0.0)
        self.left.append(-1)
        self.right.append(-1)
        self.r0.append(r0)
        self.r1.append(r1)
        self.rlo.append(lo)
        self.rhi.append(hi)
        self.rank.append(r0 if r1 - r0 == 1 else -1)
        return len(self.axis) - 1

    def tree(self) -> CutTree:
        return CutTree(self.axis, self.cut, self.left, self.right, self.rank,
                       np.array(self.rlo), np.array(self.rhi), self.work)


def rcb_tree(comm, x: np.ndarray, w: np.ndarray, parts: int, lo, hi) -> CutTree:
    """The RCB of the points ``x`` (this rank's share; each point on one rank) with integer
    weights ``w`` into ``parts`` regions (collective over ``comm``; ``parts`` need not be
    ``comm.size``).

    The set of ranks of a node, ``p`` of them, splits into the first ``p // 2`` and the rest,
    across the longest extent of the box around the node's points, at the weighted quantile
    ``p // 2 / p``, found by histogram refinement: each pass sums per-rank histograms of the
    node's points in ``HIST_BINS`` bins (integer weights: exact sums, in any order) and
    zooms into the bin holding the quantile; the cut is the bin edge nearer to it. The result
    depends only on the set of points and weights (not on which rank holds which, nor on an
    earlier decomposition) and is the same on every rank. A node holding no point is cut in
    the middle of its region (the root's region: ``[lo, hi]``). Work per rank:
    O(own points x levels x passes); messages: a few arrays of ``HIST_BINS`` per node."""
    from mpi4py import MPI

    x = np.asarray(x, float).reshape(-1, 3)
    w = np.asarray(w, np.int64).reshape(-1)
    t = _Nodes(parts, lo, hi)
    node = np.zeros(len(x), np.int64)
    active = [0] if parts > 1 else []
    if parts == 1:
        t.rank[0] = 0
        t.work[0] = _allreduce(comm, np.array([w.sum()], np.int64), MPI.SUM)[0]
    while active:  # one level of the tree a pass
        groups = _level_groups(node, active, len(t.axis))
        has, ax, a, b = _windows(comm, x, groups, active, t.rlo, t.rhi)
        coord = [x[g, ax[j]] for j, g in enumerate(groups)]
        pl = np.array([(t.r1[i] - t.r0[i]) // 2 for i in active], np.int64)
        p = np.array([t.r1[i] - t.r0[i] for i in active], np.int64)
        cuts, left_w, total = _quantile_cuts(comm, groups, coord, w, a, b, p, pl, has)
        active = _split_level(t, active, groups, coord, node, ax, cuts, pl, left_w, total)
    return t.tree()


def _level_groups(node: np.ndarray, active: list[int], n_nodes: int) -> list[np.ndarray]:
    """This rank's points (``node``: the node each is in) of each node of ``active``."""
    k = len(active)
    slot = np.full(n_nodes, -1, np.int64)
    slot[active] = np.arange(k)
    j_of = slot[node]
    mine = np.nonzero(j_of >= 0)[0]
    mine = mine[np.argsort(j_of[mine], kind="stable")]
    bounds = np.searchsorted(j_of[mine], np.arange(k + 1))
    return [mine[bounds[j]:bounds[j + 1]] for j in range(k)]


def _windows(comm, x: np.ndarray, groups, active: list[int], rlo, rhi):
    """Each node's cut axis and first window ``[a, b)`` (collective): the longest extent of
    the box around its points (over the ranks) and that box along it; for a node holding no
    point (``has`` False), its region's longest extent and the region's middle."""
    from mpi4py import MPI

    k = len(active)
    # the box around each node's points
    box = np.full((k, 6), np.inf)
    for j, g in enumerate(groups):
        if len(g):
            box[j, :3] = x[g].min(0)
            box[j, 3:] = -x[g].max(0)
    box = _allreduce(comm, box, MPI.MIN)
    bmin, bmax = box[:, :3], -box[:, 3:]
    has = np.isfinite(bmin[:, 0])
    ax = np.empty(k, np.int64)
    a = np.empty(k)
    b = np.empty(k)
    for j, i in enumerate(active):
        ext = bmax[j] - bmin[j] if has[j] else rhi[i] - rlo[i]
        ax[j] = int(np.argmax(ext))  # the first of equal extents: x, y, z
        if has[j]:
            a[j] = bmin[j, ax[j]]
            b[j] = np.nextafter(bmax[j, ax[j]], np.inf)  # every point below b
        else:
            a[j] = b[j] = 0.5 * (rlo[i][ax[j]] + rhi[i][ax[j]])
    return has, ax, a, b


def _quantile_cuts(comm, groups, coord, w: np.ndarray, a: np.ndarray, b: np.ndarray,
                   p: np.ndarray, pl: np.ndarray, has: np.ndarray):
    """Each node's cut at the weighted quantile ``pl / p`` of its points' ``coord`` in the
    window ``[a, b)``, by ``HIST_PASSES`` passes of histogram refinement (collective), the
    weight left of it and the node's total weight. A node holding no point is cut at ``a``."""
    from mpi4py import MPI

    k = len(groups)
    below = np.zeros(k, np.int64)  # weight left of the window [a, b)
    total = None
    inside = np.zeros(k, np.int64)
    for _ in range(HIST_PASSES):
        edges = np.linspace(a, b, HIST_BINS + 1, axis=1)
        hist = np.zeros((k, HIST_BINS), np.int64)
        for j, g in enumerate(groups):
            c = coord[j]
            sel = (c >= a[j]) & (c < b[j])
            if sel.any():
                bins = np.searchsorted(edges[j], c[sel], side="right") - 1
                hist[j] = np.bincount(bins, w[g][sel], HIST_BINS).astype(np.int64)
        hist = _allreduce(comm, hist, MPI.SUM)
        if total is None:
            total = hist.sum(1)
        cum = below[:, None] + np.cumsum(hist, axis=1)
        # the first bin whose upper edge has at least the share p_left / p to its left
        reach = cum * p[:, None] >= total[:, None] * pl[:, None]
        jb = np.where(reach.any(1), np.argmax(reach, axis=1), HIST_BINS - 1)
        rows = np.arange(k)
        inside = hist[rows, jb]
        below = cum[rows, jb] - inside
        a, b = edges[rows, jb], edges[rows, jb + 1]
    # the window's edge nearer the quantile (the lower one on a tie)
    err_a = np.abs(below * p - total * pl)
    err_b = np.abs((below + inside) * p - total * pl)
    take_b = err_b < err_a
    cuts = np.where(take_b, b, a)
    left_w = np.where(take_b, below + inside, below)
    for j in range(k):
        if not has[j]:
            cuts[j] = a[j]
    return cuts, left_w, total


def _split_level(t: _Nodes, active: list[int], groups, coord, node: np.ndarray, ax, cuts,
                 pl, left_w, total) -> list[int]:
    """Split each node of ``active`` at ``cuts`` along ``ax`` into two children (its first
    ``pl`` ranks left, with the weight ``left_w``; the rest right) and move its points
    (``node``) into them; returns the children still to split (more than one rank)."""
    nxt = []
    for j, i in enumerate(active):
        t.axis[i], t.cut[i] = int(ax[j]), float(cuts[j])
        mid = t.r0[i] + int(pl[j])
        for lo_r, hi_r, wt, side in ((t.r0[i], mid, left_w[j], "left"),
                                     (mid, t.r1[i], total[j] - left_w[j], "right")):
            c_lo, c_hi = t.rlo[i].copy(), t.rhi[i].copy()
            (c_hi if side == "left" else c_lo)[ax[j]] = cuts[j]  # the cut bounds the child
            child = t.add(lo_r, hi_r, c_lo, c_hi)
            (t.left if side == "left" else t.right)[i] = child
            if hi_r - lo_r == 1:
                t.work[lo_r] = wt
            else:
                nxt.append(child)
        g = groups[j]
        go = coord[j] >= cuts[j]
        node[g] = np.where(go, t.right[i], t.left[i])
    return nxt


class RCBDecomposition:
    """Ranks on the leaves of an RCB cut tree (:func:`rcb_tree`) of the blocks' centroids,
    weighted by work; ``threshold``: the work imbalance (max / mean of the ranks' owned work)
    above which :meth:`rebalance` recomputes the cuts (None: the cuts of the start are kept).
    Construction is collective: the start's cuts, every block weighing 1 or ``weights`` (``x``:
    this rank's share of the start's centroids, ``weights`` theirs: a zoned block's grid)."""

    balance = "rcb"
    dims = None  # no rank grid

    def __init__(self, comm, lo: np.ndarray, hi: np.ndarray, x: np.ndarray,
                 threshold: float | None, weights: np.ndarray | None = None):
        self.comm = comm
        self.size = comm.size
        self.rank = comm.rank
        self.lo = np.asarray(lo, float)
        self.hi = np.asarray(hi, float)
        self.threshold = threshold
        self.imbalance = None
        self.n_balanced = 0  # cut trees computed after the start's
        w = np.ones(len(x), np.int64) if weights is None else np.asarray(weights, np.int64)
        self.tree = rcb_tree(comm, x, w, self.size, self.lo, self.hi)

    def owner_of(self, points: np.ndarray) -> np.ndarray:
        return self.tree.owner_of(points)

    def ranks_near(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        return self.tree.ranks_near(lo, hi)

    def brick(self, rank: int) -> tuple[np.ndarray, np.ndarray]:
        """The region of ``rank`` (the outer ones bounded by the model's box at start; blocks
        beyond it belong to the nearest region)."""
        return self.tree.region(rank)

    def describe(self) -> str:
        return "recursive coordinate bisection (parallel.balance: rcb)"

    def rebalance(self, blocks, n_owned: int, contacts, zones=None) -> bool:
        """At a rebuild point (collective, before the migration): if the owned work is more
        imbalanced than the threshold, recompute the cuts from the owned blocks' centroids
        and weights (:func:`block_work`); True if they were (the caller then migrates)."""
        if self.threshold is None or self.size == 1:
            return False
        w = block_work(blocks, n_owned, contacts, zones)
        # the largest and the total owned work: two reductions of one integer (not an
        # allgather of every rank's, O(P) on every rank); integer sums are exact, so the
        # mean is the same double as the mean of the gathered works
        mine = int(w.sum())
        most = self.comm.allreduce(mine, op=_mpi_op("MAX"))
        mean = float(self.comm.allreduce(mine, op=_mpi_op("SUM"))) / self.size
        self.imbalance = float(most / mean) if mean > 0 else 1.0
        if self.imbalance <= self.threshold:
            return False
        self.tree = rcb_tree(self.comm, blocks.x[:n_owned], w, self.size, self.lo, self.hi)
        self.n_balanced += 1
        got = self.tree.leaf_work
        log.info("rebalanced: work imbalance %.3g -> %.3g (parallel.rebalance %.3g)",
                 self.imbalance, got.max() / max(got.mean(), 1e-300), self.threshold)
        return True

    def free(self):
        pass


def make_decomposition(comm, resolved, parallel, x: np.ndarray, shared: bool = False,
                       weights: np.ndarray | None = None):
    """The decomposition ``parallel`` asks for (collective); ``x``: the start's centroids of
    every block (the same on every rank), or with ``shared`` those of this rank's build share
    (pdem.state.build_share: the even share taken here of every block's); ``weights``: their
    work (None: 1 each)."""
    lo, hi = np.array(resolved.domain_lo), np.array(resolved.domain_hi)
    if balance_of(parallel) == "uniform":
        return Decomposition(comm, lo, hi, list(resolved.dims))
    if not shared:
        n = len(x)
        mine = slice(n * comm.rank // comm.size, n * (comm.rank + 1) // comm.size)
        x = x[mine]
        weights = None if weights is None else weights[mine]
    return RCBDecomposition(comm, lo, hi, np.asarray(x, float), parallel.rebalance, weights)
