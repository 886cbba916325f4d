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
import json
import math
import os
import uuid
from pathlib import Path

import h5py
import numpy as np

from ..deformable import grid_checkpoint
from ..model import csr
from ..model.contacts import ContactStore
from ..model.fields import (
    BLOCK_BY_NAME,
    CHECKPOINT,
    CONTACT,
    CONTACT_ADDED,
    SUB,
    SUB_GRID,
    SUB_HIST,
    select,
)
from ..mpi import allgather, barrier, gather
from .layout import even_share

FORMAT = "checkpoint"
# 2: contact rows (ia, ib) no longer stored, joint-law history columns (subcontacts/sc_hist),
# the resolved scene values and the plugins' restart state as attributes. 3: contacts name
# their convex pieces (pga, pgb: joined blocks). 4: narrower integers (sub-contact state bits
# uint8, contact types int8) and ``held`` with no columns in scenes without solve.inactive.
# 5: no sub-contact normal force (``sc_fn``: the law gives it from the stored state), int32
# contact gids (``ga gb pga pgb``).
# 1 to 4 still read (their integers cast to the fields' dtypes, ``held`` fitted to the scene,
# a stored ``sc_fn`` ignored).
FORMAT_VERSION = 5
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
    # zoned blocks: their grids' rows (collective: gathered to the one writer if needed)
    grid_rows = None if state.grids is None else grid_checkpoint.checkpoint_rows(state.grids, comm, parallel)
    if f is not None:
        try:
            _fill(f, attrs, rows, contacts, nsub, counts, tot, off_c, off_s)
            if grid_rows is not None:
                grid_checkpoint.write(f, grid_rows, comm.rank)
            elements = state.reinforcement
            if elements is not None and elements.installed:  # (every rank holds them alike)
                g = f.create_group("reinforcement")
                g.attrs["installed"] = json.dumps(elements.installed)
                for k, v in elements.saved().items():
                    g.create_dataset(k, data=v)
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
    # the zoned blocks' sub-contact columns, in scenes with zoned blocks only
    grid = (SUB_GRID,) if "sc_grid" in contacts else ()
    groups = (("contacts", CONTACT_CK, 0, off_c), ("subcontacts", SUB_CK + grid, 1, off_s))
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


# bytes (as stored) of a batch of contacts that a restart reads and sends before the next
READ_BATCH = 4 << 20

# rows between two wanted ones that a read takes along rather than starting a new read
READ_GAP = 256


def _read_rows(dset, rows: np.ndarray) -> np.ndarray:
    """Rows ``rows`` (sorted, unique) of a dataset: one slice read per run of rows, runs closer
    than READ_GAP joined (a hyperslab read each, not a point selection per row)."""
    if len(rows) == 0:
        return np.zeros((0, *dset.shape[1:]), dset.dtype)
    if len(rows) == dset.shape[0]:
        return dset[()]
    if int(rows[-1]) - int(rows[0]) + 1 == len(rows):  # a range: one slice, not copied again
        return dset[int(rows[0]):int(rows[-1]) + 1]
    breaks = np.nonzero(np.diff(rows) > READ_GAP)[0] + 1
    parts = []
    for chunk in np.split(rows, breaks):
        lo, hi = int(chunk[0]), int(chunk[-1]) + 1
        parts.append(dset[lo:hi][chunk - lo])
    return np.concatenate(parts)


def _widened(stored: tuple, want: tuple) -> bool:
    """Whether a stored field is a declared one that has gained columns since the file was
    written (the block ``work`` had 9 before the quiet faces' column)."""
    return (len(stored) == len(want) == 2 and stored[0] == want[0]
            and stored[1] < want[1])


def _widen(a: np.ndarray, shape: tuple) -> np.ndarray:
    """Rows of a widened field (:func:`_widened`) with its new columns zero (their start)."""
    if a.shape[1:] == tuple(shape):
        return a
    out = np.zeros((len(a), *shape), a.dtype)
    out[:, :a.shape[1]] = a
    return out


class CheckpointReader:
    """An open checkpoint: attributes checked at opening, rows read by selection, so that a
    rank reads the rows of the blocks and contacts it will hold (``ModelState.restore``).
    Opened collectively with the mpio driver when h5py has it and ``comm`` has several ranks
    (each rank then reads its own rows), else by each rank on its own. ``by_share``: the
    contacts are read in contiguous shares (:meth:`contact_share`, :meth:`contact_range`), so
    the sub-contact counts of every contact are not read at opening (their checks are the
    shares')."""

    def __init__(self, path: str | os.PathLike, comm=None, by_share: bool = False):
        self.path = Path(path)
        self.by_share = by_share
        if not self.path.exists():
            raise FileNotFoundError(f"no checkpoint at {self.path}")
        parallel = comm is not None and comm.size > 1 and h5py.get_config().mpi
        try:
            self.f = h5py.File(self.path, "r", driver="mpio", comm=comm) if parallel \
                else h5py.File(self.path, "r")
        except OSError as exc:
            raise ValueError(f"{self.path} is not a readable HDF5 file ({exc})") from None
        try:
            self._check()
        except BaseException:
            self.f.close()
            raise

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.f.close()

    def _check(self) -> None:
        f = self.f
        if f.attrs.get("pdem_format") != FORMAT:
            raise ValueError(f"{self.path} is not a pdem checkpoint")
        if int(f.attrs["format_version"]) > FORMAT_VERSION:
            raise ValueError(f"{self.path}: checkpoint format {int(f.attrs['format_version'])} "
                             f"is newer than this pdem reads ({FORMAT_VERSION})")
        self.attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
        _validate_attrs(self.path, self.attrs)
        self.n_blocks = int(self.attrs["n_blocks"])
        for k in CHECKPOINT:
            want = (self.n_blocks, *BLOCK_BY_NAME[k].shape)
            if f"blocks/{k}" in f and f[f"blocks/{k}"].shape != want \
                    and not _widened(f[f"blocks/{k}"].shape, want):
                raise ValueError(f"{self.path}: blocks/{k} has shape {f[f'blocks/{k}'].shape}, "
                                 f"expected {want}")
        for k in _CORE:
            if f"blocks/{k}" not in f:
                raise ValueError(f"{self.path}: blocks/{k} is missing or not finite: cannot "
                                 "continue")
        if "contacts/nsub" not in f:
            raise ValueError(f"{self.path}: contacts/nsub missing: not a complete checkpoint")
        self.n_contacts = int(f["contacts/nsub"].shape[0])
        self.nsub = None if self.by_share else self._counts(0, self.n_contacts)
        names = {fd.name for fd in CONTACT_CK if f"contacts/{fd.name}" in f}
        for piece, block in (("pga", "ga"), ("pgb", "gb")):
            if piece not in names and block in names:  # format <= 2: every block one piece
                names.add(piece)
        missing = [fd.name for fd in CONTACT_CK if fd.name not in names
                   and fd.name not in CONTACT_ADDED]
        if missing:
            raise ValueError(f"{self.path}: contacts/{missing[0]} missing: not a complete "
                             "checkpoint")
        nc = self.n_contacts
        for fd in CONTACT_CK:
            if f"contacts/{fd.name}" in f and len(f[f"contacts/{fd.name}"]) != nc:
                raise ValueError(f"{self.path}: contacts/{fd.name} has "
                                 f"{len(f[f'contacts/{fd.name}'])} rows, contacts/nsub {nc}")
        # by shares, the counts' sum is checked against these rows once summed (the restart)
        self.n_sub = int(self.nsub.sum()) if self.nsub is not None else None
        for fd in SUB_CK:
            if f"subcontacts/{fd.name}" not in f:
                if fd.name == "sc_hist":  # format 1: no law history
                    continue
                raise ValueError(f"{self.path}: subcontacts/{fd.name} missing: not a complete "
                                 "checkpoint")
            rows = len(f[f"subcontacts/{fd.name}"])
            if self.n_sub is None:
                self.n_sub = rows
            if rows != self.n_sub:
                raise ValueError(f"{self.path}: subcontacts/{fd.name} has {rows} rows, expected "
                                 f"{self.n_sub}")

    def _counts(self, c0: int, c1: int) -> np.ndarray:
        """The sub-contact counts of contacts ``c0:c1``, checked."""
        nsub = self.f["contacts/nsub"][c0:c1]
        if (nsub < 0).any():
            raise ValueError(f"{self.path}: contacts/nsub has negative counts")
        return nsub

    def block_column(self, k: str) -> np.ndarray:
        """Field ``k`` of every block (a field added after the file was written: zeros)."""
        return self.block_rows(np.arange(self.n_blocks), (k,))[k]

    def block_rows(self, gids: np.ndarray, fields=CHECKPOINT) -> dict[str, np.ndarray]:
        """Fields of blocks ``gids`` (sorted); a field added after the file was written
        starts from zero (its declared start value). Non-finite poses are refused."""
        f = self.f
        out = {k: _widen(_read_rows(f[f"blocks/{k}"], gids), BLOCK_BY_NAME[k].shape)
               if f"blocks/{k}" in f else
               np.zeros((len(gids), *BLOCK_BY_NAME[k].shape), BLOCK_BY_NAME[k].dtype)
               for k in fields}
        for k in _CORE:
            if k in out and (not np.isfinite(out[k]).all() or (
                    k == "q" and len(gids) and not (np.abs(out[k]).sum(axis=1) > 0).all())):
                raise ValueError(f"{self.path}: blocks/{k} is missing or not finite: cannot "
                                 "continue")
        return out

    def contact_column(self, k: str) -> np.ndarray:
        """``ga`` or ``gb`` of every contact, checked to name blocks of the model."""
        a = self.f[f"contacts/{k}"][()]
        if len(a) and not ((a >= 0) & (a < self.n_blocks)).all():
            raise ValueError(f"{self.path}: contacts/{k} names blocks outside "
                             f"0..{self.n_blocks - 1}")
        return a

    def _declared(self, name: str, fd, a: np.ndarray) -> np.ndarray:
        """``a`` in field ``fd``'s dtype (older files: int64 state bits and contact types);
        a value the dtype cannot hold is refused (a damaged file)."""
        if a.dtype == fd.dtype:
            return a
        out = a.astype(fd.dtype)
        if not np.array_equal(out, a):
            raise ValueError(f"{self.path}: {name} holds values outside {np.dtype(fd.dtype)}")
        return out

    def contacts(self, rows: np.ndarray) -> ContactStore:
        """Contacts ``rows`` (sorted) with their sub-contacts, in the fields' dtypes (``held``
        as stored: the restart fits it to the scene, ContactStore.with_held)."""
        sub_rows, start = csr.take(csr.starts(self.nsub), rows)
        return self._contact_store(rows, sub_rows, start)

    def contact_share(self, rank: int, size: int) -> tuple[int, int, np.ndarray]:
        """Rank ``rank``'s contiguous share ``[c0, c1)`` of the contact rows and their
        sub-contact counts (checked): what it reads of the contacts (:meth:`contact_range`)."""
        c0, c1 = even_share(rank, size, self.n_contacts)
        return c0, c1, self._counts(c0, c1)

    def contact_blocks(self, c0: int, c1: int) -> dict[str, np.ndarray]:
        """The blocks and pieces of contacts ``c0:c1`` (``ga gb pga pgb``), the blocks checked
        to be the model's: what decides where the contacts go, and their order there, before
        the rest is read (:meth:`contact_range`)."""
        rows = np.arange(c0, c1)
        out = {}
        for fd in CONTACT_CK:
            if fd.name in ("ga", "gb", "pga", "pgb") and f"contacts/{fd.name}" in self.f:
                out[fd.name] = self._declared(f"contacts/{fd.name}", fd,
                                              _read_rows(self.f[f"contacts/{fd.name}"], rows))
        for k in ("ga", "gb"):
            a = out[k]
            if len(a) and not ((a >= 0) & (a < self.n_blocks)).all():
                raise ValueError(f"{self.path}: contacts/{k} names blocks outside "
                                 f"0..{self.n_blocks - 1}")
        for piece, block in (("pga", "ga"), ("pgb", "gb")):
            if piece not in out:  # format <= 2: every block one piece
                out[piece] = out[block].copy()
        return out

    def contact_batches(self, nsub: np.ndarray, budget: int | None = None) -> np.ndarray:
        """Batches of a share of contacts (sub-contact counts ``nsub``) of about ``budget``
        bytes each as stored: their first rows and the end (a restart reads and sends its
        share batch by batch, pdem.parallel.migrate.route_contacts)."""
        def row_bytes(group, fields):
            return sum(self.f[f"{group}/{fd.name}"].dtype.itemsize
                       * int(np.prod(self.f[f"{group}/{fd.name}"].shape[1:], dtype=np.int64))
                       for fd in fields if f"{group}/{fd.name}" in self.f)

        budget = budget or READ_BATCH
        per = row_bytes("contacts", CONTACT_CK) + row_bytes("subcontacts", SUB_CK + (SUB_GRID,)
                                                            ) * nsub.astype(np.int64)
        end = np.cumsum(per)
        k = max(1, -(-int(end[-1]) // budget)) if len(end) else 1
        cuts = np.searchsorted(end, budget * np.arange(1, k), side="right")
        return np.concatenate([[0], cuts, [len(nsub)]]).astype(np.int64)

    def contact_range(self, c0: int, c1: int, nsub: np.ndarray, s0: int,
                      known: dict | None = None) -> ContactStore:
        """Contacts ``c0:c1`` (sub-contact counts ``nsub``, the first of their sub-contacts at
        row ``s0``): one slice of each dataset; their blocks are checked to be the model's.
        ``known``: columns already read (:meth:`contact_blocks`), not read again."""
        rows = np.arange(c0, c1)
        start = csr.starts(nsub)
        part = self._contact_store(rows, np.arange(s0, s0 + int(start[-1])), start, known)
        for k in ("ga", "gb"):
            a = part.arrays[k]
            if len(a) and not ((a >= 0) & (a < self.n_blocks)).all():
                raise ValueError(f"{self.path}: contacts/{k} names blocks outside "
                                 f"0..{self.n_blocks - 1}")
        return part

    def _contact_store(self, rows, sub_rows, start, known=None) -> ContactStore:
        f = self.f
        known = known or {}
        arrays = {fd.name: known[fd.name] if fd.name in known else
                  self._declared(f"contacts/{fd.name}", fd,
                                 _read_rows(f[f"contacts/{fd.name}"], rows))
                  for fd in CONTACT_CK if f"contacts/{fd.name}" in f}
        for piece, block in (("pga", "ga"), ("pgb", "gb")):
            if piece not in arrays:  # format <= 2: every block one piece
                arrays[piece] = arrays[block].copy()
        for fd in CONTACT:  # rows are local: reassigned when the contacts are distributed
            arrays.setdefault(fd.name, np.zeros((len(rows), *fd.shape), fd.dtype))
        sub = {fd.name: self._declared(f"subcontacts/{fd.name}", fd,
                                       _read_rows(f[f"subcontacts/{fd.name}"], sub_rows))
               for fd in SUB_CK + (SUB_GRID,) if f"subcontacts/{fd.name}" in f}
        sub.setdefault("sc_hist", np.zeros((len(sub_rows), 0)))  # format 1: no law history
        return ContactStore(arrays, sub, start)


def read_checkpoint(path: str | os.PathLike) -> dict:
    """Everything in a checkpoint, read by one process (tools, tests; a restart reads each
    rank's share, :class:`CheckpointReader`): ``attrs``, ``blocks`` {field: (n_blocks, ...)}
    and ``contacts`` (a ContactStore)."""
    with CheckpointReader(path) as r:
        out = {"attrs": r.attrs, "blocks": r.block_rows(np.arange(r.n_blocks))}
        for k in ("ga", "gb"):
            r.contact_column(k)
        out["contacts"] = r.contacts(np.arange(len(r.nsub)))
    out["path"] = str(path)  # groups read at the restore (zoned blocks' grids)
    return out


def read_elements(path: str | os.PathLike) -> tuple[list[str], dict[str, np.ndarray]] | None:
    """A checkpoint's reinforcement (pdem.reinforce: the installed entries and their state),
    None if it holds none; read whole by every rank (the elements are few)."""
    with h5py.File(path, "r") as f:
        g = f.get("reinforcement")
        if g is None:
            return None
        return json.loads(g.attrs["installed"]), {k: g[k][()] for k in g}


def open_checkpoint(path: str | os.PathLike) -> dict:
    """A checkpoint's attributes, checked (its rows are read by ``ModelState.restore``,
    each rank its own, so none of them is read here): ``attrs`` and ``path``."""
    with CheckpointReader(path, by_share=True) as r:
        return {"attrs": r.attrs, "path": str(path)}


# what a restart reads from the attributes, and the values it can continue from
_ATTRS = {"step": lambda v: v >= 0, "time": math.isfinite, "dt": lambda v: math.isfinite(v) and v > 0,
          "alpha": lambda v: math.isfinite(v) and v >= 0, "ratio": math.isfinite,
          "n_blocks": lambda v: v >= 0}
# kinematic fields every format has had: a checkpoint without them cannot continue
_CORE = ("x", "q", "v", "w")


def _validate_attrs(path, attrs) -> None:
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


def prune(prefix: str, keep: int, comm) -> None:
    """Keep the newest ``keep`` checkpoints ``{prefix}-*.h5`` (rank 0 deletes)."""
    if comm.rank != 0:
        return
    p = Path(prefix)
    files = sorted(p.parent.glob(p.name + "-*.h5"))
    for old in files[:-keep]:
        old.unlink(missing_ok=True)
