"""ModelState: one rank's share of the model (blocks, contacts, halo, cell space, clock).

Built from a scene (or a checkpoint) on every rank alike. The static model (shapes, masses,
initial state) is built on every rank from the scene, keyed by gid (``glob``); a rank holds rows
of it (owned + ghosts) in ``blocks``, and after set-up keeps only those rows' geometry (it
travels with the blocks, pdem.parallel.migrate) and two bytes of every block (RUN_CATALOGUE);
a stage asks the owners for what else it reads of every block (ModelState.scene_fields).
Everything the cycle reads and writes lives here; the stepper (:mod:`pdem.stepper`) changes
it, plugins (:mod:`pdem.plugins`) observe it.
"""

from __future__ import annotations

import math

import numpy as np

from .boundary import apply_scene, needs_every_block
from .config import ConfigError, Scene
from .config.load import dump_scene
from .contact.algorithms import ALGORITHMS
from .contact.laws import joint_table
from .deformable.columns import GRID_WIDTH
from .deformable.store import GridStore
from .distribute import distribute_initial, redistribute
from .dynamics.damping import DAMPING
from .dynamics.kinematics import refresh_pose, thinnest_width
from .io.checkpoint import new_run_id, written_contacts
from .io.layout import even_share, h5py_has_mpi
from .memory import map_large_blocks, return_freed_memory
from .model.blocks import BlockStore
from .model.build import SpecTable, block_store, expand_blocks, geometry_columns
from .model.contacts import ContactStore
from .model.csr import KEY_SHIFT
from .model.fields import held_width
from .model.runs import RunColumn
from .mpi import LOCAL, allgather, allgather_rows, broadcast, configure_waits
from .parallel.decomposition import make_decomposition, zone_work
from .preflight import check_derived, machine_memory, preflight, rescaled
from .reinforce import Elements
from .resolve import REMAP_FRACTION, Resolved, contact_tolerance, resolve
from .restart import restore
from .selection import GATHERED
from .timers import Timers

# a block may move up to this fraction of the thinnest piece's width in one step (see
# max_step_motion)
STEP_WIDTH_FRACTION = 0.2


def max_step_motion(ctol: float, thinnest: float) -> float:
    """The step motion the run-time tunnelling guard allows: CTOL/2 (pdem.stepper's remap
    trigger: up to it every pair closing in is found before it touches) or, if larger, a fifth
    of the thinnest piece's width. A step larger than CTOL/2 only delays a contact: the pair is
    first seen already overlapping by up to the two blocks' motion in that step; a block passes
    through another only when that overlap reaches about half the thinner one's width (the
    common plane then lies past its middle and pushes it out on the far side)."""
    return max(REMAP_FRACTION * ctol, STEP_WIDTH_FRACTION * thinnest)


def needs_whole_scene(scene: Scene, comm) -> bool:
    """Whether set-up needs every block's geometry on every rank: a boundary stress finds
    the exposed faces of its blocks among all blocks (pdem.boundary), and without parallel
    h5py rank 0 writes every block's surface."""
    return needs_every_block(scene) or (comm.size > 1 and not h5py_has_mpi())


def build_share(comm, n: int) -> tuple[int, int]:
    """The gids ``[lo, hi)`` whose store this rank builds at set-up: an even share, the
    output writer's (pdem.io.layout.writer_range with parallel h5py)."""
    return even_share(comm.rank, comm.size, n)


def scene_catalogue(comm, share) -> BlockStore:
    """The :data:`CATALOGUE` fields of every block, gathered from the ranks' build shares
    (contiguous, in rank order: gid order); no geometry."""
    return BlockStore.catalogue({k: allgather_rows(comm, getattr(share, k)) for k in GATHERED})


def zoned_grids(scene: Scene, comm, specs, first_gid: int):
    """The grids of the zoned blocks among ``specs`` (None for a scene without ``zones``)."""
    if not any(b.zones is not None for b in scene.blocks):
        return None
    return GridStore.build(scene, specs, first_gid)


class ModelState:
    """The model on one rank; construct with :meth:`create` (collective). Its blocks go to
    their owners, and set-up's scene data is dropped, by :mod:`pdem.distribute`."""

    def __init__(self, scene: Scene, comm, specs, glob, group_names, joints, resolved: Resolved,
                 thinnest: float, share=None, grids=None):
        self.scene = scene
        self.scene_yaml = dump_scene(scene)
        self.comm = comm
        self.specs = specs
        self.glob = glob
        self.group_names = group_names
        self.joints = joints
        self.resolved = resolved
        self.timers = Timers()
        self.run_id = broadcast(comm, new_run_id() if comm.rank == 0 else None)
        self.step = 0
        self.time = 0.0
        self.dt = resolved.dt
        self.alpha = resolved.alpha
        self.ratio = math.inf
        # staged runs (pdem.stages): the current stage, how many are done, and where the one
        # in progress started (its changes made at stage_started; -1: none yet)
        self.stage = 0
        self.stage_next = 0
        self.stage_started = -1
        self.stage_t0 = 0.0
        self.stage_step0 = 0
        self.stage_times: dict[int, float] = {}  # model time at which stage k began
        self.boundary = None  # pdem.boundary.Boundary: the conditions in force
        # cables and rock bolts (pdem.reinforce; None: a scene without reinforcement)
        self.reinforcement = Elements(scene) if scene.reinforcement else None
        self.energy_start = None  # (kinetic, joint spring energy) at the start, see plugins.energy
        self.gravity = np.array(scene.gravity, float)
        self.damping = DAMPING[scene.solve.damping.mode]
        self.damping_name = scene.solve.damping.mode  # (a stage's, once it starts)
        self.scalar_inertia = scene.solve.inertia == "scalar"
        self.algorithm = ALGORITHMS[scene.contact.algorithm](resolved.ctol, resolved.snap_tol)
        # the initial cuts from the build shares' centroids (or every block's, when every rank
        # built every block)
        rows = glob if share is None else share
        self.decomp = make_decomposition(
            comm, resolved, scene.parallel, rows.x, share is not None,
            None if grids is None else 1 + zone_work(grids.zones_at(rows.gid)))
        self.n_rebuilds = 0
        self.blocks = None
        self.n_owned = 0
        # zoned: empty_contacts; ``held`` only with solve.inactive (pdem.model.fields)
        self.contacts = ContactStore.empty(joints.hist_width,
                                           held=held_width(scene.solve.inactive is not None))
        self.halo = None
        self.cells = None
        self.estimate = None  # pre-flight cost estimate (pdem.preflight), set by create
        self.check_overlaps = False  # refuse blocks overlapping at start (Stepper.start)
        # keep the whole scene's geometry after set-up (pdem check's report; Simulation)
        self.keep_scene_geometry = False
        self.writer_mesh = None  # the output writer's share of the surfaces (set-up)
        # and of the initial centroids and groups (its gid range's rows; set-up)
        self.writer_static = None
        # whether the run writes output: else the writer's surfaces are not taken (Simulation)
        self.output_surfaces = True
        # the largest motion of a block in one step that cannot take it through another block
        # unseen (pdem.dynamics.motion.motion_bookkeeping)
        self.max_step = max_step_motion(resolved.ctol, thinnest)
        # the grids of the zoned blocks (pdem.deformable.store.GridStore); None: all rigid
        self.grids = None
        # this rank's share of the scene's blocks with their geometry, from set-up to the
        # first distribution (None: ``glob`` has every block's geometry)
        self.share = None

    @staticmethod
    def create(scene: Scene, comm, *, check_overlaps: bool = True, whole: bool = False
               ) -> ModelState:
        """Build the blocks, resolve the scene's ``auto`` values and check the start.

        Each rank builds the shapes (families' members: pdem.model.build.expand_blocks) and
        the store (geometry, mass properties) of its share of the gids (:func:`build_share`)
        only, and the ranks gather the per-block fields every rank keeps (the
        catalogue) and the specs' geometric scalars; the blocks go to their owners at
        :meth:`distribute_initial`. ``whole`` (or a scene that reads every block's faces, see
        :func:`needs_whole_scene`): every rank builds every block, as ``pdem check`` does."""
        map_large_blocks()  # arrays freed during set-up go back to the system (pdem.memory)
        configure_waits(comm)  # oversubscribed ranks sleep while they wait (pdem.mpi)
        # refuse a scene too large for the machine before its blocks exist (docs/limits.md);
        # the smallest node's memory, so that every rank refuses alike (no rank left waiting)
        memory = min(allgather(comm, machine_memory()))
        warn = comm.rank == 0
        whole = whole or needs_whole_scene(scene, comm)
        estimate = preflight(scene, comm.size, memory, warn, whole)
        specs = expand_blocks(scene, estimate.max_blocks,
                              None if whole else lambda n: build_share(comm, n), comm)
        if len(specs) != estimate.blocks:  # cuts and mesh cells are counted only once built
            estimate = rescaled(estimate, len(specs))
            if len(specs) > estimate.max_blocks or estimate.bytes_per_rank > estimate.max_bytes:
                raise ConfigError([f"limits: the scene makes {estimate} (limits.max_blocks, "
                                   "limits.max_memory_per_rank; docs/limits.md)"])
        # this rank built the shapes of its share only (the others' blocks are names and
        # scalars: pdem.model.speclist)
        lo, hi = (0, len(specs)) if whole else build_share(comm, len(specs))
        share, group_names = block_store(scene, specs, lo, hi)
        grids = zoned_grids(scene, comm, specs[lo:hi], lo)
        columns = geometry_columns(specs[lo:hi])
        if not whole:  # as runs where they run (an array's), else every block's rows
            columns = {k: RunColumn.gathered(comm, v) for k, v in columns.items()}
        # the shapes are in the stores now (the output's surfaces too): the specs keep names
        # and scalars, as columns (every rank keeps them for every block)
        specs = SpecTable(specs, scene.blocks, columns)
        return_freed_memory()  # the shapes: the distribution's messages come on top
        joints = joint_table(scene, group_names)
        if whole:
            glob, verts_max = share, None
        else:
            refresh_pose(share, 0.5 * contact_tolerance(scene, specs))
            glob = scene_catalogue(comm, share)
            verts_max = max(allgather(comm, float(np.abs(share.verts_world).max(initial=1.0))))
        # the resolve's and the start checks' per-block reads beyond the catalogue (envelopes,
        # velocities, applied forces) are of this rank's share, reduced over the ranks
        rows, over = (glob, LOCAL) if whole else (share, comm)
        resolved = resolve(scene, comm.size, specs, glob, joints, verts_max, rows, over)
        if grids is not None:
            resolved = grids.resolve(scene, resolved, comm)
        check_derived(scene, specs, rows, joints, group_names, resolved.dt, warn, resolved.ctol,
                      over)
        thinnest = thinnest_width(share.vert_start, share.verts_local, share.face_start,
                                  share.normals_local, share.offsets_local)
        state = ModelState(scene, comm, specs, glob, group_names, joints, resolved,
                           thinnest if whole else min(allgather(comm, thinnest)),
                           None if whole else share, grids)
        state.share = None if whole else share
        state.grids = grids
        if grids is not None:  # the sub-contacts carry their gridpoints (sc_grid)
            state.contacts = state.empty_contacts()
        state.estimate = estimate
        apply_scene(state)
        # checked by the stepper's start on the first contact update (one search, not two)
        state.check_overlaps = check_overlaps
        return state

    @property
    def ctol(self) -> float:
        return self.resolved.ctol

    def empty_contacts(self) -> ContactStore:
        """A store of no contacts with this scene's sub-contact columns."""
        return ContactStore.empty(self.joints.hist_width,
                                  GRID_WIDTH if self.grids is not None else 0,
                                  held_width(self.scene.solve.inactive is not None))

    def damping_args(self):
        """The damping kernel's constants now (alpha changes under adaptive damping)."""
        return self.damping.kernel_args(self.alpha)

    # ------------------------------------------------------------------ ownership
    def scene_store(self):
        """The scene's store with its geometry (set-up and restore only)."""
        if not self.glob.has_geometry:
            raise RuntimeError("the scene's block geometry was released after set-up")
        return self.glob

    def scene_fields(self, names) -> BlockStore:
        """Per-block fields ``names`` of every scene block, rows by gid: the scene's store
        while it keeps them (set-up, a restart's replay, a run that keeps the whole scene),
        else gathered from the blocks' owners (collective; a transient of a stage's start or
        of the output's opening: no rank keeps them for blocks it does not hold)."""
        g = self.glob
        if all(k in vars(g) for k in names):
            return g
        b, n = self.blocks, self.n_owned
        gid = allgather_rows(self.comm, b.gid[:n])
        order = np.argsort(gid, kind="stable")
        if len(gid) != g.n or not np.array_equal(gid[order], np.arange(g.n)):
            raise RuntimeError(f"scene_fields: the ranks own {len(gid)} blocks, not each of "
                               f"the scene's {g.n} once")
        return BlockStore.catalogue({"gid": gid[order], **{
            k: allgather_rows(self.comm, getattr(b, k)[:n])[order] for k in names}})

    def distribute_initial(self):
        """The first distribution of the blocks (collective; pdem.distribute)."""
        distribute_initial(self)

    def redistribute(self):
        """Migrate blocks whose centroid left the brick and rebuild ghosts (collective;
        pdem.distribute)."""
        redistribute(self)

    def rebalance(self) -> bool:
        """At a rebuild point, before :meth:`redistribute`: new cuts if the owned work is
        imbalanced (``parallel.rebalance``, balance rcb; collective), see parallel.decomposition."""
        zones = None if self.grids is None else self.grids.zones_at(self.blocks.gid[:self.blocks.n])
        return self.decomp.rebalance(self.blocks, self.n_owned, self.contacts, zones)

    def owned_gids(self) -> np.ndarray:
        return self.blocks.gid[:self.n_owned]

    def owned_row(self, gid: int) -> int:
        """Row of block ``gid`` if this rank owns it, else -1."""
        owned = self.owned_gids()
        i = int(np.searchsorted(owned, gid))
        return i if i < len(owned) and owned[i] == gid else -1

    def restore(self, ck: dict):
        """Continue from a checkpoint's state (any rank count; :func:`pdem.restart.restore`)."""
        restore(self, ck)

    # ------------------------------------------------------------------ start checks
    def check_initial_overlaps(self):
        """Blocks interpenetrating at start are an input error, named by block (collective;
        called by the stepper's start once the first contact update has measured every pair
        that can touch: a rank checks the contacts it writes, each pair once over the ranks,
        and every rank raises alike). The first ten in contact-key order, as one rank
        checking every pair would find them; pairs of two fixed blocks (never in contact)
        are not checked."""
        c = self.contacts
        tol = self.resolved.overlap_tolerance
        bad = np.nonzero(written_contacts(self) & (c.gap < -tol))[0] if c.n else []
        found = [(int(c.pga[i]) * KEY_SHIFT + int(c.pgb[i]), int(c.ga[i]), int(c.gb[i]),
                  float(-c.gap[i])) for i in bad]
        found = sorted(found)[:10]
        found = sorted(f for part in allgather(self.comm, found) for f in part)[:10]
        if found:
            raise ConfigError([
                f"blocks {self.specs[ga].name!r} and {self.specs[gb].name!r} overlap by "
                f"{depth:.4g} m at start (tolerance {tol:.3g} m: contact.overlap_tolerance)"
                for _, ga, gb, depth in found])

    # ------------------------------------------------------------------ reports
    def load_report(self) -> dict:
        """Blocks, ghosts and contacts per rank and the imbalance (collective)."""
        grid_halo = self.grids.halo if self.grids is not None else None
        mine = (self.n_owned, self.blocks.n - self.n_owned, self.contacts.n,
                self.halo.bytes_per_step + (grid_halo.bytes_per_step if grid_halo else 0))
        rows = np.array(allgather(self.comm, mine))
        owned = rows[:, 0]
        imbalance = float(owned.max() / owned.mean()) if owned.mean() > 0 else 1.0
        return {"owned": rows[:, 0].tolist(), "ghosts": rows[:, 1].tolist(),
                "contacts": rows[:, 2].tolist(), "halo_bytes": rows[:, 3].tolist(),
                "imbalance": imbalance, "rebuilds": self.n_rebuilds}
