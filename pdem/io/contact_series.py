"""The joint state of the run output: the flat ``contacts/*`` and ``subcontacts/*`` series,
their snapshot offsets, ``xdmf/index`` and each snapshot's views (:mod:`pdem.io.joints`)."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from mpi4py import MPI

from ..model import csr
from . import joints
from .h5core import H5Core, add_range_view
from .xdmf import CONTACT_VIEWED, SUB_VIEWED, view_path

__all__ = ["ContactSeries", "ContactSource", "DictContacts", "CONTACT_CHUNK", "ROUND_ROWS",
           "contact_chunk"]

# rows per chunk of the flat contact and sub-contact datasets: from CONTACT_CHUNK[0] for a small
# scene to CONTACT_CHUNK[1] (contact_chunk). Each deflated chunk written leaves HDF5 and MPI-IO
# holding heap: 64,000 cubes on 2 ranks (~19,300 chunks of 1,024 rows a snapshot) kept ~10 MB
# more a rank than with 16,384-row chunks, whose file was 6 % smaller (better deflate) and whose
# snapshots 18 % quicker; a small scene's chunks mostly hold a snapshot's few rows, and large
# ones there only grow the file (the 1,000-block pile: 9.4 MB -> 11.6 MB at 16,384 rows).
CONTACT_CHUNK = (1024, 16384)
# rows (contacts and sub-contacts) a rank receives and writes per round of a snapshot's
# contacts: what the writer holds at once is bounded by this, not by the rank's contacts (about
# twice a round's packed rows, ~100 bytes a row: ~7 MB; 64,000 cubes on 2 ranks, 8 rounds a
# snapshot: 1 << 16 held ~8 MB more a rank for ~15% less snapshot time, bench/output_memory.py)
ROUND_ROWS = 1 << 15


def contact_chunk(n_blocks: int) -> int:
    """Rows per chunk of the contact series of a scene of ``n_blocks``: the power of two at or
    above a quarter of the blocks (a cube stack has ~12 contacts and ~21 sub-contacts a block),
    within :data:`CONTACT_CHUNK`."""
    lo, hi = CONTACT_CHUNK
    return int(min(hi, max(lo, 1 << max(0, (max(n_blocks, 1) // 4 - 1).bit_length()))))


class ContactSource(Protocol):
    """A rank's contacts for one snapshot, made row by row as the writer streams them:
    ``block_a`` (k,) the gid of each contact's block A, ``n_sub`` (k,) its sub-contacts,
    ``n_subs`` their total as given (None: not known before ``rows``), and ``rows(idx)`` the
    contacts ``idx`` (in that order: grouped by the rank they go to) in
    :meth:`pdem.io.writer.OutputWriter.write_snapshot`'s dict format, their sub-contacts in
    contact order."""

    block_a: np.ndarray
    n_sub: np.ndarray
    n_subs: int | None

    def rows(self, idx: np.ndarray) -> dict: ...


class DictContacts:
    """A :class:`ContactSource` of contacts passed whole (a dict; ``None``: none)."""

    def __init__(self, contacts: dict | None) -> None:
        self.d = contacts
        if contacts is None:
            self.block_a, self.n_sub, self.n_subs = np.zeros(0, np.int64), np.zeros(0, np.int64), 0
            return
        self.block_a = np.asarray(contacts["block"], np.int64).reshape(-1, 2)[:, 0]
        self.n_sub = np.asarray(contacts["n_sub"], np.int64).reshape(-1)
        self.n_subs = np.asarray(contacts["sub"]["point"]).size // 3

    def rows(self, idx: np.ndarray) -> dict:
        d = self.d
        if len(idx) == len(self.n_sub) and np.array_equal(idx, np.arange(len(idx))):
            return d  # every contact in order: the dict as given
        sub_idx, _ = csr.take(csr.starts(self.n_sub), idx)
        out = {k: np.asarray(v)[idx] for k, v in d.items() if k != "sub"}
        out["sub"] = {k: np.asarray(v)[sub_idx] for k, v in d["sub"].items()}
        return out


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
        chunk = contact_chunk(int(core.bounds[-1]))
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
                    chunks=(chunk, *c.shape), dtype=c.dtype, compression="gzip",
                    compression_opts=4, shuffle=True)
                d.attrs["units"] = c.units
                d.attrs["doc"] = c.doc
        f["contacts/state"].attrs["names"] = list(joints.STATE_NAMES)
        f.create_dataset("xdmf/index", (0,), maxshape=(None,), chunks=(chunk,),
                         dtype=np.int64)

    def prepare(self, contacts) -> ContactSource:
        """This rank's contacts as a :class:`ContactSource` (a dict is wrapped; ``None``: none),
        checked: block A in range, ``n_sub`` summing to the sub-contacts (``ValueError``)."""
        if contacts is None:
            return DictContacts(None)
        source = contacts if hasattr(contacts, "rows") else DictContacts(contacts)
        block_a = np.asarray(source.block_a, np.int64).reshape(-1)
        nsub = np.asarray(source.n_sub, np.int64).reshape(-1)
        if len(nsub) != len(block_a) or (nsub < 0).any() or (
                source.n_subs is not None and nsub.sum() != source.n_subs):
            raise ValueError(f"write_snapshot: contacts n_sub sums to {nsub.sum()}, "
                             f"{source.n_subs} sub-contacts given")
        if len(block_a) and (block_a.min() < 0 or block_a.max() >= self.n_blocks):
            raise ValueError(f"write_snapshot: contact blocks outside [0, {self.n_blocks})")
        return source

    def _rounds(self, block_a: np.ndarray, nsub: np.ndarray):
        """Plan a snapshot's streaming (collective): the round of each contact, the number of
        rounds, the totals over the ranks and this rank's first rows (n_c, n_s, off_c, off_s).

        Rank ``r`` receives the contacts whose block A lies in its gid range (``bounds``), in
        ``k`` rounds: round ``j`` brings those whose block A lies in the ``j``-th of ``k`` even
        parts of that range. Piece gids are numbered block by block, so the rounds' sorted
        rows follow one another in key order; ``k`` is chosen so that a rank receives about
        :data:`ROUND_ROWS` rows (contacts and sub-contacts) a round."""
        core = self.core
        comm, size, bounds = core.comm, core.comm.size, core.bounds
        dest = np.searchsorted(bounds, block_a, side="right") - 1
        counts = np.zeros((2, size), np.int64)
        counts[0] = np.bincount(dest, minlength=size)
        counts[1] = np.bincount(dest, weights=nsub, minlength=size).astype(np.int64)
        total = np.empty_like(counts)
        comm.Allreduce(counts, total, op=MPI.SUM)
        k = max(1, -(-int((total[0] + total[1]).max()) // ROUND_ROWS))
        lo, hi = bounds[:-1], bounds[1:]
        part_starts = (lo[:, None] + (hi - lo)[:, None] * np.arange(k)[None, :] // k).ravel()
        rounds = (np.searchsorted(part_starts, block_a, side="right") - 1) % k
        before = total[:, :comm.rank].sum(axis=1)
        return (rounds, k, int(total[0].sum()), int(total[1].sum()), int(before[0]),
                int(before[1]))

    def _round_rows(self, source: ContactSource, idx: np.ndarray) -> tuple[np.ndarray, ...]:
        """One round: the contacts ``idx`` of this rank's source, packed, sent to the rank of
        their block A, sorted by key (``ValueError`` on every rank if one came twice)."""
        core, msg = self.core, None
        crows = np.zeros((0, joints.C_WIDTH))
        srows = np.zeros((0, joints.S_WIDTH))
        # made in the order of the ranks they go to: the exchange sends them as they are, no
        # sorted copy of the round's rows (they are sorted by key once received)
        to = np.searchsorted(core.bounds, np.asarray(source.block_a).reshape(-1)[idx]
                             .astype(np.int64), side="right")
        idx = idx[np.argsort(to, kind="stable")]
        del to
        try:
            if len(idx):
                d = source.rows(idx)
                crows = joints.pack(d, joints.CONTACT_COLS, joints.C_AT, joints.C_WIDTH)
                srows = joints.pack(d["sub"], joints.SUB_COLS, joints.S_AT, joints.S_WIDTH)
                del d
                if joints.col(crows, joints.C_AT, "n_sub").sum() != len(srows):
                    raise ValueError("write_snapshot: contacts n_sub does not match the "
                                     "sub-contacts given")
        except ValueError as e:
            msg = str(e)
        core.raise_if_any(msg)
        ga = joints.col(crows, joints.C_AT, "block")[:, 0].astype(np.int64)
        dest = np.searchsorted(core.bounds, ga, side="right") - 1
        nsub = joints.col(crows, joints.C_AT, "n_sub").astype(np.int64)
        (crows,) = core.exchange(dest, crows)
        (srows,) = core.exchange(np.repeat(dest, nsub), srows)
        crows, srows = joints.sort_contacts(crows, srows)
        piece = joints.col(crows, joints.C_AT, "piece")
        if len(piece) > 1:
            same = np.flatnonzero((piece[1:] == piece[:-1]).all(axis=1))
            if len(same):
                msg = (f"write_snapshot: contact {piece[same[0]].astype(int).tolist()} passed "
                       "twice (each contact must be passed by exactly one rank)")
        core.raise_if_any(msg)
        return crows, srows

    def write(self, i: int, source: ContactSource) -> None:
        """Snapshot ``i``'s contacts (collective over every rank; the IO ranks write): this
        rank's sorted slab of the flat series, streamed in rounds of about
        :data:`ROUND_ROWS` rows (no rank holds more than a round's rows at once), the
        offsets, and the views of the contact sidecars."""
        core, f = self.core, self.core.f
        block_a = np.asarray(source.block_a, np.int64).reshape(-1)
        rounds, k, n_c, n_s, off_c, off_s = self._rounds(
            block_a, np.asarray(source.n_sub, np.int64).reshape(-1))
        del block_a
        groups = (("contacts", joints.CONTACT_SERIES, n_c, off_c),
                  ("subcontacts", joints.SUB_SERIES, n_s, off_s))
        if core.io:
            for group, series, n, _ in groups:
                for c in series:
                    f[f"{group}/{c.name}"].resize(self.bases[group] + n, axis=0)
        order = np.argsort(rounds, kind="stable")
        ends = np.searchsorted(rounds[order], np.arange(1, k + 1))
        del rounds
        done = [0, 0]  # rows of contacts and sub-contacts this rank has written
        for j in range(k):
            idx = np.sort(order[(ends[j - 1] if j else 0):ends[j]])
            crows, srows = self._round_rows(source, idx)
            cvals, svals = joints.reduce_contacts(crows, srows)
            del crows, srows
            for g, ((group, series, _, off), values) in enumerate(zip(groups, (cvals, svals),
                                                                      strict=True)):
                first = self.bases[group] + off + done[g]
                for c in series:
                    data = np.asarray(values[c.name]).reshape(-1, *c.shape).astype(c.dtype)
                    if core.io:
                        core.write(f[f"{group}/{c.name}"], (first,) + (0,) * len(c.shape), data)
                    done[g] += len(data) if c is series[0] else 0
            del cvals, svals
        self.n_contacts.append(n_c)
        self.n_subs.append(n_s)
        root = core.comm.rank == 0
        for group, _, n, _ in groups:
            self.bases[group] += n
            if core.io:
                offset = f[f"{group}/offset"]
                offset.resize(i + 2, axis=0)
                core.write(offset, (i + 1,),
                           np.array([self.bases[group]], np.int64) if root else None)
        if not core.io:
            return
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
