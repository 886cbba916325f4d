"""Domain decomposition on one rank: the choice of the rank grid and the point -> rank map, and
the RCB cut tree (parallel.balance: rcb; its ``parts`` need not be the communicator's size, so
trees for 2-7 ranks are built here on MPI.COMM_SELF).

``Decomposition`` needs a communicator of ``prod(dims)`` ranks for its Cartesian topology, so
the many-rank cases of ``owner_of`` run the real method on a stand-in holding the same edges and
dims without a communicator (``owner_of`` is arithmetic on them), and check it against MPI's
row-major rank order (the order of ``Cartcomm.Get_coords`` with ``reorder=False``). The real
class is built on MPI.COMM_SELF with dims [1, 1, 1].
"""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.parallel.decomposition import (
    ZONES_PER_WORK,
    Decomposition,
    balance_of,
    block_work,
    choose_dims,
    rcb_tree,
)

DOWN = np.array([0.0, 0.0, -9.81])


@pytest.mark.parametrize("size", [1, 2, 3, 4, 6, 8, 12, 16, 24, 64, 512, 1000])
def test_choose_dims_multiplies_to_size(size):
    for extent in ([1.0, 1.0, 1.0], [10.0, 2.0, 1.0], [1.0, 5.0, 30.0]):
        dims = choose_dims(size, np.array(extent), DOWN)
        assert int(np.prod(dims)) == size
        assert all(isinstance(d, int) and d >= 1 for d in dims)
        assert sorted(dims, reverse=True) == sorted(MPI.Compute_dims(size, [0, 0, 0]), reverse=True)


def test_choose_dims_largest_factor_on_longest_axis():
    # no gravity: the longest axis gets the largest factor, the shortest the smallest
    assert choose_dims(12, np.array([1.0, 10.0, 3.0]), np.zeros(3)) == [2, 3, 2]
    assert choose_dims(12, np.array([10.0, 1.0, 3.0]), np.zeros(3)) == [3, 2, 2]
    assert choose_dims(4, np.array([10.0, 1.0, 3.0]), np.zeros(3)) == [2, 1, 2]
    assert choose_dims(8, np.array([2.0, 30.0, 1.0]), np.zeros(3)) == [2, 2, 2]
    assert choose_dims(2, np.array([1.0, 1.0, 5.0]), np.zeros(3)) == [1, 1, 2]


def test_choose_dims_gravity_axis_last():
    # the vertical axis is the longest, but split last: settling blocks gather at the bottom
    assert choose_dims(2, np.array([1.0, 2.0, 50.0]), DOWN) == [1, 2, 1]
    assert choose_dims(4, np.array([3.0, 2.0, 50.0]), DOWN) == [2, 2, 1]
    assert choose_dims(8, np.array([3.0, 2.0, 50.0]), DOWN) == [2, 2, 2]
    assert choose_dims(3, np.array([3.0, 2.0, 50.0]), DOWN) == [3, 1, 1]
    # gravity along -x (a tilted model): x is the axis split last
    assert choose_dims(2, np.array([50.0, 2.0, 1.0]), np.array([-9.81, 0.0, -0.1])) == [1, 2, 1]
    # the same whatever gravity's sign
    assert choose_dims(6, np.array([5.0, 4.0, 3.0]), -DOWN) == choose_dims(6, np.array([5.0, 4.0, 3.0]), DOWN)


def test_choose_dims_ties_are_stable():
    # equal extents: the order is x, y, z (minus gravity's), so every rank picks the same grid
    assert choose_dims(4, np.array([2.0, 2.0, 1.0]), DOWN) == [2, 2, 1]
    assert choose_dims(2, np.array([2.0, 2.0, 1.0]), DOWN) == [2, 1, 1]
    assert choose_dims(3, np.array([2.0, 2.0, 2.0]), np.zeros(3)) == [3, 1, 1]


class GridStandIn:
    """``Decomposition`` for ``dims`` ranks without a communicator: its edges and dims, and the
    real class's ``owner_of`` (pure arithmetic)."""

    owner_of = Decomposition.owner_of

    def __init__(self, lo, hi, dims):
        self.dims = np.array(dims, np.int64)
        self.edges = [np.linspace(lo[k], hi[k], dims[k] + 1) for k in range(3)]

    def coords(self, rank: int) -> tuple[int, int, int]:
        """MPI's row-major Cartesian coordinates (the last axis varies fastest)."""
        return tuple(int(c) for c in np.unravel_index(rank, tuple(self.dims)))


def test_one_rank_owns_everything():
    lo, hi = np.array([-1.0, -2.0, 0.0]), np.array([3.0, 2.0, 5.0])
    d = Decomposition(MPI.COMM_SELF, lo, hi, [1, 1, 1])
    try:
        pts = np.array([[0.0, 0.0, 1.0], lo, hi, [100.0, -100.0, 1e9], [-1e9, 0.0, np.inf]])
        assert d.owner_of(pts).tolist() == [0] * 5
        assert d.owner_of(np.array([0.5, 0.5, 0.5])).tolist() == [0]
        blo, bhi = d.brick(0)
        assert np.array_equal(blo, lo) and np.array_equal(bhi, hi)
        assert d.cart.Get_coords(0) == [0, 0, 0]
    finally:
        d.free()


def test_dims_must_multiply_to_size():
    with pytest.raises(ValueError, match="do not multiply"):
        Decomposition(MPI.COMM_SELF, np.zeros(3), np.ones(3), [2, 1, 1])


@pytest.mark.parametrize("dims", [[2, 1, 1], [1, 3, 1], [2, 2, 1], [2, 3, 4], [4, 1, 2]])
def test_owner_of_row_major_and_bricks(dims):
    lo, hi = np.array([-4.0, 0.0, -1.0]), np.array([4.0, 6.0, 3.0])
    grid = GridStandIn(lo, hi, dims)
    size = int(np.prod(dims))
    for rank in range(size):
        c = grid.coords(rank)
        # the centre and corners (just inside) of the brick at coords c belong to that rank
        blo = np.array([grid.edges[k][c[k]] for k in range(3)])
        bhi = np.array([grid.edges[k][c[k] + 1] for k in range(3)])
        inset = 1e-9 * (hi - lo)
        corners = [np.where(m, bhi - inset, blo + inset) for m in itertools.product((0, 1), repeat=3)]
        pts = np.array([0.5 * (blo + bhi), *corners])
        assert grid.owner_of(pts).tolist() == [rank] * len(pts), (dims, rank, c)


def test_owner_of_on_edges_and_outside():
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([4.0, 2.0, 2.0])
    grid = GridStandIn(lo, hi, [4, 2, 1])  # rank = 2 i + j
    # a point on an interior edge goes to the brick above it (searchsorted side="right")
    assert grid.owner_of(np.array([[1.0, 0.5, 1.0], [1.0, 1.0, 1.0], [3.0, 1.0, 1.0]])).tolist() \
        == [2, 3, 7]
    # points outside the grid are clamped to the nearest brick (blocks flying away keep an owner)
    far = np.array([[-5.0, -5.0, -5.0], [9.0, 9.0, 9.0], [-1.0, 9.0, 0.0], [9.0, -1.0, 1.0],
                    [0.0, 0.0, 0.0], [4.0, 2.0, 2.0]])
    assert grid.owner_of(far).tolist() == [0, 7, 1, 6, 0, 7]
    # one point, as a 1-D array
    assert grid.owner_of(np.array([2.5, 0.1, 1.9])).tolist() == [4]


# ---------------------------------------------------------------------------------------------
# RCB (parallel.balance: rcb)

LO, HI = np.array([0.0, 0.0, 0.0]), np.array([10.0, 4.0, 2.0])


def skewed(n=4000, seed=3):
    """A pile in one corner (90 % of the points) and a sparse scatter; weights 1-30, the pile's
    heavier (many contacts)."""
    rng = np.random.default_rng(seed)
    k = n * 9 // 10
    x = np.concatenate([rng.random((k, 3)) * [1.5, 1.0, 0.5], rng.random((n - k, 3)) * HI])
    w = np.concatenate([rng.integers(5, 31, k), rng.integers(1, 3, n - k)])
    return x, w


def tree(x, w, parts):
    return rcb_tree(MPI.COMM_SELF, x, w, parts, LO, HI)


@pytest.mark.parametrize("parts", [1, 2, 3, 4, 5, 7])
def test_rcb_every_point_has_one_owner_and_the_work_is_balanced(parts):
    x, w = skewed()
    t = tree(x, w, parts)
    owner = t.owner_of(x)
    assert owner.min() >= 0 and owner.max() < parts
    work = np.bincount(owner, w, parts)
    assert np.array_equal(work.astype(np.int64), t.leaf_work)  # the tree's own bookkeeping
    # within the heaviest block's weight of the exact share per leaf, at every level
    assert work.max() / work.mean() < 1.0 + parts * w.max() / w.sum() + 1e-12, work
    assert sorted(t.rank[t.rank >= 0].tolist()) == list(range(parts))
    assert t.depth == int(np.ceil(np.log2(parts)))


def test_rcb_balances_far_better_than_the_grid():
    x, w = skewed()
    for parts in (2, 3, 5):
        work = np.bincount(tree(x, w, parts).owner_of(x), w, parts)
        dims = [parts, 1, 1]  # the grid along the longest axis
        grid = np.searchsorted(np.linspace(LO[0], HI[0], parts + 1)[1:-1], x[:, 0], side="right")
        on_grid = np.bincount(grid, w, parts)
        assert work.max() / work.mean() < 1.01, (parts, work)
        assert on_grid.max() / on_grid.mean() > 1.5, (dims, on_grid)


def test_rcb_is_deterministic_and_order_free():
    x, w = skewed()
    a = tree(x, w, 5)
    perm = np.random.default_rng(0).permutation(len(x))
    b = tree(x[perm], w[perm], 5)
    for k in ("axis", "cut", "left", "right", "rank", "lo", "hi", "leaf_work"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k


def test_rcb_owner_of_everywhere():
    """Points outside the model's box, on the cuts, far away, in any shape of array: one owner."""
    x, w = skewed()
    t = tree(x, w, 3)
    inner = np.nonzero(t.rank < 0)[0]
    on_cuts = np.array([[t.cut[i] if k == t.axis[i] else 0.5 for k in range(3)] for i in inner])
    far = np.array([[-1e9, -1e9, -1e9], [1e9, 1e9, 1e9], [-1e9, 1e9, 0.0], [50.0, -3.0, 7.0]])
    got = t.owner_of(np.concatenate([on_cuts, far]))
    assert got.min() >= 0 and got.max() < 3
    # a point on the root's cut belongs to the side above it (x[axis] >= cut): ranks 1, 2
    p = np.full(3, 0.5)
    p[t.axis[0]] = t.cut[0]
    below = p.copy()
    below[t.axis[0]] = np.nextafter(t.cut[0], -np.inf)
    assert t.owner_of(p)[0] >= 1 and t.owner_of(below)[0] == 0
    assert t.owner_of(np.array([0.1, 0.1, 0.1])).shape == (1,)
    # the region of each rank holds the points it owns
    owner = t.owner_of(x)
    for r in range(3):
        lo, hi = t.region(r)
        assert np.all((x[owner == r] >= lo) & (x[owner == r] <= hi)), r


def test_rcb_cuts_the_longest_extent_first():
    rng = np.random.default_rng(1)
    x = rng.random((1000, 3)) * [1.0, 1.0, 6.0]  # a tall column: the first cut is across z
    t = tree(x, np.ones(1000, np.int64), 2)
    assert t.axis[0] == 2 and abs(t.cut[0] - np.median(x[:, 2])) < 0.05


def test_rcb_degenerate_inputs():
    # fewer points than ranks, identical points, no points at all: every rank a region, one
    # owner per point, the same tree twice
    one = np.array([[1.0, 1.0, 1.0]])
    for x in (one, np.repeat(one, 10, 0), np.zeros((0, 3))):
        w = np.ones(len(x), np.int64)
        a, b = tree(x, w, 5), tree(x, w, 5)
        assert np.array_equal(a.cut, b.cut)
        assert sorted(a.rank[a.rank >= 0].tolist()) == list(range(5))
        if len(x):
            assert a.leaf_work.sum() == len(x)
            assert np.unique(a.owner_of(x)).size == 1


def scene_with(parallel: str):
    return parse_scene(f"""
name: p
materials: {{rock: {{density: 2000}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9}}}}
blocks: [{{name: a, box: {{min: [0, 0, 0], max: [1, 1, 1]}}, material: rock}}]
solve: {{steps: 1}}
parallel: {parallel}
""")


def test_balance_setting():
    assert scene_with("{}").parallel.rebalance == 1.2
    assert balance_of(scene_with("{}").parallel) == "rcb"
    assert balance_of(scene_with("{dims: [2, 1, 1]}").parallel) == "uniform"
    assert balance_of(scene_with("{balance: uniform}").parallel) == "uniform"
    assert balance_of(scene_with("{balance: rcb, rebalance: null}").parallel) == "rcb"
    from pdem.config import ConfigError

    with pytest.raises(ConfigError, match="parallel: dims \\[2, 1, 1\\] is a rank grid"):
        scene_with("{balance: rcb, dims: [2, 1, 1]}")
    with pytest.raises(ConfigError, match="parallel.rebalance"):
        scene_with("{rebalance: 0.9}")
    with pytest.raises(ConfigError, match="parallel.balance"):
        scene_with("{balance: grid}")


def test_weighted_share_is_contiguous_complete_and_balanced():
    """Shares of weighted items: contiguous, covering every item once in rank order, each
    within one item's weight of an even share; all-zero weights split by count."""
    from pdem.mpi import weighted_share

    rng = np.random.default_rng(3)
    for size in (1, 2, 3, 7):
        for w in (rng.uniform(0, 10, 101), np.ones(5), np.zeros(9), np.array([100.0, 1, 1, 1]),
                  np.zeros(0)):
            shares = [weighted_share(r, size, w) for r in range(size)]
            assert shares[0][0] == 0 and shares[-1][1] == len(w)
            assert all(a[1] == b[0] for a, b in zip(shares, shares[1:], strict=False))
            if w.sum() > 0:
                even = w.sum() / size
                assert all(abs(w[lo:hi].sum() - even) <= w.max() + 1e-9 for lo, hi in shares)


def test_work_counts_zones_and_gridpoint_subcontacts_but_not_rigid_ones():
    """RCB's weights (block_work): a rigid free block weighs 1 + its contacts; a zoned one adds
    its zones // ZONES_PER_WORK, and a contact with a zoned block (owned or ghost) adds its
    gridpoint sub-contacts // ZONES_PER_WORK to each owned free block in it; a rigid contact
    weighs 1 whatever its sub-contacts. Rows: 0 rigid free, 1 zoned free, 2 rigid fixed (owned),
    3 zoned ghost."""
    blocks = SimpleNamespace(out=np.zeros(4, np.int8), fixed=np.array([0, 0, 1, 0], np.int8))
    zones = np.array([0, 700, 0, 1400], np.int64)
    # contacts: 0-2 rigid (4 sub-contacts), 1-2 zoned on the fixed block (42 gridpoint
    # sub-contacts), 0-3 rigid with the zoned ghost (28), 1-3 zoned with zoned (70)
    contacts = SimpleNamespace(n=4, arrays={"ia": np.array([0, 1, 0, 1]),
                                            "ib": np.array([2, 2, 3, 3])},
                               sc_start=np.array([0, 4, 46, 74, 144]))
    k = ZONES_PER_WORK
    w = block_work(blocks, 3, contacts, zones)
    assert w.tolist() == [1 + 1 + (1 + 28 // k),
                          1 + 700 // k + (1 + 42 // k) + (1 + 70 // k),
                          1]
    # owned rows' zones only (no ghosts known): zones weigh, contacts count 1 each
    assert block_work(blocks, 3, contacts, zones[:3]).tolist() == [3, 1 + 700 // k + 2, 1]
    # a rigid scene: as before
    assert block_work(blocks, 3, contacts).tolist() == [3, 3, 1]
