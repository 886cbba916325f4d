"""Per-step forward halo: owners send ghost copies their pose, velocities and triggers.

Only ranks that share ghosts talk, with packed float64 buffers (``Isend``/``Irecv``, no
pickles). Fixed blocks never change, so they are sent once, at the ghost rebuild, not here.
There is no reverse halo: every rank that owns a free block of a contact computes that contact
itself (the same inputs give the same bits), so forces never travel back.
"""

from __future__ import annotations

import numpy as np

from ..jit import kernel
from ..model.fields import HALO, pack, row_width, unpack
from ..mpi import wait_all

# columns of a full halo row: the block fields declared with halo=True (pdem.model.fields); a
# scene sends those of the features it uses (pdem.model.fields.halo_fields)
ROW = row_width(HALO)
HALO_TAG = 11  # the forward halo's messages (pdem.parallel.native sends the same)
GRID_HALO_TAG = 12  # the zoned blocks' gridpoints' (RowHalo; the compiled loop's the same)


@kernel
def copy_rows(columns, rows, buf, pack):
    """``pack``: ``buf[i]`` = the ``rows[i]`` rows of the 2-D float64 ``columns``, side by
    side; else the inverse (the ghosts' rows from a received buffer)."""
    col = 0
    for a in columns:
        w = a.shape[1]
        for i in range(rows.shape[0]):
            r = rows[i]
            for k in range(w):
                if pack:
                    buf[i, col + k] = a[r, k]
                else:
                    a[r, k] = buf[i, col + k]
        col += w


def halo_columns(blocks, fields) -> tuple | None:
    """The fields' arrays of ``blocks`` as 2-D float64 views (one numba type for the compiled
    copy), or None when one is not float64 (``still`` with solve.inactive: numpy copies it)."""
    out = []
    for f in fields:
        a = getattr(blocks, f.name)
        if a.dtype != np.float64 or not a.flags.c_contiguous:
            return None
        out.append(a.reshape(a.shape[0], f.width))
    return tuple(out)


class Halo:
    """Send/receive plan: ``send[r]`` local owned rows ghosted on rank r, ``recv[r]`` local ghost
    rows owned by rank r, both in gid order so the two sides agree row by row; ``fields``: the
    halo fields sent (pdem.model.fields.halo_fields)."""

    def __init__(self, comm, send: dict[int, np.ndarray], recv: dict[int, np.ndarray],
                 fields=HALO):
        self.comm = comm
        self.fields = fields
        width = row_width(fields)
        self.send = {r: rows for r, rows in send.items() if len(rows)}
        self.recv = {r: rows for r, rows in recv.items() if len(rows)}
        self.sbuf = {r: np.empty((len(rows), width)) for r, rows in self.send.items()}
        self.rbuf = {r: np.empty((len(rows), width)) for r, rows in self.recv.items()}

    @property
    def bytes_per_step(self) -> int:
        """Bytes this rank sends per step."""
        return sum(b.nbytes for b in self.sbuf.values())

    @property
    def neighbours(self) -> list[int]:
        return sorted(set(self.send) | set(self.recv))

    def forward(self, blocks):
        """Copy owners' state into the ghost rows (collective among neighbours)."""
        if not self.send and not self.recv:
            return
        # compiled copies: numpy's fancy indexing per field cost ~0.25 ms a step for ~1000
        # ghosts, 3 % of a 2-rank step of the 22^3 stack (bench/scaling.py)
        columns = halo_columns(blocks, self.fields)
        arrays = None if columns is not None else {f.name: getattr(blocks, f.name)
                                                   for f in self.fields}
        reqs = [self.comm.Irecv(buf, source=r, tag=HALO_TAG) for r, buf in self.rbuf.items()]
        for r, rows in self.send.items():
            if columns is None:
                pack(arrays, self.fields, rows, self.sbuf[r])
            else:
                copy_rows(columns, rows, self.sbuf[r], True)
            reqs.append(self.comm.Isend(self.sbuf[r], dest=r, tag=HALO_TAG))
        wait_all(self.comm, reqs)
        for r, rows in self.recv.items():
            if columns is None:
                unpack(arrays, self.fields, rows, self.rbuf[r])
            else:
                copy_rows(columns, rows, self.rbuf[r], False)


class RowHalo:
    """Per-step forward of rows of flat arrays of equal length (the zoned blocks' gridpoints,
    pdem.deformable.store): ``send[r]`` indices of rows this rank's owned grids hold and rank
    r ghosts, ``recv[r]`` the ghost rows rank r owns, in the same order on both sides (the
    blocks' halo plan, gid order); ``width`` the columns of all arrays forwarded together."""

    def __init__(self, comm, send: dict[int, np.ndarray], recv: dict[int, np.ndarray],
                 width: int):
        self.comm = comm
        self.send = {r: idx for r, idx in send.items() if len(idx)}
        self.recv = {r: idx for r, idx in recv.items() if len(idx)}
        self.sbuf = {r: np.empty((len(idx), width)) for r, idx in self.send.items()}
        self.rbuf = {r: np.empty((len(idx), width)) for r, idx in self.recv.items()}

    @property
    def bytes_per_step(self) -> int:
        return sum(b.nbytes for b in self.sbuf.values())

    def forward(self, arrays) -> None:
        """Copy the owners' rows of ``arrays`` (each (n, k), the k summing to ``width``) into
        the ghost rows (collective among neighbours)."""
        if not self.send and not self.recv:
            return
        reqs = [self.comm.Irecv(buf, source=r, tag=GRID_HALO_TAG) for r, buf in self.rbuf.items()]
        for r, idx in self.send.items():
            c = 0
            for a in arrays:
                self.sbuf[r][:, c:c + a.shape[1]] = a[idx]
                c += a.shape[1]
            reqs.append(self.comm.Isend(self.sbuf[r], dest=r, tag=GRID_HALO_TAG))
        wait_all(self.comm, reqs)
        for r, idx in self.recv.items():
            c = 0
            for a in arrays:
                a[idx] = self.rbuf[r][:, c:c + a.shape[1]]
                c += a.shape[1]
