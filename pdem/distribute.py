"""The distribution of a model state's blocks to their owners (collective).

A :class:`pdem.state.ModelState` holds the rows of one rank; these functions (re)build them:
the first distribution, from the build share or the whole scene's store, what set-up then
drops of the scene (its geometry, the per-block fields the run no longer reads), and the
migrations after (:func:`redistribute`), all through pdem.parallel.migrate's rebuild.
"""

from __future__ import annotations

import numpy as np

from .boundary import needs_every_block
from .contact.cellspace import CellSpace
from .dynamics.kinematics import refresh_pose
from .io.layout import writer_range
from .io.surfaces import body_surfaces
from .memory import return_freed_memory
from .model.contacts import ContactStore
from .model.fields import MIGRATE, halo_fields
from .parallel.migrate import rebuild
from .selection import CATALOGUE, RUN_CATALOGUE


def distribute(state, owned_gids, rows: dict, contacts: ContactStore, source=None,
               consume: bool = False, consume_contacts: bool = False):
    """(Re)build the rank's blocks, contacts and halo (collective), see parallel.migrate.
    ``rows``: the owned blocks' :data:`MIGRATE` fields; ``source``: a store holding the
    blocks ``owned_gids`` (default: the rank's); ``consume``: it is dropped once sent (the
    build share); ``consume_contacts``: ``contacts`` are dropped once merged (a restart's,
    read for this call)."""
    with state.timers.phase("migrate"):
        r = state.resolved
        grids = state.grids
        if grids is not None:  # the blocks' geometry travels: the zoned pieces' planes first
            grids.fresh_planes(state.blocks)
        state.blocks, state.n_owned, state.contacts, state.halo, held = rebuild(
            state.comm, state.decomp, state.glob, state.blocks if source is None else source,
            owned_gids, rows, contacts, 0.5 * r.ctol, r.margin,
            halo_fields(state.scene.solve.inactive is not None,
                        any(x.zones is not None for x in state.scene.blocks)), consume,
            None if grids is None else grids.payload(), consume_contacts)
        b = state.blocks
        if grids is not None:  # zoned blocks' grids came with them (owned and ghosts)
            state.grids = type(grids).arrived(grids, b, state.n_owned, held)
            state.grids.plan_halo(state.halo)
        refresh_pose(b, 0.5 * r.ctol)
        # a rank whose brick holds no block has no cell space until blocks arrive; blocks
        # deleted from the model take no space
        present = b.out != 2
        state.cells = CellSpace(b.lo[present], b.hi[present], r.cell_size) \
            if present.any() else None
        state.n_rebuilds += 1
        if state.reinforcement is not None:  # the elements' hosts: their rows here now
            state.reinforcement.bind(state)
        return_freed_memory()  # the messages and the old store


def needs_scene_geometry(state) -> bool:
    """Whether the run reads the geometry of blocks it does not hold after set-up: a
    stage's boundary stress finds the exposed faces on the scene's store (pdem.boundary)."""
    return needs_every_block(state.scene, stages_only=True)


def distributed_from_scene(state):
    """After the first distribution from the scene's store: take the output writer's
    share of the surfaces, then drop the rest of the scene's geometry (the start's
    contact search and first update then run without it: the set-up's peak)."""
    if state.glob.has_geometry and state.output_surfaces:  # else from the build share
        lo, hi = writer_range(state.comm, state.glob.n)
        state.writer_mesh = body_surfaces(state.glob, lo, hi)
        state.writer_static = (state.glob.x0[lo:hi].copy(), state.glob.group[lo:hi].copy())
    if not state.keep_scene_geometry:
        release_scene_geometry(state)
        release_setup_fields(state)


def release_scene_geometry(state):
    """After set-up (blocks distributed, output opened): drop the geometry of the blocks
    the rank does not hold. The scene's store keeps its per-block fields (a few scalars a
    block: fixed, radius, ...); each rank's store holds its blocks' and ghosts' geometry,
    which migrates with them."""
    if not needs_scene_geometry(state):
        if state.glob.has_geometry:
            state.glob.drop_geometry()
        # the catalogue's envelopes (lo, hi: the resolve's) too, 48 bytes a scene block
        state.glob.keep_fields(CATALOGUE)
    return_freed_memory()


def release_setup_fields(state, keep: tuple[str, ...] = ()):
    """Of every scene block keep only :data:`RUN_CATALOGUE` and ``keep``: once the
    blocks are distributed, and once the output is open. A run that keeps the whole scene
    (``pdem check``, a stage's boundary stress) keeps it all."""
    if not state.keep_scene_geometry and not needs_scene_geometry(state):
        state.glob.keep_fields(RUN_CATALOGUE + keep)
        return_freed_memory()


def distribute_initial(state):
    """Every rank takes the blocks whose centroid lies in its brick (collective): from
    its build share, sent to their owners, or from the whole scene's store."""
    empty = state.empty_contacts()
    if state.share is None:
        g = state.glob
        owned = np.nonzero(state.decomp.owner_of(g.x) == state.comm.rank)[0]
        distribute(state, owned, {k: getattr(g, k)[owned] for k in MIGRATE}, empty,
                   source=state.scene_store())
    else:
        s = take_share(state)
        distribute(state, s.gid.copy(), {k: getattr(s, k) for k in MIGRATE}, empty,
                   source=s, consume=True)
    distributed_from_scene(state)


def take_share(state):
    """The build share, to be sent to the owners (and dropped: ``state.share`` is None
    after), with what set-up changed on the scene's per-block fields since it was built
    (boundary conditions, mass scaling, a restart's removed blocks); the output writer
    takes its surfaces first (the build share is the writer's, pdem.state.build_share)."""
    s, state.share = state.share, None
    for k in CATALOGUE:  # the rest was set on the share itself
        if k in vars(state.glob):
            getattr(s, k)[:] = getattr(state.glob, k)[s.gid]
    if state.output_surfaces:  # the writer's range is the build share (writer_range)
        state.writer_mesh = body_surfaces(s)
        state.writer_static = (s.x.copy(), s.group.copy())
    return s


def redistribute(state):
    """Migrate blocks whose centroid left the brick and rebuild ghosts (collective)."""
    n = state.n_owned
    b = state.blocks
    distribute(state, b.gid[:n].copy(), {k: getattr(b, k)[:n].copy() for k in MIGRATE},
               state.contacts)
