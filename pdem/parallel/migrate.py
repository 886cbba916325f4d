"""Ownership migration and ghost rebuild (collective, at start, restart and when blocks moved).

1. Every owned block goes to the rank whose brick holds its centroid, with its dynamic state
   and, to a rank that did not own it, its static data and body-frame geometry (a rank keeps
   the geometry of the blocks it holds only: memory O(N/P + ghosts), docs/parallel.md); the
   contacts of a migrating free block (with their full history: common plane, sub-contacts,
   shear forces, slip state) go with it.
2. Each rank's interest box is the box around its owned free blocks, padded by CTOL/2 and
   enlarged by ``margin``; a block whose padded bounding box reaches into another rank's interest
   box becomes a ghost there (with its geometry). Between two rebuilds no block moves more than margin/2 (the
   solver triggers a rebuild before that), so every pair that can come within CTOL of an owned
   free block has both blocks on the rank.
3. A rank keeps the contacts in which it owns a free block: those it computes every step.

The messages here are rare (not per step) and ragged, so they are mpi4py's pickles of dicts
of numpy arrays, sent to the ranks concerned only: no rank makes a message, an array or a loop
of size P (the rank count) in a migration (docs/parallel.md, Scaling). Blocks go to their new
owners by a sparse exchange (pdem.mpi.sparse_exchange: the receivers need not know who sends);
interest boxes are asked of the ranks whose cells lie within reach of a rank's blocks
(``decomp.ranks_near``), and the ghosts go to those of them whose box they reach.
"""

from __future__ import annotations

import numpy as np

from ..model import csr
from ..model.blocks import BlockStore, pack, take_rows, unpack, whole_message
from ..model.contacts import ContactStore
from ..model.fields import HALO, MIGRATE
from ..mpi import alltoall_rows, max_over_ranks, neighbour_exchange, sparse_exchange
from .halo import Halo


def _boxes(x, radius, pad):
    r = (radius + pad)[:, None]
    return x - r, x + r


# contacts are looked up in pieces of this many rows, so the lookups' temporaries (int64
# positions, masks) stay small beside the contacts: placing a restart's ~400,000 contacts a
# rank (64,000 cubes on 2 ranks) made ~15 MB of them at once, the restart's peak
LOOKUP_CHUNK = 1 << 16


def _chunks(n: int):
    return ((lo, min(lo + LOOKUP_CHUNK, n)) for lo in range(0, n, LOOKUP_CHUNK))


def _in_sorted(sorted_set: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``np.isin(values, sorted_set)`` for an ascending ``sorted_set``, chunk by chunk."""
    out = np.zeros(len(values), bool)
    if len(sorted_set) == 0:
        return out
    last = len(sorted_set) - 1
    for lo, hi in _chunks(len(values)):
        v = values[lo:hi]
        out[lo:hi] = sorted_set[np.minimum(np.searchsorted(sorted_set, v), last)] == v
    return out


def contacts_needed(contacts: ContactStore, owned_free_gids: np.ndarray) -> np.ndarray:
    """Mask of contacts in which this rank owns a free block."""
    free = np.sort(owned_free_gids)
    return _in_sorted(free, contacts.ga) | _in_sorted(free, contacts.gb)


def _merge_contacts(parts: list[ContactStore], free_gids: np.ndarray, drop: list[bool]
                    ) -> ContactStore:
    """The contacts of ``parts`` in which a block of ``free_gids`` is (:func:`contacts_needed`),
    each once (duplicates are identical copies: the first is kept), sorted by key. Column by
    column from the parts, each part's column dropped once taken where ``drop`` says so (the
    parts are not first concatenated whole and the union then selected: two copies of every
    contact on top of the parts were a restart's peak)."""
    given = parts
    drop = [d for p, d in zip(parts, drop, strict=True) if p.n]
    parts = [p for p in parts if p.n]
    if not parts:
        return given[0].take(np.zeros(0, np.int64))

    def column(columns: str, k: str, rows: np.ndarray) -> np.ndarray:
        cols = [getattr(p, columns).pop(k) if d else getattr(p, columns)[k]
                for p, d in zip(parts, drop, strict=True)]
        whole = cols[0] if len(cols) == 1 else np.concatenate(cols)  # one part: no copy
        del cols  # a dropped part's column is freed once taken
        return whole[rows]

    keys = np.concatenate([p.keys() for p in parts])
    # one part in key order, each contact once (a restart's, routed in key order)
    in_order = len(parts) == 1 and bool(np.all(keys[1:] > keys[:-1]))
    if in_order:
        first = None  # every row (made only if some are not needed)
        ga, gb = parts[0].arrays["ga"], parts[0].arrays["gb"]
    else:
        _, first = np.unique(keys, return_index=True)
        ga = np.concatenate([p.arrays["ga"] for p in parts])[first]
        gb = np.concatenate([p.arrays["gb"] for p in parts])[first]
    del keys
    free = np.sort(free_gids)
    needed = _in_sorted(free, ga) | _in_sorted(free, gb)
    del ga, gb
    if in_order and needed.all() and drop[0]:  # all of a part the caller gives up: its
        arrays, sub = parts[0].arrays, parts[0].sub  # columns are taken as they are
        parts[0].arrays, parts[0].sub = {}, {}
        return ContactStore(arrays, sub, parts[0].sc_start)
    first = np.nonzero(needed)[0] if first is None else first[needed]
    sub_rows, start = csr.take(csr.starts(np.concatenate([np.diff(p.sc_start) for p in parts])),
                               first)
    arrays = {k: column("arrays", k, first) for k in list(parts[0].arrays)}
    sub = {k: column("sub", k, sub_rows) for k in list(parts[0].sub)}
    return ContactStore(arrays, sub, start)


def hand_over_contacts(comm, decomp, blocks: BlockStore, contacts: ContactStore,
                       freed: np.ndarray) -> ContactStore:
    """Blocks that were fixed and are free now (``freed``: gids, every rank alike;
    collective). A fixed block's contacts were computed by the owners of the free blocks it
    touches only, so its own owner, which computes all of them from now on, holds just those
    it computed itself. Every other rank sends it those it holds, with their history (common
    plane, sub-contacts, shear forces, slip state): they go on as they would on one rank,
    instead of being found again, fresh, by the next search. Returns this rank's contacts
    with those received, each once, in key order; their rows (``ia``, ``ib``, ``ka``,
    ``kb``) are renumbered by the next :func:`rebuild`, which must follow.

    The owner of a freed block is the rank whose region holds its centroid: a fixed block
    never moves, and every rebuild (the one after new cuts too) put it there."""
    freed = np.sort(np.asarray(freed, np.int64))
    send = {}
    if contacts.n and len(freed):
        for g, row in (("ga", "ia"), ("gb", "ib")):
            hit = _in_sorted(freed, getattr(contacts, g))
            if not hit.any():
                continue
            # the freed block's row here (owned or ghost) gives its centroid, hence its owner
            dest = np.full(contacts.n, -1, np.int64)
            dest[hit] = decomp.owner_of(blocks.x[np.asarray(contacts.arrays[row])[hit]])
            for r in np.unique(dest[hit]).tolist():
                if r != comm.rank:
                    send[r] = send.get(r, np.zeros(contacts.n, bool)) | (dest == r)
    got = sparse_exchange(comm, {r: contacts.select(m) for r, m in send.items()})
    if not got:
        return contacts
    parts = [contacts] + [got[r] for r in sorted(got)]
    # the union (a contact held here and received is one contact: identical copies)
    every = np.unique(np.concatenate([a for p in parts for a in (p.ga, p.gb)]))
    return _merge_contacts(parts, every, [False] + [True] * len(got))


def _number_rows(contacts: ContactStore, blocks: BlockStore) -> None:
    """Set the contacts' local rows (``ia``, ``ib``: blocks; ``ka``, ``kb``: pieces) from
    their gids in ``blocks`` (owned and ghosts)."""
    all_gids = blocks.gid
    row_of = np.argsort(all_gids, kind="stable")
    sorted_gids = all_gids[row_of]
    a = contacts.arrays
    for side, g in (("ia", "ga"), ("ib", "gb")):
        rows = np.empty(len(a[g]), a[side].dtype)
        for lo, hi in _chunks(len(rows)):
            gids = a[g][lo:hi]
            pos = np.searchsorted(sorted_gids, gids)
            if np.any(pos >= len(sorted_gids)) or np.any(
                    sorted_gids[np.minimum(pos, len(sorted_gids) - 1)] != gids):
                raise RuntimeError("a contact's block is neither owned nor a ghost after the "
                                   "rebuild")
            rows[lo:hi] = row_of[pos]
        a[side] = rows
    # the pieces in contact: the same piece ordinal within the block's local pieces
    start, piece_gid = blocks.piece_start, blocks.piece_gid
    for side, piece, pg in (("ia", "ka", "pga"), ("ib", "kb", "pgb")):
        out = np.empty(len(a[side]), a[piece].dtype)
        for lo, hi in _chunks(len(out)):
            first = start[a[side][lo:hi]]  # the block's first piece
            out[lo:hi] = first + (a[pg][lo:hi] - piece_gid[first])
        a[piece] = out


def place_contacts(blocks: BlockStore, n_owned: int, fixed: np.ndarray,
                   placed: ContactStore) -> ContactStore:
    """Contacts already on the rank that owns a free block of each (a restart's, routed
    there once its blocks are distributed: pdem.state): those of its free owned blocks, each
    once, in key order, their rows numbered in ``blocks``; ``placed`` is consumed."""
    gids = blocks.gid[:n_owned]
    mine = _merge_contacts([placed], gids[fixed[gids] == 0], [True])
    _number_rows(mine, blocks)
    return mine


def route_contacts(comm, to_a: np.ndarray, to_b: np.ndarray, nsub: np.ndarray,
                   keys, bounds: np.ndarray, read, keys_done=None) -> ContactStore:
    """This rank's contacts ``0..n`` each to rank ``to_a[c]`` and to rank ``to_b[c]`` (-1:
    none; once if the same), with their ``nsub[c]`` sub-contacts (collective); returns the
    contacts sent here in the order of their keys (``keys(lo, hi)``: those of contacts
    ``lo:hi``; equal keys in rank order, then each rank's order). ``read(lo, hi)`` gives
    contacts ``lo:hi`` as a ContactStore;
    ``bounds`` are the batches' first rows and the end (the ranks may give different
    numbers of batches). ``keys_done()``, if given, is called once the keys are no longer
    asked for (the caller may drop what it made them from before the contacts are read).

    A batch is read, sent column by column as raw rows (no pickle) and dropped before the
    next is read, and what arrives is put straight into its place in arrays of the final
    size (the counts, keys and sub-contact counts are sent first): a rank holds at most one
    batch beyond what it keeps, and the result needs no reordering copy. Read whole, sent,
    then sorted, a restart's contacts were its peak (~60 MB a rank above a fresh run's at
    64,000 cubes on 2 ranks)."""
    n_batches = int(max_over_ranks(comm, len(bounds) - 1))
    bounds = np.concatenate([bounds, np.full(n_batches + 1 - len(bounds), bounds[-1])])
    batches = [(int(bounds[j]), int(bounds[j + 1])) for j in range(n_batches)]
    counts = np.zeros((n_batches, comm.size), np.int64)
    sub_counts = np.zeros((n_batches, comm.size), np.int64)
    for j, (lo, hi) in enumerate(batches):
        rows, dest = _sends(to_a[lo:hi], to_b[lo:hi])
        counts[j] = np.bincount(dest, minlength=comm.size)
        np.add.at(sub_counts[j], dest, nsub[lo:hi][rows])
    # what each rank sends here, per batch: the sizes of what is received
    mine = np.stack([counts.T, sub_counts.T], axis=2).reshape(comm.size, -1)
    got = alltoall_rows(comm, mine, np.ones(comm.size, np.int64)
                        ).reshape(comm.size, n_batches, 2).sum(axis=0)
    # the keys and sub-contact counts first: where each contact received goes
    key_here = np.empty(int(got[:, 0].sum()), np.int64)
    # (the sub-contact counts in the caller's dtype and the places in int32 where they fit:
    # both are held until the last batch has arrived, the routing's peak)
    n_here = np.empty(len(key_here), nsub.dtype)
    at = 0
    for j, (lo, hi) in enumerate(batches):
        rows, _ = _sends(to_a[lo:hi], to_b[lo:hi])
        m = int(got[j, 0])
        alltoall_rows(comm, keys(lo, hi)[rows], counts[j], out=key_here[at:at + m])
        alltoall_rows(comm, nsub[lo:hi][rows], counts[j], out=n_here[at:at + m])
        at += m
    if keys_done is not None:
        keys_done()
    order = np.argsort(key_here, kind="stable")
    del key_here
    place = np.empty(len(order), np.int32 if len(order) < 2**31 else np.int64)
    place[order] = np.arange(len(order), dtype=place.dtype)
    sc_start = csr.starts(n_here[order])
    del order
    arrays: dict[str, np.ndarray] = {}
    sub: dict[str, np.ndarray] = {}
    at = 0
    for j, (lo, hi) in enumerate(batches):
        rows, _ = _sends(to_a[lo:hi], to_b[lo:hi])
        part = read(lo, hi)
        sub_rows, _ = csr.take(part.sc_start, rows)
        m = int(got[j, 0])
        to = place[at:at + m]  # the rows received, and their sub-contacts' rows
        n = n_here[at:at + m]
        sub_to = np.repeat(sc_start[to] - csr.starts(n)[:-1], n) + np.arange(int(n.sum()))
        for columns, into, take, c, where in (
                (part.arrays, arrays, rows, counts[j], to),
                (part.sub, sub, sub_rows, sub_counts[j], sub_to)):
            for k in list(columns):
                col = columns.pop(k)
                if k not in into:
                    into[k] = np.empty((len(place) if into is arrays else int(sc_start[-1]),
                                        *col.shape[1:]), col.dtype)
                into[k][where] = alltoall_rows(comm, col[take], c)
                del col
        at += m
        del part
    return ContactStore(arrays, sub, sc_start)


def _sends(to_a: np.ndarray, to_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows a batch sends (each to ``to_a`` and to ``to_b``, -1: none, once if the same),
    by destination rank and then in order, and the rank of each."""
    n = len(to_a)
    dest = np.concatenate([to_a, np.where(to_b != to_a, to_b, -1)])
    rows = np.concatenate([np.arange(n), np.arange(n)])
    sent = dest >= 0
    dest, rows = dest[sent], rows[sent]
    order = np.lexsort((rows, dest))
    return rows[order], dest[order]


def rows_of(gids_held: np.ndarray, gids: np.ndarray) -> np.ndarray:
    """Rows of ``gids`` in a store whose rows hold ``gids_held`` (each gid must be there)."""
    order = np.argsort(gids_held, kind="stable")
    pos = np.searchsorted(gids_held, gids, sorter=order)
    pos = np.minimum(pos, max(len(gids_held) - 1, 0))
    rows = order[pos] if len(gids_held) else np.zeros(0, np.int64)
    if len(rows) != len(gids) or np.any(gids_held[rows] != gids):
        raise RuntimeError("rebuild: a block to distribute is not in the source store")
    return rows


def _migrate_owned(comm, decomp, source: BlockStore, owned_gids: np.ndarray, state: dict,
                   contacts: ContactStore, fixed: np.ndarray, extras: dict | None,
                   consume: bool):
    """Step 1 of :func:`rebuild`: every owned block goes to the rank whose brick holds its
    centroid, and to a rank that did not own it with its store rows and the contacts of
    its free blocks that leave. Returns the gids owned now (ascending), their MIGRATE rows
    and store in that order, the contacts received and the extras held (None without)."""
    rank = comm.rank
    src_rows = rows_of(source.gid, owned_gids)
    dest = decomp.owner_of(state["x"]) if len(owned_gids) else np.zeros(0, np.int64)
    out = {}
    # only the ranks that get blocks (a loop over every rank was O(P x blocks) a migration)
    for r in np.unique(np.append(dest, rank)).tolist():
        go = dest == r
        msg = {"gid": owned_gids[go], **{k: state[k][go] for k in MIGRATE}}
        if extras is not None:
            msg["extras"] = {int(g): extras[int(g)] for g in owned_gids[go] if int(g) in extras}
        if r != rank:
            msg["store"] = pack(source, src_rows[go])
            if contacts.n:
                leaving_free = owned_gids[go & ~fixed[owned_gids]]
                msg["contacts"] = contacts.select(contacts_needed(contacts, leaving_free))
        out[r] = msg
    stays = pack(source, src_rows[dest == rank])
    if consume:
        source.clear()
    held = None if extras is None else out[rank]["extras"]
    own = {k: v for k, v in out.pop(rank).items() if k != "extras"}
    got = sparse_exchange(comm, out)  # {source: message}, in rank order
    del out
    if held is not None:
        for m in got.values():
            held.update(m["extras"])
    got[rank] = own
    got = [got[r] for r in sorted(got)]  # rank order, this rank's own part included
    gids = np.concatenate([m["gid"] for m in got])
    order = np.argsort(gids, kind="stable")
    gids = gids[order]
    new_state = {k: np.concatenate([m[k] for m in got])[order] for k in MIGRATE}
    arrived = unpack([m["store"] if "store" in m else stays for m in got],
                     np.zeros(len(gids), np.uint8))
    del stays  # the messages are in ``arrived`` now: not kept through its copy below
    for m in got:
        m.pop("store", None)
    mine_store = take_rows(arrived, order, np.ones(len(gids), np.uint8))
    del arrived
    received = [m["contacts"] for m in got if "contacts" in m]
    return gids, new_state, mine_store, received, held


def _interest_boxes(comm, decomp, gids: np.ndarray, x: np.ndarray, radius: np.ndarray,
                    fixed: np.ndarray, pad: float, margin: float) -> tuple[dict, list]:
    """The interest boxes (``lo``, ``hi`` in a row of 6) of the ranks this rank's owned
    blocks may reach, by rank, and the ranks that asked for this rank's (collective). A
    rank's box is the box around its owned free blocks (``gids``, centroids ``x``), padded
    by ``pad`` and enlarged by ``margin``; empty (inverted) on a rank that owns no free
    block.

    A rank's box lies within its cell (``decomp.ranks_near``: a block is owned where its
    centroid is) grown by the largest padded radius of a free block (one reduction) and the
    margin. So the ranks whose cells meet this rank's blocks' box grown by that much are
    the only ones whose boxes its blocks can reach: it asks them for theirs (a sparse
    exchange: they learn who asks) and they answer, O(neighbours) a rank. (An ``allgather``
    of every rank's box was O(P) on every rank at every migration.)"""
    sel = ~fixed[gids]
    if sel.any():
        lo, hi = _boxes(x[sel], radius[sel], pad)
        box = np.concatenate([lo.min(0) - margin, hi.max(0) + margin])
        reach = float((radius[sel] + pad).max())
    else:
        box = np.array([np.inf] * 3 + [-np.inf] * 3)
        reach = 0.0
    reach = max_over_ranks(comm, reach) + margin
    asked = np.zeros(0, np.int64)
    if len(gids):
        blo, bhi = _boxes(x, radius, pad)
        grow = reach * (1.0 + 1e-6) + 1e-9  # generous: a neighbour too many costs a message
        lo_all, hi_all = blo.min(0), bhi.max(0)
        grow = grow + 1e-12 * np.maximum(np.abs(lo_all), np.abs(hi_all))
        asked = decomp.ranks_near(lo_all - grow, hi_all + grow)
        asked = asked[asked != comm.rank]
    askers = list(sparse_exchange(comm, {int(r): None for r in asked}))
    return neighbour_exchange(comm, {r: box for r in askers}, asked.tolist()), askers


def _send_ghosts(comm, boxes: dict, askers, gids: np.ndarray, new_state: dict,
                 mine_store: BlockStore, pad: float, held: dict | None):
    """Each owned block whose padded bounding box reaches into another rank's interest box
    (``boxes``: by rank, those of the ranks this rank's blocks may reach) goes there as a
    ghost (with its geometry, and its extras); ``askers``: the ranks whose blocks may reach
    this rank's box (each sends a message here, empty or not). Returns the messages sent
    and those received, by rank in rank order."""
    blo, bhi = _boxes(new_state["x"], mine_store.radius, pad)
    out = {}
    for r, box in boxes.items():
        hit = np.all(blo <= box[3:], axis=1) & np.all(bhi >= box[:3], axis=1)
        out[r] = {"gid": gids[hit], **{k: new_state[k][hit] for k in MIGRATE},
                  "store": pack(mine_store, np.nonzero(hit)[0])}
        if held is not None:
            out[r]["extras"] = {int(g): held[int(g)] for g in gids[hit] if int(g) in held}
    got = neighbour_exchange(comm, out, askers)
    if held is not None:
        for m in got.values():
            held.update(m["extras"])
    return out, got


def _ghost_rows(got: list, state: dict):
    """The ghosts received (:func:`_send_ghosts`, by rank): the messages that hold some, as
    (rank, message) in rank order, their gids in gid order, the rank each came from, that
    order, and their MIGRATE rows in it (shaped as ``state``'s when none came)."""
    ghost_parts = [(r, m) for r, m in sorted(got.items()) if len(m["gid"])]
    g_gids = np.concatenate([m["gid"] for _, m in ghost_parts]) if ghost_parts else np.zeros(0, np.int64)
    g_from = np.concatenate([np.full(len(m["gid"]), r) for r, m in ghost_parts]) if ghost_parts \
        else np.zeros(0, np.int64)
    g_order = np.argsort(g_gids, kind="stable")
    g_gids, g_from = g_gids[g_order], g_from[g_order]
    g_state = {k: (np.concatenate([m[k] for _, m in ghost_parts])[g_order] if ghost_parts
                   else np.zeros((0, *state[k].shape[1:]))) for k in MIGRATE}
    return ghost_parts, g_gids, g_from, g_order, g_state


def _halo_plan(out: dict, gids: np.ndarray, g_gids: np.ndarray, g_from: np.ndarray,
               fixed: np.ndarray, n_owned: int) -> tuple[dict, dict]:
    """The per-step halo's rows (free blocks only; fixed ghosts were sent once): by rank,
    the owned rows sent there and the ghost rows received from there."""
    send = {}
    for r, m in sorted(out.items()):
        gi = m["gid"][~fixed[m["gid"]]]
        send[r] = np.searchsorted(gids, gi)  # owned rows are [0, n_owned) in gid order
    recv = {}
    for r in np.unique(g_from):
        rows = np.nonzero((g_from == r) & ~fixed[g_gids])[0] + n_owned
        recv[int(r)] = rows
    return send, recv


def rebuild(comm, decomp, glob: BlockStore, source: BlockStore, owned_gids: np.ndarray,
            state: dict, contacts: ContactStore, pad: float, margin: float, halo_fields=HALO,
            consume: bool = False, extras: dict | None = None, consume_contacts: bool = False):
    """Redistribute blocks and contacts; returns (blocks, n_owned, contacts, halo, extras).

    ``glob``: the per-block static fields of every block, by gid (fixed, radius);
    ``source``: a store holding the blocks ``owned_gids`` (the scene's store at start, this
    rank's store later): their static data and geometry go with them;
    ``owned_gids``/``state``: the blocks this rank owns now and their MIGRATE arrays;
    ``contacts``: this rank's contacts (``ga``, ``gb`` valid; rows are reassigned here);
    ``halo_fields``: what the halo sends each step (pdem.model.fields.halo_fields);
    ``consume``: ``source`` is not used after this call (the set-up's build share): its
    arrays are dropped as soon as its blocks are packed, not kept through the rebuild's
    peak; ``consume_contacts``: the same for ``contacts`` (a restart's, read for this
    rebuild), whose columns are dropped as they are merged;
    ``extras``: objects by gid that travel with their blocks, to the new owner and to the
    ranks that ghost them (the zoned blocks' grids: pdem.deformable.store), for blocks of
    ``owned_gids``; returned for the blocks held after (owned and ghosts), None without.
    """
    owned_gids = np.asarray(owned_gids, np.int64)
    fixed = glob.fixed.astype(bool)
    # 1. migration of owned blocks and the contacts of the free ones that leave
    gids, new_state, mine_store, received, held = _migrate_owned(
        comm, decomp, source, owned_gids, state, contacts, fixed, extras, consume)
    parts = [contacts] + received
    drop = [consume_contacts] + [True] * (len(parts) - 1)
    del received

    # 2. interest boxes and ghosts
    free_now = gids[~fixed[gids]]
    # the contacts this rank computes: those of its free blocks (rows renumbered at 4.)
    # (a restart's contacts, read for this rebuild, and the ones received: their columns
    # dropped as they are merged)
    mine = _merge_contacts(parts, free_now, drop)
    del parts
    boxes, askers = _interest_boxes(comm, decomp, gids, new_state["x"], mine_store.radius, fixed,
                                    pad, margin)
    out, got = _send_ghosts(comm, boxes, askers, gids, new_state, mine_store, pad, held)
    ghost_parts, g_gids, g_from, g_order, g_state = _ghost_rows(got, state)

    # 3. the local store: owned rows first, then ghosts, each in gid order
    owned = np.concatenate([np.ones(len(gids), np.uint8), np.zeros(len(g_gids), np.uint8)])
    n_owned = len(gids)
    # each copy of the owned blocks is dropped once the next is made (the rebuild's peak)
    mine_msg = whole_message(mine_store)
    del mine_store
    both = unpack([mine_msg] + [m["store"] for _, m in ghost_parts], owned)
    del mine_msg, got
    for _, m in ghost_parts:
        m.pop("store")
    for m in out.values():
        m.pop("store")
    blocks = take_rows(both, np.concatenate([np.arange(n_owned), n_owned + g_order]), owned)
    del both
    for k in MIGRATE:
        getattr(blocks, k)[:] = np.concatenate([new_state[k], g_state[k]])

    # 4. the contacts' rows renumbered
    _number_rows(mine, blocks)

    # 5. the per-step halo plan (free blocks only; fixed ghosts were sent once, above)
    send, recv = _halo_plan(out, gids, g_gids, g_from, fixed, n_owned)
    blocks.u_mig[:] = 0.0
    return blocks, n_owned, mine, Halo(comm, send, recv, halo_fields), held
