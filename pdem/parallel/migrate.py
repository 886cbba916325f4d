"""Ownership migration and ghost rebuild (collective, at start, restart and when blocks moved).

1. Every owned block goes to the rank whose brick holds its centroid, with its dynamic state;
   the contacts of a migrating free block (with their full history: common plane, sub-contacts,
   shear forces, slip state) go with it.
2. Each rank's interest box is the box around its owned free blocks, padded by CTOL/2 and
   enlarged by ``margin``; a block whose padded bounding box reaches into another rank's interest
   box becomes a ghost there. Between two rebuilds no block moves more than margin/2 (the
   solver triggers a rebuild before that), so every pair that can come within CTOL of an owned
   free block has both blocks on the rank.
3. A rank keeps the contacts in which it owns a free block: those it computes every step.

The messages here are rare (not per step) and ragged, so they use mpi4py's pickle-based
``alltoall`` of dicts of numpy arrays.
"""

from __future__ import annotations

import numpy as np

from ..model.blocks import BlockStore, take_rows
from ..model.contacts import ContactStore
from ..model.fields import HALO, MIGRATE
from .halo import Halo
from .mpi import allgather, alltoall


def _boxes(x, radius, pad):
    r = (radius + pad)[:, None]
    return x - r, x + r


def contacts_needed(contacts: ContactStore, owned_free_gids: np.ndarray) -> np.ndarray:
    """Mask of contacts in which this rank owns a free block."""
    return np.isin(contacts.ga, owned_free_gids) | np.isin(contacts.gb, owned_free_gids)


def _merge_contacts(parts: list[ContactStore]) -> ContactStore:
    """Union by key (duplicates are identical copies: keep the first), sorted by key."""
    merged = ContactStore.concatenate(parts, parts[0].hist_width)
    _, first = np.unique(merged.keys(), return_index=True)  # sorted by key, first occurrence
    return merged.take(first)


def rebuild(comm, decomp, glob: BlockStore, owned_gids: np.ndarray, state: dict,
            contacts: ContactStore, pad: float, margin: float, halo_fields=HALO):
    """Redistribute blocks and contacts; returns (blocks, n_owned, contacts, halo).

    ``owned_gids``/``state``: the blocks this rank owns now and their MIGRATE arrays;
    ``contacts``: this rank's contacts (``ga``, ``gb`` valid; rows are reassigned here);
    ``halo_fields``: what the halo sends each step (pdem.model.fields.halo_fields).
    """
    size, rank = comm.size, comm.rank
    owned_gids = np.asarray(owned_gids, np.int64)
    fixed = glob.fixed.astype(bool)
    # 1. migration of owned blocks and the contacts of the free ones that leave
    dest = decomp.owner_of(state["x"]) if len(owned_gids) else np.zeros(0, np.int64)
    out = []
    for r in range(size):
        go = dest == r
        msg = {"gid": owned_gids[go], **{k: state[k][go] for k in MIGRATE}}
        if r != rank and contacts.n:
            leaving_free = owned_gids[go & ~fixed[owned_gids]]
            msg["contacts"] = contacts.select(contacts_needed(contacts, leaving_free))
        out.append(msg)
    got = alltoall(comm, out)
    gids = np.concatenate([m["gid"] for m in got])
    order = np.argsort(gids, kind="stable")
    gids = gids[order]
    new_state = {k: np.concatenate([m[k] for m in got])[order] for k in MIGRATE}
    parts = [contacts] + [m["contacts"] for m in got if "contacts" in m]
    merged = _merge_contacts(parts)

    # 2. interest boxes and ghosts
    free_now = gids[~fixed[gids]]
    if len(free_now):
        sel = ~fixed[gids]
        lo, hi = _boxes(new_state["x"][sel], glob.radius[free_now], pad)
        box = np.concatenate([lo.min(0) - margin, hi.max(0) + margin])
    else:
        box = np.array([np.inf] * 3 + [-np.inf] * 3)
    boxes = np.array(allgather(comm, box))
    blo, bhi = _boxes(new_state["x"], glob.radius[gids], pad)
    out = []
    for r in range(size):
        if r == rank:
            out.append(None)
            continue
        hit = np.all(blo <= boxes[r, 3:], axis=1) & np.all(bhi >= boxes[r, :3], axis=1)
        out.append({"gid": gids[hit], **{k: new_state[k][hit] for k in MIGRATE}})
    got = alltoall(comm, out)
    ghost_parts = [(r, m) for r, m in enumerate(got) if m is not None and len(m["gid"])]
    g_gids = np.concatenate([m["gid"] for _, m in ghost_parts]) if ghost_parts else np.zeros(0, np.int64)
    g_from = np.concatenate([np.full(len(m["gid"]), r) for r, m in ghost_parts]) if ghost_parts \
        else np.zeros(0, np.int64)
    g_order = np.argsort(g_gids, kind="stable")
    g_gids, g_from = g_gids[g_order], g_from[g_order]
    g_state = {k: (np.concatenate([m[k] for _, m in ghost_parts])[g_order] if ghost_parts
                   else np.zeros((0, *state[k].shape[1:]))) for k in MIGRATE}

    # 3. the local store: owned rows first, then ghosts, each in gid order
    all_gids = np.concatenate([gids, g_gids])
    owned = np.concatenate([np.ones(len(gids), np.uint8), np.zeros(len(g_gids), np.uint8)])
    blocks = take_rows(glob, all_gids, owned)
    for k in MIGRATE:
        getattr(blocks, k)[:] = np.concatenate([new_state[k], g_state[k]])

    # 4. contacts this rank computes, rows renumbered
    needed = contacts_needed(merged, free_now)
    mine = merged.select(needed)
    row_of = np.argsort(all_gids, kind="stable")
    sorted_gids = all_gids[row_of]
    for side, g in (("ia", "ga"), ("ib", "gb")):
        pos = np.searchsorted(sorted_gids, mine.arrays[g])
        if np.any(pos >= len(sorted_gids)) or np.any(sorted_gids[np.minimum(pos, len(sorted_gids) - 1)]
                                                     != mine.arrays[g]):
            raise RuntimeError("a contact's block is neither owned nor a ghost after the rebuild")
        mine.arrays[side] = row_of[pos]
    # the pieces in contact: the same piece ordinal within the block's local pieces
    for side, piece, g, pg in (("ia", "ka", "ga", "pga"), ("ib", "kb", "gb", "pgb")):
        ordinal = mine.arrays[pg] - glob.piece_start[mine.arrays[g]]
        mine.arrays[piece] = blocks.piece_start[mine.arrays[side]] + ordinal

    # 5. the per-step halo plan (free blocks only; fixed ghosts were sent once, above)
    send = {}
    for r, m in enumerate(out):
        if m is None:
            continue
        gi = m["gid"][~fixed[m["gid"]]]
        send[r] = np.searchsorted(gids, gi)  # owned rows are [0, n_owned) in gid order
    recv = {}
    n_owned = len(gids)
    for r in np.unique(g_from):
        rows = np.nonzero((g_from == r) & ~fixed[g_gids])[0] + n_owned
        recv[int(r)] = rows
    blocks.u_mig[:] = 0.0
    return blocks, n_owned, mine, Halo(comm, send, recv, halo_fields)
