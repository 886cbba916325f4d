"""Domain decomposition: a 3D Cartesian grid of ranks, each owning a brick of space.

A block is owned by the rank whose brick holds its centroid (clamped to the grid, so blocks
that fly outside still have an owner). The bricks are fixed for the run: they split the bounding
box of the model at start uniformly along each axis.
"""

from __future__ import annotations

import numpy as np


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

    def brick(self, rank: int) -> tuple[np.ndarray, np.ndarray]:
        c = self.cart.Get_coords(rank)
        lo = np.array([self.edges[k][c[k]] for k in range(3)])
        hi = np.array([self.edges[k][c[k] + 1] for k in range(3)])
        return lo, hi

    def free(self):
        self.cart.Free()
