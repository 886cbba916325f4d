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

import contextlib
import math
import os
import uuid
from pathlib import Path

import h5py
import numpy as np

from ..model import csr
from ..model.contacts import ContactStore
from ..model.fields import BLOCK_BY_NAME, CHECKPOINT, CONTACT, CONTACT_ADDED, SUB, SUB_HIST, select
from ..parallel.mpi import allgather, barrier, gather

FORMAT = "checkpoint"
# 2: contact rows (ia, ib) no longer stored, joint-law history columns (subcontacts/sc_hist),
# the resolved scene values and the plugins' restart state as attributes. 3: contacts name
# their convex pieces (pga, pgb: joined blocks). 1 and 2 still read.
FORMAT_VERSION = 3
CONTACT_CK = select(CONTACT, checkpoint=True)
SUB_CK = select(SUB, checkpoint=True) + (SUB_HIST,)


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


def written_contacts(state) -> np.ndarray:
    """Which of this rank's contacts it writes (checkpoints, output): each contact once over
    all ranks, by the owner of its lower-gid free block. A contact across a subdomain boundary
    is held, identical, by both owners; this picks one copy."""
    b, c = state.blocks, state.contacts
    free = state.glob.fixed == 0
    owned = np.zeros(state.glob.n, bool)
    owned[b.gid[:state.n_owned]] = True
    return (owned[c.ga] & free[c.ga]) | (owned[c.gb] & free[c.gb] & ~free[c.ga])


def checkpoint_payload(state, extra_attrs: dict) -> tuple[dict, dict, dict, np.ndarray]:
    """This rank's share: (attrs, block rows {field: array, 'gid'}, contacts, nsub)."""
    b = state.blocks
    n = state.n_owned
    rows = {k: getattr(b, k)[:n] for k in CHECKPOINT}
    rows["gid"] = b.gid[:n]
    sel = state.contacts.select(written_contacts(state))
    contacts = {**sel.arrays, **sel.sub}
    attrs = {
        "pdem_format": FORMAT, "format_version": FORMAT_VERSION, "run_id": state.run_id,
        "step": state.step, "time": state.time, "dt": state.dt, "alpha": state.alpha,
        "ratio": state.ratio if np.isfinite(state.ratio) else -1.0,
        "n_blocks": state.glob.n, "n_ranks": state.comm.size, "scene": state.scene_yaml,
        "resolved": state.resolved.to_json(), **extra_attrs,
    }
    return attrs, rows, contacts, np.diff(sel.sc_start)


def write_checkpoint(path: str | os.PathLike, state, extra_attrs: dict | None = None) -> str:
    """Write the model state to ``path`` (collective). Returns the final path.

    ``extra_attrs``: the plugins' restart state (str/int/float values)."""
    comm = state.comm
    path = str(path)
    tmp = path + ".tmp"
    attrs, rows, contacts, nsub = checkpoint_payload(state, extra_attrs or {})
    parallel = comm.size > 1 and h5py.get_config().mpi
    if not parallel and comm.size > 1:
        parts = gather(comm, (rows, contacts, nsub))
        if comm.rank == 0:
            rows = {k: np.concatenate([p[0][k] for p in parts]) for k in rows}
            contacts = {k: np.concatenate([p[1][k] for p in parts]) for k in contacts}
            nsub = np.concatenate([p[2] for p in parts])
    counts = np.array([len(nsub), int(nsub.sum())])
    if parallel:
        all_counts = np.array(allgather(comm, counts))
        offs = all_counts.cumsum(0) - all_counts
        tot = all_counts.sum(0)
        off_c, off_s = offs[comm.rank]
        f = h5py.File(tmp, "w", driver="mpio", comm=comm)
    else:
        tot = counts
        off_c = off_s = 0
        f = h5py.File(tmp, "w") if comm.rank == 0 else None
    if f is not None:
        try:
            _fill(f, attrs, rows, contacts, nsub, counts, tot, off_c, off_s)
        except BaseException:
            # the previous checkpoint is untouched (it has another name); drop the partial temp
            # file. A parallel file is not closed here: closing is collective and the other
            # ranks may be elsewhere; the caller aborts the job.
            if not parallel:
                f.close()
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
        f.close()
    barrier(comm)
    if comm.rank == 0:
        os.replace(tmp, path)  # atomic: a reader sees the old or the complete new file
    barrier(comm)
    return path


def _fill(f, attrs, rows, contacts, nsub, counts, tot, off_c, off_s) -> None:
    """Attributes, blocks (rows = gid) and this rank's contacts into the open file."""
    for k, v in attrs.items():
        f.attrs[k] = v
    n_blocks = attrs["n_blocks"]
    order = np.argsort(rows["gid"], kind="stable")
    gid = rows["gid"][order]
    for k in CHECKPOINT:
        data = rows[k][order]
        d = f.create_dataset(f"blocks/{k}", (n_blocks, *data.shape[1:]), dtype=data.dtype)
        d.attrs["units"] = BLOCK_BY_NAME[k].units
        for a, z in _runs(gid):
            d[gid[a]:gid[a] + (z - a)] = data[a:z]
    groups = (("contacts", CONTACT_CK, 0, off_c), ("subcontacts", SUB_CK, 1, off_s))
    for group, fields, axis, off in groups:
        for fd in fields:
            shape = contacts[fd.name].shape[1:]
            d = f.create_dataset(f"{group}/{fd.name}", (int(tot[axis]), *shape),
                                 dtype=fd.dtype)
            if counts[axis]:
                d[off:off + counts[axis]] = contacts[fd.name]
    d = f.create_dataset("contacts/nsub", (int(tot[0]),), dtype=np.int64)
    if counts[0]:
        d[off_c:off_c + counts[0]] = nsub


def read_checkpoint(path: str | os.PathLike) -> dict:
    """Everything in a checkpoint (read by each rank; restart keeps what it needs):
    ``attrs``, ``blocks`` {field: (n_blocks, ...)} and ``contacts`` (a ContactStore)."""
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
        n_blocks = int(f.attrs["n_blocks"])
        # a field added after the file was written starts from zero (its declared start value)
        out["blocks"] = {k: f[f"blocks/{k}"][()] if f"blocks/{k}" in f else
                         np.zeros((n_blocks, *BLOCK_BY_NAME[k].shape), BLOCK_BY_NAME[k].dtype)
                         for k in CHECKPOINT}
        nsub = f["contacts/nsub"][()]
        arrays = {fd.name: f[f"contacts/{fd.name}"][()] for fd in CONTACT_CK
                  if f"contacts/{fd.name}" in f}
        for piece, block in (("pga", "ga"), ("pgb", "gb")):
            if piece not in arrays and block in arrays:  # format <= 2: every block one piece
                arrays[piece] = arrays[block].copy()
        missing = [fd.name for fd in CONTACT_CK if fd.name not in arrays
                   and fd.name not in CONTACT_ADDED]
        if missing:
            raise ValueError(f"{path}: contacts/{missing[0]} missing: not a complete checkpoint")
        for fd in CONTACT:  # rows are local: reassigned when the contacts are distributed
            arrays.setdefault(fd.name, np.zeros((len(nsub), *fd.shape), fd.dtype))
        sub = {fd.name: f[f"subcontacts/{fd.name}"][()] for fd in SUB_CK
               if f"subcontacts/{fd.name}" in f}
        sub.setdefault("sc_hist", np.zeros((int(nsub.sum()), 0)))  # format 1: no law history
    _validate(path, out["attrs"], out["blocks"], arrays, sub, nsub)
    out["contacts"] = ContactStore(arrays, sub, csr.starts(nsub))
    return out


# what a restart reads from the attributes, and the values it can continue from
_ATTRS = {"step": lambda v: v >= 0, "time": math.isfinite, "dt": lambda v: math.isfinite(v) and v > 0,
          "alpha": lambda v: math.isfinite(v) and v >= 0, "ratio": math.isfinite,
          "n_blocks": lambda v: v >= 0}
# kinematic fields every format has had: a checkpoint without them cannot continue
_CORE = ("x", "q", "v", "w")


def _validate(path, attrs, blocks, arrays, sub, nsub) -> None:
    """A damaged or foreign checkpoint is refused with what is wrong (found by the fuzz:
    missing attributes gave KeyError tracebacks, a zero dt a ZeroDivisionError, short datasets
    IndexErrors deep in the restart)."""
    for key, ok in _ATTRS.items():
        if key not in attrs:
            raise ValueError(f"{path}: attribute {key!r} missing: not a complete checkpoint")
        try:
            v = float(attrs[key])
        except (TypeError, ValueError):
            raise ValueError(f"{path}: attribute {key!r} is {attrs[key]!r}, not a number") from None
        if not ok(v):
            raise ValueError(f"{path}: attribute {key!r} = {v!r} cannot be continued from")
    for key in ("scene", "run_id"):
        if not isinstance(attrs.get(key), str):
            raise ValueError(f"{path}: attribute {key!r} missing: not a complete checkpoint")
    n = int(attrs["n_blocks"])
    for k, a in blocks.items():
        want = (n, *BLOCK_BY_NAME[k].shape)
        if a.shape != want:
            raise ValueError(f"{path}: blocks/{k} has shape {a.shape}, expected {want}")
    for k in _CORE:
        if not np.isfinite(blocks[k]).all() or (k == "q" and n and
                                                 not (np.abs(blocks[k]).sum(axis=1) > 0).all()):
            raise ValueError(f"{path}: blocks/{k} is missing or not finite: cannot continue")
    nc, ns = len(nsub), int(np.sum(nsub))
    if (nsub < 0).any():
        raise ValueError(f"{path}: contacts/nsub has negative counts")
    for k, a in arrays.items():
        if len(a) != nc:
            raise ValueError(f"{path}: contacts/{k} has {len(a)} rows, contacts/nsub {nc}")
    for fd in SUB_CK:
        if fd.name not in sub:  # sc_hist alone may be absent (format 1), set by the reader
            raise ValueError(f"{path}: subcontacts/{fd.name} missing: not a complete checkpoint")
    for k, a in sub.items():
        if len(a) != ns:
            raise ValueError(f"{path}: subcontacts/{k} has {len(a)} rows, expected {ns}")
    for k in ("ga", "gb"):
        if nc and not ((arrays[k] >= 0) & (arrays[k] < n)).all():
            raise ValueError(f"{path}: contacts/{k} names blocks outside 0..{n - 1}")


def prune(prefix: str, keep: int, comm) -> None:
    """Keep the newest ``keep`` checkpoints ``{prefix}-*.h5`` (rank 0 deletes)."""
    if comm.rank != 0:
        return
    p = Path(prefix)
    files = sorted(p.parent.glob(p.name + "-*.h5"))
    for old in files[:-keep]:
        old.unlink(missing_ok=True)
