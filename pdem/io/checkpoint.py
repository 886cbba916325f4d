"""Checkpoints: the full state, keyed by global id, restartable on any number of ranks.

A checkpoint holds the resolved scene, the clock (step, time, dt), the damping state, every
block's dynamic state (row = gid) and every contact with its sub-contacts and history. Each
rank writes its own rows through the mpio driver (blocks by runs of consecutive gids; each
contact once, by the rank owning its lower-gid free block). The file is written under a
temporary name and renamed by rank 0 once every rank has closed it, so the last good
checkpoint is never overwritten in place. Derived state (the cell space, ghost lists, vertex
positions) is not stored: it is rebuilt on restart and results do not depend on it.
"""

from __future__ import annotations

import os
import uuid
from pathlib import Path

import h5py
import numpy as np

from ..model.blocks import DYNAMIC_FIELDS
from ..model.contacts import CONTACT_FIELDS, SUB_FIELDS

FORMAT = "checkpoint"
FORMAT_VERSION = 1


def new_run_id() -> str:
    return uuid.uuid4().hex[:12]


def _runs(sorted_rows: np.ndarray):
    """(start, stop) index pairs of runs of consecutive values."""
    if len(sorted_rows) == 0:
        return []
    breaks = np.nonzero(np.diff(sorted_rows) != 1)[0] + 1
    starts = np.concatenate([[0], breaks])
    stops = np.concatenate([breaks, [len(sorted_rows)]])
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def checkpoint_payload(solver) -> tuple[dict, dict, dict, np.ndarray]:
    """This rank's share: (attrs, block rows {field: array, 'gid'}, contacts, nsub)."""
    b = solver.blocks
    n = solver.n_owned
    rows = {k: getattr(b, k)[:n] for k in DYNAMIC_FIELDS}
    rows["gid"] = b.gid[:n]
    c = solver.contacts
    free = solver.glob.fixed == 0
    owned = set(b.gid[:n].tolist())
    ga_mine = np.array([g in owned for g in c.ga.tolist()], bool) & free[c.ga]
    gb_mine = np.array([g in owned for g in c.gb.tolist()], bool) & free[c.gb]
    write = ga_mine | (gb_mine & ~free[c.ga])
    sel = c.select(write)
    contacts = {**sel.arrays, **sel.sub}
    attrs = {
        "pdem_format": FORMAT, "format_version": FORMAT_VERSION, "run_id": solver.run_id,
        "step": solver.step, "time": solver.time, "dt": solver.dt, "alpha": solver.alpha,
        "ratio": solver.ratio if np.isfinite(solver.ratio) else -1.0,
        "n_blocks": solver.glob.n, "n_ranks": solver.comm.size, "scene": solver.scene_yaml,
    }
    return attrs, rows, contacts, np.diff(sel.sc_start)


def write_checkpoint(path: str | os.PathLike, solver) -> str:
    """Write the solver's state to ``path`` (collective). Returns the final path."""
    comm = solver.comm
    path = str(path)
    tmp = path + ".tmp"
    attrs, rows, contacts, nsub = checkpoint_payload(solver)
    parallel = comm.size > 1 and h5py.get_config().mpi
    if not parallel and comm.size > 1:
        parts = comm.gather((rows, contacts, nsub), root=0)
        if comm.rank == 0:
            rows = {k: np.concatenate([p[0][k] for p in parts]) for k in rows}
            contacts = {k: np.concatenate([p[1][k] for p in parts]) for k in contacts}
            nsub = np.concatenate([p[2] for p in parts])
    counts = np.array([len(nsub), int(nsub.sum())])
    if parallel:
        all_counts = np.array(comm.allgather(counts))
        offs = all_counts.cumsum(0) - all_counts
        tot = all_counts.sum(0)
        off_c, off_s = offs[comm.rank]
        f = h5py.File(tmp, "w", driver="mpio", comm=comm)
    else:
        tot = counts
        off_c = off_s = 0
        f = h5py.File(tmp, "w") if comm.rank == 0 else None
    if f is not None:
        with f:
            for k, v in attrs.items():
                f.attrs[k] = v
            n_blocks = attrs["n_blocks"]
            order = np.argsort(rows["gid"], kind="stable")
            gid = rows["gid"][order]
            for k in DYNAMIC_FIELDS:
                data = rows[k][order]
                d = f.create_dataset(f"blocks/{k}", (n_blocks, *data.shape[1:]), dtype=data.dtype)
                for a, z in _runs(gid):
                    d[gid[a]:gid[a] + (z - a)] = data[a:z]
            for k in CONTACT_FIELDS:
                shape, dt = CONTACT_FIELDS[k]
                d = f.create_dataset(f"contacts/{k}", (int(tot[0]), *shape), dtype=dt)
                if counts[0]:
                    d[off_c:off_c + counts[0]] = contacts[k]
            d = f.create_dataset("contacts/nsub", (int(tot[0]),), dtype=np.int64)
            if counts[0]:
                d[off_c:off_c + counts[0]] = nsub
            for k in SUB_FIELDS:
                shape, dt = SUB_FIELDS[k]
                d = f.create_dataset(f"subcontacts/{k}", (int(tot[1]), *shape), dtype=dt)
                if counts[1]:
                    d[off_s:off_s + counts[1]] = contacts[k]
    comm.Barrier()
    if comm.rank == 0:
        os.replace(tmp, path)  # atomic: a reader sees the old or the complete new file
    comm.Barrier()
    return path


def read_checkpoint(path: str | os.PathLike) -> dict:
    """Everything in a checkpoint (read by each rank; restart keeps what it needs)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no checkpoint at {path}")
    with h5py.File(path, "r") as f:
        if f.attrs.get("pdem_format") != FORMAT:
            raise ValueError(f"{path} is not a pdem checkpoint")
        if int(f.attrs["format_version"]) > FORMAT_VERSION:
            raise ValueError(f"{path}: checkpoint format {int(f.attrs['format_version'])} is newer "
                             f"than this pdem reads ({FORMAT_VERSION})")
        out = {"attrs": {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}}
        out["blocks"] = {k: f[f"blocks/{k}"][()] for k in DYNAMIC_FIELDS}
        out["contacts"] = {k: f[f"contacts/{k}"][()] for k in CONTACT_FIELDS}
        out["nsub"] = f["contacts/nsub"][()]
        out["sub"] = {k: f[f"subcontacts/{k}"][()] for k in SUB_FIELDS}
    return out


def prune(prefix: str, keep: int, comm) -> None:
    """Keep the newest ``keep`` checkpoints ``{prefix}-*.h5`` (rank 0 deletes)."""
    if comm.rank != 0:
        return
    p = Path(prefix)
    files = sorted(p.parent.glob(p.name + "-*.h5"))
    for old in files[:-keep]:
        old.unlink(missing_ok=True)
