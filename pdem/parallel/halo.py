"""Per-step forward halo: owners send ghost copies their pose, velocities and triggers.

Only ranks that share ghosts talk, with packed float64 buffers (``Isend``/``Irecv``, no
pickles). Fixed blocks never change, so they are sent once, at the ghost rebuild, not here.
There is no reverse halo: every rank that owns a free block of a contact computes that contact
itself (the same inputs give the same bits), so forces never travel back.
"""

from __future__ import annotations

import numpy as np

# columns of a halo row: x(3) q(4) v(3) w(3) dtheta(3) u_acc u_geo
ROW = 18


class Halo:
    """Send/receive plan: ``send[r]`` local owned rows ghosted on rank r, ``recv[r]`` local ghost
    rows owned by rank r, both in gid order so the two sides agree row by row."""

    def __init__(self, comm, send: dict[int, np.ndarray], recv: dict[int, np.ndarray]):
        self.comm = comm
        self.send = {r: rows for r, rows in send.items() if len(rows)}
        self.recv = {r: rows for r, rows in recv.items() if len(rows)}
        self.sbuf = {r: np.empty((len(rows), ROW)) for r, rows in self.send.items()}
        self.rbuf = {r: np.empty((len(rows), ROW)) for r, rows in self.recv.items()}

    @property
    def bytes_per_step(self) -> int:
        """Bytes this rank sends per step."""
        return sum(b.nbytes for b in self.sbuf.values())

    @property
    def neighbours(self) -> list[int]:
        return sorted(set(self.send) | set(self.recv))

    def forward(self, blocks, dtheta):
        """Copy owners' state into the ghost rows (collective among neighbours)."""
        from mpi4py import MPI

        reqs = [self.comm.Irecv(buf, source=r, tag=11) for r, buf in self.rbuf.items()]
        for r, rows in self.send.items():
            buf = self.sbuf[r]
            buf[:, 0:3] = blocks.x[rows]
            buf[:, 3:7] = blocks.q[rows]
            buf[:, 7:10] = blocks.v[rows]
            buf[:, 10:13] = blocks.w[rows]
            buf[:, 13:16] = dtheta[rows]
            buf[:, 16] = blocks.u_acc[rows]
            buf[:, 17] = blocks.u_geo[rows]
            reqs.append(self.comm.Isend(buf, dest=r, tag=11))
        MPI.Request.Waitall(reqs)
        for r, rows in self.recv.items():
            buf = self.rbuf[r]
            blocks.x[rows] = buf[:, 0:3]
            blocks.q[rows] = buf[:, 3:7]
            blocks.v[rows] = buf[:, 7:10]
            blocks.w[rows] = buf[:, 10:13]
            dtheta[rows] = buf[:, 13:16]
            blocks.u_acc[rows] = buf[:, 16]
            blocks.u_geo[rows] = buf[:, 17]
