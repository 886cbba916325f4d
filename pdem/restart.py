"""Restart: a model state continued from a checkpoint on any rank count.

The blocks travel to their owners at the checkpoint's poses with their stored rows, and the
contacts of their free blocks with them (pdem.io.checkpoint has the file's layout). A file
read whole by one process, every block read by every rank, or (a scene built in shares) each
rank reading its build share's rows and an even share of the contacts; a damaged file found
by any rank is refused by every rank with the same line.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .deformable import grid_checkpoint
from .distribute import distribute, distributed_from_scene, take_share
from .errors import UserError
from .io.checkpoint import CheckpointReader, read_elements
from .model.csr import KEY_SHIFT
from .model.fields import MIGRATE, held_width
from .mpi import allgather, allgather_rows
from .parallel.migrate import place_contacts, route_contacts


def restore(state, ck: dict) -> None:
    """Continue from a checkpoint's state (any rank count; see pdem.io.checkpoint)."""
    a = ck["attrs"]
    if int(a["n_blocks"]) != state.glob.n:
        # found by the fuzz: a checkpoint whose blocks do not match its scene
        raise UserError(f"checkpoint: {int(a['n_blocks'])} blocks stored, its scene makes "
                        f"{state.glob.n}: the file is damaged")
    state.step = int(a["step"])
    state.time = float(a["time"])
    state.dt = float(a["dt"])
    state.alpha = float(a["alpha"])
    state.ratio = float(a["ratio"]) if a["ratio"] >= 0 else math.inf
    state.run_id = str(a["run_id"])
    state.resolved = dataclasses.replace(state.resolved, dt=state.dt)
    if "blocks" in ck:  # read whole by one process (read_checkpoint)
        _restore_share(state, ck["blocks"]["out"], ck["blocks"]["x"],
                       lambda owned: {k: ck["blocks"][k][owned] for k in MIGRATE},
                       lambda free: ck["contacts"], ck["path"], read=False)
        return
    path = ck["path"]
    if state.share is not None:
        with _reader(state, path, by_share=True) as reader:
            _restore_by_share(state, reader, path)
        return
    with _reader(state, path) as reader:
        # every rank has every block (it reads every block's centroid: who owns what) and
        # reads the contacts' blocks, then the rows it will hold: its blocks and the
        # contacts of its free blocks (the rebuild keeps no others)
        out, x = checked(state.comm, lambda: (reader.block_column("out"),
                                              reader.block_column("x")), path)
        _restore_share(
            state, out, x,
            lambda owned: checked(state.comm, lambda: reader.block_rows(owned, MIGRATE), path),
            lambda free: reader.contacts(checked(state.comm, lambda: np.nonzero(
                np.isin(reader.contact_column("ga"), free)
                | np.isin(reader.contact_column("gb"), free))[0], path)), path)


def _restore_by_share(state, reader, path) -> None:
    """Each rank reads the rows of its build share's blocks (a hyperslab: no rank reads a
    whole column) and the rebuild takes them to their owners at the checkpoint's poses.
    Then each reads an even, contiguous share of the contacts and sends each contact
    straight to the ranks that own a free block of it: the contacts are not held while
    the blocks travel (that was a restart's peak). What every rank learns of every block
    is its ``out`` code and its owner (1 + 4 bytes a block, gathered from the shares,
    dropped after)."""
    comm = state.comm
    gids = state.share.gid.copy()
    rows = checked(state.comm, lambda: reader.block_rows(gids, MIGRATE), path)
    out = allgather_rows(comm, rows["out"])
    owner = allgather_rows(comm, state.decomp.owner_of(rows["x"]).astype(np.int32))

    def placed():
        c0, c1, nsub = checked(comm, lambda: reader.contact_share(comm.rank, comm.size), path)
        counts = allgather(comm, int(nsub.sum()))
        if sum(counts) != reader.n_sub:  # every rank alike: the sum is everyone's
            raise UserError(f"cannot restart from {path}: contacts/nsub counts "
                            f"{sum(counts)} sub-contacts, the file holds {reader.n_sub}")
        s0 = sum(counts[:comm.rank])
        bounds = reader.contact_batches(nsub)
        if len(nsub) and int(nsub.max()) < 2**31:  # held through the routing: half size
            nsub = nsub.astype(np.int32)
        known = checked(state.comm, lambda: reader.contact_blocks(c0, c1), path)
        fixed = state.glob.fixed  # to the owners of their free blocks
        ga = known["ga"]
        to_a = np.where(fixed[ga] == 0, owner[ga], -1)
        gb = known["gb"]
        to_b = np.where(fixed[gb] == 0, owner[gb], -1)
        del ga, gb
        held = [known]  # the blocks and pieces: dropped once the keys are sent
        del known

        def keys(lo, hi):
            return held[0]["pga"][lo:hi].astype(np.int64) * KEY_SHIFT + held[0]["pgb"][lo:hi]

        def read(lo, hi):  # (the blocks and pieces read again: 16 bytes a contact)
            return checked(state.comm, lambda: reader.contact_range(
                c0 + lo, c0 + hi, nsub[lo:hi], s0 + int(nsub[:lo].sum())), path)

        return route_contacts(comm, to_a, to_b, nsub, keys, bounds, read,
                              keys_done=held.clear)

    held = [rows]  # given to the rebuild, then dropped: not kept while the contacts come
    del rows
    _restore_share(state, out, None, lambda owned: held.pop(), None, path, placed=placed)


def _restore_share(state, out, x, block_rows, contacts, path, read: bool = True,
                   placed=None) -> None:
    """The blocks this rank brings in (its build share, or those it owns at the
    checkpoint's poses) from ``block_rows(gids)``, and the contacts of their free ones,
    ``contacts(gids of those free blocks)``: the rebuild sends both to the owners.
    ``read``: the contacts were read for this (the rebuild drops them as it merges),
    else they are the caller's (a checkpoint read whole). ``placed()`` instead of
    ``contacts``: read the contacts and send them to the owners of their free blocks
    (collective), once the blocks are distributed."""
    gone = out > 0  # blocks that left the model domain act as fixed ones
    state.glob.fixed[gone] = 1
    state.glob.out[gone] = out[gone]
    if state.grids is not None:  # grids of blocks taken out are held still, not stepped
        state.grids.remove(np.nonzero(gone)[0])
    if state.share is None:  # every rank has every block: it takes its own
        owned = np.nonzero(state.decomp.owner_of(x) == state.comm.rank)[0]
        source = state.scene_store()
    else:  # each rank sends its share's blocks, at their checkpoint poses, to the owners
        source = take_share(state)
        owned = source.gid.copy()
    free = owned[state.glob.fixed[owned] == 0]  # the contacts of these come along
    if state.grids is not None:  # the grids held here (by the build) from the file
        checked(state.comm, lambda: grid_checkpoint.load(state.grids, path), path)
    # a checkpoint's ``held`` has 6 columns (older files always) or none: the scene's
    held = held_width(state.scene.solve.inactive is not None)
    if placed is not None:
        distribute(state, owned, block_rows(owned), state.empty_contacts(), source=source,
                   consume=source is not state.glob)
        with state.timers.phase("migrate"):
            state.contacts = place_contacts(state.blocks, state.n_owned, state.glob.fixed,
                                           placed().with_held(held))
    else:
        distribute(state, owned, block_rows(owned), contacts(free).with_held(held),
                   source=source, consume=source is not state.glob, consume_contacts=read)
    if state.grids is not None:  # zoned rows and pieces from the stored gridpoints
        b, rows = state.blocks, state.grids.rows
        x_saved = b.x[rows].copy()
        state.grids.sync(b)
        state.grids.sync(b, ghosts=True)
        b.x[rows] = x_saved  # the stored centroids (the same numbers, recomputed)
        b.dx[rows] = 0.0
    distributed_from_scene(state)
    if state.reinforcement is not None:  # the elements installed by then, as they were
        saved = checked(state.comm, lambda: read_elements(path), path)
        if saved is not None:
            state.reinforcement.restored(state, *saved)


def _reader(state, path, by_share: bool = False):
    """The checkpoint opened on every rank (collective), or one line of why not."""
    return checked(state.comm, lambda: CheckpointReader(path, state.comm, by_share), path)


def checked(comm, read, path):
    """``read()`` on every rank; a damaged file found by any rank is refused by all
    (the same line), never one rank raising while the others wait."""
    try:
        value, why = read(), None
    except (OSError, ValueError, KeyError) as exc:
        value, why = None, str(exc)
    whys = [w for w in allgather(comm, why) if w is not None]
    if whys:
        raise UserError(f"cannot restart from {path}: {whys[0]}")
    return value
