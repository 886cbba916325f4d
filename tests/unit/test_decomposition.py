"""Domain decomposition on one rank: the choice of the rank grid and the point -> rank map.

``Decomposition`` needs a communicator of ``prod(dims)`` ranks for its Cartesian topology, so
the many-rank cases of ``owner_of`` run the real method on a stand-in holding the same edges and
dims without a communicator (``owner_of`` is arithmetic on them), and check it against MPI's
row-major rank order (the order of ``Cartcomm.Get_coords`` with ``reorder=False``). The real
class is built on MPI.COMM_SELF with dims [1, 1, 1].
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from mpi4py import MPI

from pdem.parallel.decomposition import Decomposition, choose_dims

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
