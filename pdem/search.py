"""The contact search of a step: blocks whose accumulated motion passed the trigger are
remapped into the cell space, and contacts are created with their new neighbours (the
refresh that follows decides which touch). Called by the stepper at the start, after a step
that asks for it, and by a stage that changed the blocks (pdem.stages)."""

from __future__ import annotations

import numpy as np

from .dynamics.kinematics import update_envelopes
from .model.csr import pair_key


def search(s, active: np.ndarray) -> int:
    """In the model state ``s``: remap ``active`` blocks and create contacts with new
    neighbours (gap <= CTOL is decided by the next refresh; pairs found farther apart are
    dropped there); returns the contacts created."""
    b = s.blocks
    if b.n == 0:
        return 0
    if s.cells is None:
        return 0
    update_envelopes(b, 0.5 * s.ctol)
    # Every search maps all blocks afresh, so a grown cell space needs no extra remap; which
    # pairs are found depends only on the envelopes, never on the cell layout (a rank's
    # cell space differs from another's, the contacts they create must not).
    gone = b.out == 2
    if gone.any():  # deleted blocks: an inverted envelope meets nothing and maps nowhere
        s.cells.grow_to(b.lo[~gone], b.hi[~gone])
        pgone = gone[b.piece_block]
        b.piece_lo[pgone] = s.cells.hi + 1.0
        b.piece_hi[pgone] = s.cells.origin - 1.0
    else:
        s.cells.grow_to(b.lo, b.hi)
    moving = active & (b.fixed == 0) if s.step > 0 else active
    # candidates are pairs of convex pieces; pieces of one block never touch each other
    qi, qj = s.cells.candidates(b.piece_lo, b.piece_hi,
                                moving[b.piece_block].astype(np.uint8))
    b.u_acc[active] = 0.0
    pi, pj = b.piece_block[qi], b.piece_block[qj]
    other = pi != pj
    qi, qj, pi, pj = qi[other], qj[other], pi[other], pj[other]
    if len(pi) == 0:
        return 0
    gi, gj = b.piece_gid[qi], b.piece_gid[qj]
    # this rank computes the contacts in which it owns a free block
    mine = ((b.owned[pi] == 1) & (b.fixed[pi] == 0)) | ((b.owned[pj] == 1) & (b.fixed[pj] == 0))
    new = ~np.isin(pair_key(gi, gj), s.contacts.keys()) & mine
    if not new.any():
        return 0
    qi, qj, gi, gj = qi[new], qj[new], gi[new], gj[new]
    swap = gi > gj
    ka = np.where(swap, qj, qi)
    kb = np.where(swap, qi, qj)
    pga, pgb = b.piece_gid[ka], b.piece_gid[kb]
    _, first = np.unique(pair_key(pga, pgb), return_index=True)
    ka, kb, pga, pgb = ka[first], kb[first], pga[first], pgb[first]
    ia, ib = b.piece_block[ka], b.piece_block[kb]
    joint = s.joints.pair[b.group[ia], b.group[ib]].astype(np.int32)
    before = s.contacts.n
    s.contacts = s.contacts.with_new_pairs(ia=ia, ib=ib, ka=ka, kb=kb, ga=b.gid[ia],
                                           gb=b.gid[ib], pga=pga, pgb=pgb, joint=joint)
    return s.contacts.n - before
