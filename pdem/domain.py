"""The model domain (``domain:``): blocks that leave it are frozen or deleted.

A free block whose centroid leaves the box stops and acts as a fixed block from then on; a
deleted one also loses its contacts and its room in the cell space (pdem.stepper.search). Its
kinetic energy, and the energy its contacts held, is booked as taken out of the model
(``WORK_REMOVED`` of the energy budget).
"""

from __future__ import annotations

import logging

import numpy as np

from . import mpi
from .contact.forces import book_contact_energy, contact_energies
from .dynamics import motion
from .dynamics.energy import kinetic_per_block
from .selection import set_block_fields

log = logging.getLogger("pdem")

FROZEN = 1
DELETED = 2


def outside(state) -> np.ndarray:
    """Owned free blocks whose centroid is outside the model domain (mask of owned rows)."""
    b, n = state.blocks, state.n_owned
    d = state.scene.domain
    x = b.x[:n]
    out = np.any((x < np.array(d.min)) | (x > np.array(d.max)), axis=1)
    return out & (b.fixed[:n] == 0) & (b.out[:n] == 0)


def take_out(state, bodies) -> None:
    """Freeze or delete the blocks outside the domain (collective; ``bodies``: the contact
    loop's record of ``state.blocks``, for booking the contacts' energy)."""
    b = state.blocks
    rows = np.nonzero(outside(state))[0]
    code = DELETED if state.scene.domain.action == "delete" else FROZEN
    gids = np.concatenate(mpi.allgather(state.comm, b.gid[rows].copy())).astype(np.int64)
    remove_blocks(state, bodies, gids, code, "left the model domain")


def remove_blocks(state, bodies, gids: np.ndarray, code: int, why: str) -> None:
    """Freeze (``FROZEN``) or delete (``DELETED``) blocks ``gids`` on every rank (every rank
    passes the same gids). Their kinetic energy and what their contacts held is booked as
    taken out of the model."""
    b, n = state.blocks, state.n_owned
    gids = np.asarray(gids, np.int64)
    rows = np.nonzero(np.isin(b.gid[:n], gids) & (b.out[:n] == 0))[0]
    ke = kinetic_per_block(b, rows)
    if state.grids is not None:  # a zoned block's is its grid's
        ke = state.grids.kinetic_at(rows, ke)
    b.work[rows, motion.WORK_REMOVED] += ke
    # every rank's copy of every such block, owned or ghost
    set_block_fields(state, gids, fixed=1, out=code, v=0.0, w=0.0, L=0.0)
    if state.grids is not None:  # a zoned block's grid stops where it is
        state.grids.remove(gids)
    c = state.contacts
    if code == DELETED and c.n:
        gone = np.isin(c.ga, gids) | np.isin(c.gb, gids)
        held = contact_energies(c.pairs(), c.subs(), state.joints.kernel_args,
                                gone.astype(np.uint8))
        book_contact_energy(bodies, c.ia, c.ib, held, motion.WORK_REMOVED)
        state.contacts = c.select(~gone)
    names = ", ".join(state.specs[g].name for g in gids[:10]) + (" ..." if len(gids) > 10 else "")
    log.info("step %d: %d block(s) %s (%s): %s", state.step, len(gids), why,
             "deleted" if code == DELETED else "frozen", names)
