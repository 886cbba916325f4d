"""Histories and results of the run output: ``histories/<name>/{time, value}`` appended in
batches by the rank that owns the monitored block, and results every rank holds whole (e.g. a
factor-of-safety search)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import h5py
import numpy as np
from mpi4py import MPI

from .h5core import H5Core

__all__ = ["HistoryWriter"]


class HistoryWriter:
    """``histories/*`` and result groups; every method is collective over the core's ranks."""

    def __init__(self, core: H5Core) -> None:
        self.core = core
        self.rows: dict[str, int] = {}
        self.ncols: dict[str, int] = {}

    def create(self) -> None:
        """The empty group ``histories`` (IO ranks)."""
        self.core.f.create_group("histories")

    def add(self, name: str, ncols: int, attrs: dict[str, Any] | None = None) -> None:
        """Create ``histories/<name>/{time, value}`` (see ``OutputWriter.add_history``)."""
        if not name or "/" in name or name in self.rows:
            raise ValueError(f"add_history: bad or duplicate history name {name!r}")
        if int(ncols) < 1:
            raise ValueError(f"add_history({name!r}): ncols must be >= 1 (got {ncols})")
        self.rows[name] = 0
        self.ncols[name] = int(ncols)
        if not self.core.io:
            return
        g = self.core.f["histories"].create_group(name)
        for key, value in (attrs or {}).items():
            g.attrs[key] = value
        g.create_dataset("time", (0,), maxshape=(None,), chunks=(1024,), dtype=np.float64)
        g.create_dataset(
            "value", (0, int(ncols)), maxshape=(None, int(ncols)), chunks=(1024, int(ncols)),
            dtype=np.float64,
        )

    def _rows(self, name: str, time, values) -> tuple[np.ndarray | None, int]:
        """This rank's ``(time, value...)`` rows, or ``None``, and whether they are invalid."""
        if values is None:
            return None, 0
        ncols = self.ncols[name]
        v = np.asarray(values, dtype=np.float64)
        t = np.atleast_1d(np.asarray(time, dtype=np.float64))
        v = v.reshape(len(t), ncols) if v.size == len(t) * ncols else None
        if v is None:
            return None, 1
        return np.column_stack([t, v]), 0

    def write(self, name: str, time, values: np.ndarray | None) -> None:
        """Append rows to a history (see ``OutputWriter.write_history``)."""
        core, comm = self.core, self.core.comm
        if name not in self.rows:
            raise ValueError(f"write_history: no history {name!r} (call add_history first)")
        ncols = self.ncols[name]
        rows, invalid = self._rows(name, time, values)
        k = 0 if rows is None else len(rows)
        flags = np.array([rows is not None, invalid, (comm.rank + 1) * (rows is not None), k])
        comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.SUM)
        if flags[1] or flags[0] != 1:
            raise ValueError(
                f"write_history({name!r}): exactly one rank must pass {ncols} values per row "
                f"({int(flags[0])} valid, {int(flags[1])} of the wrong size)"
            )
        owner = int(flags[2]) - 1
        k = int(flags[3])
        if not core.parallel and owner != 0:
            if comm.rank == owner:
                comm.Send(np.ascontiguousarray(rows), dest=0, tag=77)
            elif comm.rank == 0:
                rows = np.empty((k, ncols + 1))
                comm.Recv(rows, source=owner, tag=77)
        i = self.rows[name]
        self.rows[name] = i + k
        if not core.io or k == 0:
            return
        g = core.f["histories"][name]
        g["time"].resize(i + k, axis=0)
        g["value"].resize(i + k, axis=0)
        mine = rows is not None
        core.write(g["time"], (i,), np.ascontiguousarray(rows[:, 0]) if mine else None)
        core.write(g["value"], (i, 0), np.ascontiguousarray(rows[:, 1:]) if mine else None)

    def write_result(self, group: str, attrs: dict[str, Any], datasets: dict[str, np.ndarray],
                     surface: tuple[str, ...], n_tri: int,
                     write_triangles: Callable[[h5py.Dataset, np.ndarray], None]) -> None:
        """Root attributes ``attrs``, static datasets ``group/<name>`` (replaced if present) and
        the per-triangle ``group/surface_<name>`` of the ``surface`` names, written with
        ``write_triangles`` (IO ranks, collective)."""
        core, f = self.core, self.core.f
        for key, value in attrs.items():
            f.attrs[key] = value
        g = f.require_group(group)
        for name, data in datasets.items():
            data = np.ascontiguousarray(data)
            if name in g:
                del g[name]
            core.write_static(g.create_dataset(name, data.shape, data.dtype), data)
        for name in surface:
            key = f"surface_{name}"
            if key in g:
                del g[key]
            write_triangles(g.create_dataset(key, (n_tri,), np.float32),
                            np.asarray(datasets[name], np.float32))
