"""The joint state of the run output: the flat ``contacts/*`` and ``subcontacts/*`` series,
their snapshot offsets, ``xdmf/index`` and each snapshot's views (:mod:`pdem.io.joints`)."""

from __future__ import annotations

import numpy as np

from . import joints
from .h5core import H5Core, add_range_view
from .xdmf import CONTACT_VIEWED, SUB_VIEWED, view_path

__all__ = ["ContactSeries", "CONTACT_CHUNK"]

CONTACT_CHUNK = 1024  # rows per chunk of the flat contact and sub-contact datasets


class ContactSeries:
    """Contacts and sub-contacts, each rank writing those whose block A lies in its gid range.

    ``n_contacts``, ``n_subs``: per snapshot, the totals over the ranks (the XDMF sidecars').
    """

    def __init__(self, core: H5Core, n_blocks: int) -> None:
        self.core, self.n_blocks = core, n_blocks
        self.n_contacts: list[int] = []  # per snapshot, contacts and sub-contacts
        self.n_subs: list[int] = []
        self.bases = {"contacts": 0, "subcontacts": 0}  # rows written so far
        self.pool = 0  # length of xdmf/index (0, 1, 2, ...): the grids' Polyvertex ids

    def create(self, joint_names) -> None:
        """The root attribute ``joint_names``, the flat contact and sub-contact series and their
        snapshot offsets (IO ranks)."""
        core, f = self.core, self.core.f
        f.attrs["joint_names"] = [str(j) for j in (joint_names or [])] or [""]
        for group, series in (("contacts", joints.CONTACT_SERIES),
                              ("subcontacts", joints.SUB_SERIES)):
            off = f.create_dataset(f"{group}/offset", (1,), maxshape=(None,), chunks=(1024,),
                                   dtype=np.int64)
            core.write(off, (0,), np.zeros(1, np.int64) if core.comm.rank == 0 else None)
            off.attrs["doc"] = f"snapshot i is rows offset[i] .. offset[i+1]-1 of {group}/*"
            for c in series:
                d = f.create_dataset(
                    f"{group}/{c.name}", (0, *c.shape), maxshape=(None, *c.shape),
                    chunks=(CONTACT_CHUNK, *c.shape), dtype=c.dtype, compression="gzip",
                    compression_opts=4, shuffle=True)
                d.attrs["units"] = c.units
                d.attrs["doc"] = c.doc
        f["contacts/state"].attrs["names"] = list(joints.STATE_NAMES)
        f.create_dataset("xdmf/index", (0,), maxshape=(None,), chunks=(CONTACT_CHUNK,),
                         dtype=np.int64)

    def pack(self, contacts: dict | None) -> tuple[np.ndarray, np.ndarray]:
        """This rank's contacts and sub-contacts as float64 rows (``ValueError`` if bad)."""
        if contacts is None:
            return np.zeros((0, joints.C_WIDTH)), np.zeros((0, joints.S_WIDTH))
        crows = joints.pack(contacts, joints.CONTACT_COLS, joints.C_AT, joints.C_WIDTH)
        srows = joints.pack(contacts["sub"], joints.SUB_COLS, joints.S_AT, joints.S_WIDTH)
        nsub = joints.col(crows, joints.C_AT, "n_sub")
        if (nsub < 0).any() or nsub.sum() != len(srows):
            raise ValueError(f"write_snapshot: contacts n_sub sums to {nsub.sum()}, "
                             f"{len(srows)} sub-contacts given")
        block = joints.col(crows, joints.C_AT, "block")
        if len(block) and (block.min() < 0 or block.max() >= self.n_blocks):
            raise ValueError(f"write_snapshot: contact blocks outside [0, {self.n_blocks})")
        return crows, srows

    def assemble(self, crows, srows) -> tuple[np.ndarray, np.ndarray]:
        """Each contact (and its sub-contacts) to the rank whose gid range holds block A: piece
        gids are numbered block by block, so rank r's keys all precede rank r+1's; then sorted
        by key. Raises ``ValueError`` on every rank if a contact came twice."""
        core = self.core
        ga = joints.col(crows, joints.C_AT, "block")[:, 0].astype(np.int64)
        dest = np.searchsorted(core.bounds, ga, side="right") - 1
        nsub = joints.col(crows, joints.C_AT, "n_sub").astype(np.int64)
        (crows,) = core.exchange(dest, crows)
        (srows,) = core.exchange(np.repeat(dest, nsub), srows)
        crows, srows = joints.sort_contacts(crows, srows)
        piece = joints.col(crows, joints.C_AT, "piece")
        msg = None
        if len(piece) > 1:
            same = np.flatnonzero((piece[1:] == piece[:-1]).all(axis=1))
            if len(same):
                msg = (f"write_snapshot: contact {piece[same[0]].astype(int).tolist()} passed "
                       "twice (each contact must be passed by exactly one rank)")
        core.raise_if_any(msg)
        return crows, srows

    def count(self, crows, srows) -> tuple[int, int, int, int]:
        """Totals over the ranks and this rank's offsets: (n_c, n_s, off_c, off_s)."""
        comm = self.core.comm
        counts = np.array([len(crows), len(srows)], np.int64)
        every = np.array(comm.allgather(counts)).reshape(-1, 2)
        before = every[: comm.rank].sum(axis=0)
        tot = every.sum(axis=0)
        self.n_contacts.append(int(tot[0]))
        self.n_subs.append(int(tot[1]))
        return int(tot[0]), int(tot[1]), int(before[0]), int(before[1])

    def write(self, i: int, crows: np.ndarray, srows: np.ndarray) -> None:
        """Snapshot ``i``'s contacts: this rank's sorted slab of the flat series (collective),
        the offsets, and the views of the contact sidecars."""
        core, f = self.core, self.core.f
        n_c, n_s, off_c, off_s = self.count(crows, srows)
        cvals, svals = joints.reduce_contacts(crows, srows)
        root = core.comm.rank == 0
        for group, series, values, n, off in (
                ("contacts", joints.CONTACT_SERIES, cvals, n_c, off_c),
                ("subcontacts", joints.SUB_SERIES, svals, n_s, off_s)):
            offset = f[f"{group}/offset"]
            base = self.bases[group]
            offset.resize(i + 2, axis=0)
            core.write(offset, (i + 1,), np.array([base + n], np.int64) if root else None)
            for c in series:
                d = f[f"{group}/{c.name}"]
                d.resize(base + n, axis=0)
                data = np.asarray(values[c.name]).reshape(-1, *c.shape).astype(c.dtype)
                core.write(d, (base + off,) + (0,) * len(c.shape), data)
            self.bases[group] = base + n
        need = max(n_c, n_s)
        if need > self.pool:
            pool = f["xdmf/index"]
            pool.resize(need, axis=0)
            lo, hi = core.share(need - self.pool)
            core.write(pool, (self.pool + lo,), np.arange(self.pool + lo, self.pool + hi))
            self.pool = need
        for group, viewed, n in (("contacts", CONTACT_VIEWED, n_c),
                                 ("subcontacts", SUB_VIEWED, n_s)):
            if n == 0:
                continue
            hi = self.bases[group]
            for name in viewed:
                add_range_view(f, f"/{group}/{name}", view_path(f"/{group}/{name}", i),
                               hi - n, hi)
            add_range_view(f, "/xdmf/index", view_path(f"/{group}/index", i), 0, n)
