"""The zoned (deformable) blocks of the run output: their tetrahedral grids ``zones/*``, the
per-gridpoint and per-zone series and each snapshot's views (:mod:`pdem.io.zones`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .h5core import CHUNK_ROWS, H5Core, add_view
from .zones import ZoneLayout, zone_columns, zone_layout, zone_values

__all__ = ["ZoneSeries", "COMPRESSION"]

# The series' filter: deflate after byte shuffling (the float32 exponents and the uint8 bits
# repeat from zone to zone). Parallel HDF5 (>= 1.10.2) writes filtered datasets with collective
# I/O only, which is how every write here goes (pdem.io.h5core). bench/zone_output.py measures
# what it saves and costs (docs/output.md, Zoned blocks); {} writes them unfiltered.
COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True}


def _static_items(zones, n_blocks: int) -> list:
    """``(gid, {initial_points, tets})`` of this rank's zoned blocks (``ValueError`` if bad)."""
    static = []
    for gid, body in ([] if zones is None else zones):
        tets = np.asarray(body.tets, np.int64)
        x0 = np.asarray(body.nodes0, np.float64)
        if x0.ndim != 2 or x0.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4 \
                or (tets.size and (tets.min() < 0 or tets.max() >= len(x0))):
            raise ValueError(f"OutputWriter: zoned block {gid}: nodes0 {x0.shape}, "
                             f"tets {tets.shape} (need (n, 3) and (m, 4) ids < n)")
        if not 0 <= int(gid) < n_blocks:
            raise ValueError(f"OutputWriter: zoned block gid {gid} outside "
                             f"[0, {n_blocks})")
        static.append((int(gid), {"initial_points": x0, "tets": tets}))
    return static


class ZoneSeries:
    """The zoned blocks' grids and series; ``layout`` is ``None`` without zoned blocks.

    Construction is collective: the layout from every rank's (gid, gridpoints, zones) of the
    ``(gid, body)`` pairs ``zones`` (``ValueError`` on every rank if bad). ``fields``: the
    series written besides the positions (pdem.io.zones.ZONE_FIELDS; None: all of them).
    """

    def __init__(self, core: H5Core, n_blocks: int,
                 zones: Sequence[tuple[int, Any]] | None,
                 fields: Sequence[str] | None = None) -> None:
        self.core = core
        self.columns = zone_columns(fields)  # the written series, gridpoints' then zones'
        self.names = tuple(c.name for c in self.columns)
        self.viewed = tuple(f"/zones/{name}" for name in self.names)
        msg, counts, static = None, np.zeros((0, 3), np.int64), []
        try:
            static = _static_items(zones, n_blocks)
            counts = np.array([(g, len(v["initial_points"]), len(v["tets"])) for g, v in static],
                              np.int64).reshape(-1, 3)
        except (TypeError, ValueError, AttributeError) as e:
            msg, counts, static = str(e), np.zeros((0, 3), np.int64), []
        core.raise_if_any(msg)
        layout = zone_layout(core.comm.allgather(counts))  # the same ValueError on every rank
        self.layout: ZoneLayout | None = layout if len(layout.gid) else None
        # what this rank writes of the static grid, by gid (rank 0 all of it in the fallback)
        self._static = None if self.layout is None else self._to_writers(static)

    def _to_writers(self, items: list) -> list:
        """``(gid, values)`` items to the ranks that write them, sorted by gid: each its own
        in parallel mode; in the fallback, all of them to rank 0."""
        comm = self.core.comm
        if not self.core.parallel and comm.size > 1:
            every = comm.gather(items, root=0)
            items = [it for part in every for it in part] if comm.rank == 0 else []
        return sorted(items, key=lambda it: it[0])

    def snapshot(self, zones) -> tuple[str | None, list]:
        """This rank's zoned blocks' snapshot values, checked against the layout: (error, items)."""
        lay = self.layout
        items = []
        try:
            for gid, body in ([] if zones is None else zones):
                k = int(np.searchsorted(lay.gid, int(gid)))
                if k == len(lay.gid) or lay.gid[k] != int(gid):
                    raise ValueError(f"write_snapshot: block {gid} is not a zoned block")
                v = zone_values(body, self.names)
                for c in self.columns:
                    start = lay.point_start if c.center == "Node" else lay.zone_start
                    n = start[k + 1] - start[k]
                    if v[c.name].size != n * c.width:
                        raise ValueError(f"write_snapshot: zoned block {gid}: {c.name} has "
                                         f"shape {np.shape(v[c.name])}, need ({n}, {c.width})")
                items.append((int(gid), v))
        except (TypeError, ValueError, AttributeError) as e:
            return str(e), []
        return None, items

    def gather(self, items: list) -> list:
        """Check that every zoned block was passed by exactly one rank (``ValueError`` on every
        rank otherwise), then send the items to their writers (collective)."""
        got = np.sort(np.concatenate([np.asarray(g, np.int64) for g in
                                      self.core.comm.allgather([gid for gid, _ in items])]))
        if not np.array_equal(got, self.layout.gid):
            missing = np.setdiff1d(self.layout.gid, got)[:5]
            dup = got[1:][np.diff(got) == 0][:5] if len(got) > 1 else got[:0]
            raise ValueError("write_snapshot: every zoned block must be passed by exactly one "
                             f"rank (missing e.g. {missing.tolist()}, duplicated e.g. "
                             f"{dup.tolist()})")
        return self._to_writers(items)

    def create(self) -> None:
        """The group ``zones/``: static grid and empty series (IO ranks, collective)."""
        core, f, lay, static = self.core, self.core.f, self.layout, self._static
        self._static = None  # written below
        npt, nz = lay.n_points, lay.n_zones
        g = f.create_group("zones")
        g.attrs["doc"] = ("zoned (deformable) blocks as one tetrahedral grid, blocks by gid: block "
                          "k's gridpoints are rows point_start[k] .. point_start[k+1]-1, its "
                          "zones zone_start[k] .. zone_start[k+1]-1")
        for name, data in (("block", lay.gid), ("point_start", lay.point_start),
                           ("zone_start", lay.zone_start)):
            core.write_static(g.create_dataset(name, (len(data),), np.int64), data)
        g["block"].attrs["doc"] = "gids of the zoned blocks, ascending"
        gids = np.array([gid for gid, _ in static], np.int64)
        p0, pn, z0, zn = lay.runs(gids)

        def cat(rows, tail=()):
            return np.concatenate(rows) if rows else np.zeros((0, *tail))
        conn = cat([v["tets"] + p for (_, v), p in zip(static, p0, strict=True)], (4,))
        x0 = cat([v["initial_points"] for _, v in static], (3,))
        for name, shape, dtype, data, per_point, units, doc in (
                ("connectivity", (nz, 4), np.int64, conn, False, "",
                 "the zones' 4 gridpoints, rows of the zones/points series"),
                ("zone_block", (nz,), np.int64, np.repeat(gids, zn), False, "",
                 "gid of each zone's block"),
                ("point_block", (npt,), np.int64, np.repeat(gids, pn), True, "",
                 "gid of each gridpoint's block"),
                ("initial_points", (npt, 3), np.float64, x0, True, "m",
                 "gridpoint positions at the start (reference of displacement)")):
            d = g.create_dataset(name, shape, dtype)
            core.write_runs(d, (), p0 if per_point else z0, pn if per_point else zn, data)
            d.attrs["doc"] = doc
            if units:
                d.attrs["units"] = units
        for c in self.columns:
            n = npt if c.center == "Node" else nz
            tail = (n, c.width) if c.width > 1 else (n,)
            d = f.create_dataset(f"zones/{c.name}", (0, *tail), maxshape=(None, *tail),
                                 chunks=(1, min(max(n, 1), CHUNK_ROWS), *tail[1:]),
                                 dtype=c.dtype, **COMPRESSION)
            d.attrs["units"] = c.units
            d.attrs["doc"] = c.doc

    def write(self, i: int, items: list) -> None:
        """Snapshot ``i`` of the zone series and its ``/xdmf`` views (IO ranks, collective)."""
        core, f = self.core, self.core.f
        gids = np.array([gid for gid, _ in items], np.int64)
        p0, pn, z0, zn = self.layout.runs(gids)
        for c in self.columns:
            starts, counts = (p0, pn) if c.center == "Node" else (z0, zn)
            d = f[f"zones/{c.name}"]
            d.resize(i + 1, axis=0)
            data = np.concatenate([v[c.name] for _, v in items]) if items else None
            core.write_runs(d, (i,), starts, counts, data)
        for path in self.viewed:
            add_view(f, path, i)
