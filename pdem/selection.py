"""Which blocks a scene's selections name, and setting fields on them: the service stages,
boundary conditions, the domain and the output share, with the per-block field tuples each
rank keeps of every block (the catalogue).

Every rank holds rows of some blocks only (its build share at set-up, the blocks it holds
after); a selection selects among those and the ranks gather the gids, and a field set on
gids is set wherever this rank keeps a row of them.
"""

from __future__ import annotations

import numpy as np

from .model.blocks import BlockStore
from .mpi import allgather_rows

# the per-block fields of every block each rank holds during set-up (the scene's store, by
# gid, its rows: no gid column): the flags a boundary condition or a stage sets (fixed,
# vfix, out). The
# rest each rank reads of its build share: the resolve, the timestep and mass scaling and the
# start checks (envelopes, velocities, applied forces, mass, inertia, radius; reduced over the
# ranks: maxima and minima, exact sums, an exact distributed median for the log;
# pdem.resolve, pdem.preflight), the selections (pdem.selection.selected: gids
# gathered), the initial decomposition (the shares' centroids), the output's initial
# centroids and groups (the writer's range is the share: ``writer_static``); a boundary
# condition or a stage sets fields on the share too (pdem.selection.set_block_fields), and the
# mass scaling its factors. 3 bytes a block, the set-up's one O(N) transient (215 with every
# field the set-up read gathered)
CATALOGUE = ("fixed", "vfix", "out")
# what the ranks gather of it
GATHERED = CATALOGUE
# what of it a rank keeps once the blocks are distributed (distribute.distributed_from_scene)
# and the output is open (pdem.simulation): two bytes a scene block, read by the rebuild
# (which contacts travel: fixed), the checkpoint (which copy of a contact is written: fixed)
# and the excavations (out). A stage's start reads the blocks each rank holds (its
# selections: gids gathered; its timestep and mass scaling: reduced over the ranks); a stage,
# a boundary condition or the domain sets fields on the blocks a rank holds
# (pdem.selection.set_block_fields). The store's rows stay by gid (``glob.n`` is the scene's
# block count).
RUN_CATALOGUE = ("fixed", "out")
# the per-block fields the timestep and mass scaling read (pdem.selection.timestep_rows)
TIMESTEP_FIELDS = ("mass", "inertia", "radius", "fixed", "mscale")


def selected(state, sel) -> np.ndarray:
    """Gids of the blocks a :class:`pdem.config.schema.Selection` names, in gid order (every
    rank alike; collective once the blocks are distributed). A range selects by the scene's
    centroids (the blocks' ``x0``): a selection does not depend on the motion. Each rank
    selects among the blocks of its build share before they are distributed, among those it
    owns after, and the ranks gather the gids selected (no rank keeps the centroids of blocks
    it does not hold, pdem.selection.CATALOGUE); a scene built whole on every rank selects
    among all."""
    g = state.glob
    whole = "x" in vars(g)
    if whole:
        gids = np.arange(g.n)
        x, out = g.x, g.out
    elif state.share is not None:  # set-up: the build share (its blocks have not moved)
        sh = state.share
        gids, x, out = sh.gid, sh.x, sh.out
    else:
        b, n = state.blocks, state.n_owned
        gids, x, out = b.gid[:n], b.x0[:n], b.out[:n]
    keep = out == 0
    if sel.names is not None or sel.groups is not None:
        keep &= state.specs.matching(gids, sel.names, sel.groups)
    if sel.range is not None:
        keep &= np.all((x >= sel.range.box.min) & (x <= sel.range.box.max), axis=1)
    mine = gids[keep].astype(np.int64)
    if whole:
        return mine
    return np.sort(allgather_rows(state.comm, mine))


def set_block_fields(state, gids, **values) -> None:
    """Set block fields of ``gids`` in this rank's rows (if any), in its build share until
    the first distribution, and in the scene's store where it keeps that field
    (pdem.selection.CATALOGUE at set-up, RUN_CATALOGUE after; its rows are the gids)."""
    gids = np.asarray(gids, np.int64)
    for store in (state.glob, state.share, state.blocks):
        if store is None:
            continue
        hit = gids if store is state.glob else np.isin(store.gid, gids)
        for key, v in values.items():
            column = vars(store).get(key)
            if column is not None:
                column[hit] = v


def timestep_rows(s):
    """``(rows, n)``: the blocks whose timestep fields (pdem.selection.TIMESTEP_FIELDS, and gid)
    this rank reads and sets, its own (reduced over the ranks) the first ``n``: the blocks it
    holds, owned first (views: a mass scale set on them is the blocks'), or before the first
    distribution its build share (or every block, when every rank built every block: then
    rank 0's own, so that a sum over the ranks counts each block once — an exact mean of every
    block counted P times is not the mean's bits when P is not a power of two, which made a
    3-rank restart's replayed stage step differ from the straight run's by an ulp)."""
    b = s.blocks
    if b is not None:
        return BlockStore.catalogue({k: getattr(b, k)[:b.n]
                                     for k in ("gid", *TIMESTEP_FIELDS)}), s.n_owned
    if s.share is not None:
        return s.share, len(s.share.gid)
    return s.glob, len(s.glob.gid) if s.comm.rank == 0 else 0
