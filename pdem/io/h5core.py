"""The parallel HDF5 file of a run's output: its communicator, the rows each rank writes, the
collective (``mpio``) or gathered writes, views, and the periodic reopen.

In parallel mode every rank writes its own rows with collective I/O (a rank with nothing to
write takes part with an empty selection); in the fallback without MPI h5py, rank 0 holds
every row and writes alone. The section writers (:mod:`pdem.io.block_series`,
:mod:`pdem.io.contact_series`, :mod:`pdem.io.zone_series`, :mod:`pdem.io.histories`) write
through an :class:`H5Core`; :class:`pdem.io.writer.OutputWriter` ties them together.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from h5py import h5fd, h5p, h5s, h5t
from mpi4py import MPI

from . import layout as row_layout
from .layout import even_share
from .xdmf import view_path

__all__ = ["H5Core", "CHUNK_ROWS", "MPIO_HINTS", "REOPEN_EVERY", "add_view", "add_range_view"]

# Parallel HDF5 duplicates the file's communicator for every virtual dataset that names the
# file itself as its source, and frees them only when the file closes: MPICH allows ~2048
# communicators, i.e. ~220 snapshots of views. So the file is closed and reopened every this
# many snapshots (collective; measured: 3000 views, no leak).
REOPEN_EVERY = 32  # 10 views per snapshot, 24 with contacts, 34 with zones: 1088 at most
# MPI-IO hints of the parallel file (ROMIO's; other MPI-IO layers ignore them). Each rank writes
# its own contiguous rows, so collective buffering only moved every rank's rows through the
# aggregator: one rank a node (rank 0 on one node), whose 16 MiB buffer then stayed resident
# while the file was open (64,000 cubes on 2 ranks: rank 0 ~11 MB above rank 1 a snapshot,
# bench/output_memory.py). HDF5's collective calls are unchanged; the bytes written are the same.
MPIO_HINTS = {"romio_cb_write": "disable"}
CHUNK_ROWS = 1 << 16  # rows per chunk along the block/vertex axis (1.5 MiB for 3 doubles)


def add_view(f: h5py.File, path: str, i: int) -> None:
    """Virtual dataset ``view_path(path, i)`` = snapshot ``i`` of the series ``path``.

    ParaView's XDMF readers disagree on how to select one snapshot of a series (the Xdmf3 readers
    cannot read HyperSlab items, the legacy one cannot read ``|``-slabs), but all read a plain
    dataset: the view is one, with no data copied. The source file is ``"."`` (this file), so
    the view survives moving the file. Creating it is collective (metadata only).
    """
    src = f[path]
    layout = h5py.VirtualLayout(shape=src.shape[1:], dtype=src.dtype)
    layout[...] = h5py.VirtualSource(".", path, shape=src.shape, dtype=src.dtype)[i]
    f.create_virtual_dataset(view_path(path, i), layout)


def add_range_view(f: h5py.File, path: str, view: str, lo: int, hi: int) -> None:
    """Virtual dataset ``view`` = rows ``lo .. hi-1`` of the flat dataset ``path`` (one
    snapshot's contacts); ``hi > lo``."""
    src = f[path]
    layout = h5py.VirtualLayout(shape=(hi - lo, *src.shape[1:]), dtype=src.dtype)
    layout[...] = h5py.VirtualSource(".", path, shape=src.shape, dtype=src.dtype)[lo:hi]
    f.create_virtual_dataset(view, layout)


class H5Core:
    """The output file and how its rows are shared out; every method is collective.

    ``n_rows`` blocks (gids) are shared out: rank ``r`` assembles and writes gids
    ``[bounds[r], bounds[r+1])`` (``[lo, hi)`` its own); in the fallback rank 0 holds them
    all. ``io``: this rank touches the file (every rank in parallel mode, rank 0 otherwise).
    ``parallel``: as :class:`pdem.io.writer.OutputWriter`'s argument.
    """

    def __init__(self, path: str | os.PathLike, comm: MPI.Comm, n_rows: int,
                 parallel: bool | None) -> None:
        self.path = Path(path)
        self.comm = comm
        rank, size = comm.rank, comm.size
        has_mpi = row_layout.h5py_has_mpi()
        if parallel is None:
            parallel = has_mpi
            if not has_mpi and rank == 0:
                warnings.warn(
                    "h5py was built without MPI: output is gathered on rank 0, which writes "
                    "it alone (install h5py with HDF5_MPI=ON for parallel output)",
                    RuntimeWarning,
                    stacklevel=3,
                )
        elif parallel and not has_mpi:
            raise RuntimeError("OutputWriter(parallel=True): h5py was built without MPI")
        self.parallel = bool(parallel)
        self.io = self.parallel or rank == 0  # does this rank touch the file?
        n = n_rows
        if n == 0:
            raise ValueError("OutputWriter: the scene has no blocks")
        if self.parallel:
            self.bounds = np.array([even_share(r, size, n)[0] for r in range(size)] + [n])
        else:
            self.bounds = np.array([0] + [n] * size)
        self.lo, self.hi = int(self.bounds[rank]), int(self.bounds[rank + 1])
        self.f: h5py.File | None = None
        self.closed = False
        self.dxpl = None

    # ------------------------------------------------------------------ the file
    def open(self, attrs: dict[str, Any]) -> None:
        """Create the file (IO ranks) with the root attributes ``attrs``, in their order."""
        # Format v108 at least: dense attribute storage, so a large scene fits in an attribute.
        if self.parallel:
            self.f = self._mpio_file("w", libver=("v108", "latest"))
            self.dxpl = h5p.create(h5p.DATASET_XFER)
            self.dxpl.set_dxpl_mpio(h5fd.MPIO_COLLECTIVE)
        else:
            self.f = h5py.File(self.path, "w", libver=("v108", "latest"))
        for key, value in attrs.items():
            self.f.attrs[key] = value

    def reopen(self) -> None:
        """Close and reopen the file (collective): frees the communicators of the views. The
        section writers look their datasets up by path, so nothing is rebound."""
        self.f.close()
        self.f = self._mpio_file("r+")

    def _mpio_file(self, mode: str, **kwargs) -> h5py.File:
        """The file opened on every rank with the ``mpio`` driver and :data:`MPIO_HINTS`."""
        info = MPI.Info.Create()
        for key, value in MPIO_HINTS.items():
            info.Set(key, value)
        try:
            return h5py.File(self.path, mode, driver="mpio", comm=self.comm, info=info,
                             **kwargs)
        finally:
            info.Free()

    def flush(self) -> None:
        """Flush the HDF5 file to disk (collective)."""
        if self.f is not None:
            self.f.flush()

    def close(self) -> None:
        """Close the file (collective; the writer makes it idempotent)."""
        self.closed = True
        if self.f is not None:
            self.f.close()
            self.f = None

    def check_open(self) -> None:
        if self.closed:
            raise ValueError(f"OutputWriter({self.path}): the file is closed")

    # ------------------------------------------------------------------ ranks
    def share(self, n: int) -> tuple[int, int]:
        """This rank's contiguous share ``[lo, hi)`` of ``n`` rows all ranks know (rank 0 all
        of them in the fallback)."""
        return even_share(self.comm.rank, self.comm.size, n) if self.parallel else (0, n)

    def raise_if_any(self, message: str | None) -> None:
        """Raise ``ValueError`` on every rank if any rank has a message (no lone raise: hangs)."""
        if self.comm.allreduce(int(message is not None), op=MPI.SUM):
            # rare path: every rank raises the same, first, message
            first = next(m for m in self.comm.allgather(message) if m is not None)
            raise ValueError(first)

    def exchange(self, dest: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
        """Rows of ``arrays`` (int64 or float64, the same row count) to rank ``dest`` (stable:
        received in source-rank order, then row order): one ``Alltoall`` of the counts, one
        ``Alltoallv`` per array."""
        comm, size = self.comm, self.comm.size
        # rows already grouped by rank (a rank's own blocks in gid order, the usual snapshot)
        # are sent as they are: no sorted copy of every array
        grouped = len(dest) < 2 or bool((dest[1:] >= dest[:-1]).all())
        order = None if grouped else np.argsort(dest, kind="stable")
        send_n = np.bincount(dest, minlength=size).astype(np.int64)
        recv_n = np.empty(size, dtype=np.int64)
        comm.Alltoall(send_n, recv_n)
        sdispl = np.concatenate([[0], np.cumsum(send_n)[:-1]])
        rdispl = np.concatenate([[0], np.cumsum(recv_n)[:-1]])
        out = []
        for a in arrays:
            c = int(np.prod(a.shape[1:], dtype=np.int64))
            mtype = MPI.INT64_T if a.dtype == np.int64 else MPI.DOUBLE
            got = np.empty((int(recv_n.sum()), *a.shape[1:]), dtype=a.dtype)
            comm.Alltoallv(
                [np.ascontiguousarray(a if grouped else a[order]), (send_n * c, sdispl * c),
                 mtype],
                [got, (recv_n * c, rdispl * c), mtype],
            )
            out.append(got)
        return tuple(out)

    # ------------------------------------------------------------------ datasets
    def series(self, name: str, tail: tuple[int, ...], dtype, chunk0: int = 1) -> h5py.Dataset:
        """An empty time series ``name`` of rows ``tail``, growing along its first axis."""
        rows = tail[:1]
        chunk = (chunk0, *(min(max(r, 1), CHUNK_ROWS) for r in rows), *tail[1:])
        return self.f.create_dataset(
            name, (0, *tail), maxshape=(None, *tail), chunks=chunk, dtype=dtype
        )

    def write(self, dset: h5py.Dataset, start: tuple[int, ...], data: np.ndarray | None):
        """Write ``data`` at ``start`` (collective in parallel mode; ``None``: take part only)."""
        mtype = h5t.py_create(dset.dtype)
        fspace = dset.id.get_space()
        if data is None or data.size == 0:
            fspace.select_none()
            mspace = h5s.create_simple((1,))
            mspace.select_none()
            buf = np.zeros(1, dtype=dset.dtype)
        else:
            buf = np.ascontiguousarray(data, dtype=dset.dtype)
            fspace.select_hyperslab(start, buf.shape)
            mspace = h5s.create_simple(buf.shape)
        dset.id.write(mspace, fspace, buf, mtype=mtype, dxpl=self.dxpl)

    def write_texts(self, group, key: str, texts: Sequence[str]) -> None:
        """A fixed-width UTF-8 dataset of one text a block (all ranks know its width; each
        encodes only the rows it writes: a name column of 10^6 blocks is not copied whole)."""
        n = len(texts)
        width = getattr(texts, "max_bytes", None)
        if width is None:
            width = max(len(str(t).encode("utf-8")) for t in texts)
        dset = group.create_dataset(key, (n,), dtype=h5py.string_dtype("utf-8", max(1, width)))
        lo, hi = self.share(n)
        mine = np.array([str(texts[i]).encode("utf-8") for i in range(lo, hi)],
                        dtype=f"S{max(1, width)}")
        self.write(dset, (lo,), mine)

    def write_static(self, dset: h5py.Dataset, data: np.ndarray) -> None:
        """Each rank writes its contiguous share of the rows of a dataset all ranks know."""
        lo, hi = self.share(len(data))
        self.write(dset, (lo,) + (0,) * (data.ndim - 1), data[lo:hi])

    def write_range(self, dset: h5py.Dataset, rows: np.ndarray) -> None:
        """Rows of this rank's gid range (``[lo, hi)``) of a per-block dataset."""
        self.write(dset, (self.lo,) + (0,) * (rows.ndim - 1), rows)

    def write_row(self, dset: h5py.Dataset, i: int, data: np.ndarray | None,
                  first: int = 0) -> None:
        """Snapshot ``i``: ``data`` holds rows ``first, first + 1, ...`` (or is ``None``)."""
        ndim = len(dset.shape)
        if data is None or ndim == 1:
            self.write(dset, (i,), None if data is None else data.reshape(1))
        else:
            self.write(dset, (i, first) + (0,) * (ndim - 2), data.reshape((1, *data.shape)))

    def write_runs(self, dset: h5py.Dataset, lead: tuple[int, ...], starts, counts,
                   data: np.ndarray | None) -> None:
        """Rows ``starts[k] .. starts[k] + counts[k] - 1`` (ascending, disjoint) of ``dset``
        after the leading indices ``lead`` (``(i,)``: snapshot ``i``), from ``data``, the runs'
        rows one after the other: one write whose selection is the union of the runs
        (collective in parallel mode; HDF5 walks a union in file order, so the runs' rows
        follow in ``data`` as in the file)."""
        if data is None or len(data) == 0:
            self.write(dset, (0,) * len(dset.shape), None)
            return
        tail = dset.shape[len(lead) + 1:]
        buf = np.ascontiguousarray(data, dtype=dset.dtype).reshape(-1, *tail)
        fspace = dset.id.get_space()
        fspace.select_none()
        for s, c in zip(starts, counts, strict=True):
            fspace.select_hyperslab((*lead, int(s), *(0,) * len(tail)),
                                    (*(1,) * len(lead), int(c), *tail), op=h5s.SELECT_OR)
        dset.id.write(h5s.create_simple(buf.shape), fspace, buf,
                      mtype=h5t.py_create(dset.dtype), dxpl=self.dxpl)
