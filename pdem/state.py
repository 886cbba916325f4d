"""ModelState: one rank's share of the model (blocks, contacts, halo, cell space, clock).

Built from a scene (or a checkpoint) on every rank alike. The static model (shapes, masses,
initial state) is built on every rank from the scene, keyed by gid; a rank holds rows of it
(owned + ghosts) in ``blocks``. Everything the cycle reads and writes lives here; the stepper
(:mod:`pdem.stepper`) changes it, plugins (:mod:`pdem.plugins`) observe it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .boundary import apply_scene
from .config import ConfigError, Scene
from .config.load import dump_scene
from .config.preflight import check_derived, machine_memory, preflight, rescaled
from .config.resolve import TOUCH_FRACTION, Resolved, resolve
from .contact.algorithms import ALGORITHMS
from .contact.cellspace import CellSpace
from .contact.detect import Planes, refresh_contacts
from .contact.laws import joint_table
from .dynamics.damping import DAMPING
from .dynamics.kinematics import refresh_pose, thinnest_width
from .errors import UserError
from .io.checkpoint import new_run_id
from .model.build import block_store, expand_blocks
from .model.contacts import ContactStore
from .model.csr import KEY_SHIFT
from .model.fields import MIGRATE, halo_fields
from .parallel.decomposition import make_decomposition
from .parallel.migrate import rebuild
from .parallel.mpi import allgather, broadcast
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
    from .stepper import REMAP_FRACTION

    return max(REMAP_FRACTION * ctol, STEP_WIDTH_FRACTION * thinnest)

class ModelState:
    """The model on one rank; construct with :meth:`create` (collective)."""

    def __init__(self, scene: Scene, comm, specs, glob, group_names, joints, resolved: Resolved):
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
        self.energy_start = None  # (kinetic, joint spring energy) at the start, see plugins.energy
        self.gravity = np.array(scene.gravity, float)
        self.damping = DAMPING[scene.solve.damping.mode]
        self.scalar_inertia = scene.solve.inertia == "scalar"
        self.algorithm = ALGORITHMS[scene.contact.algorithm](resolved.ctol, resolved.snap_tol)
        self.decomp = make_decomposition(comm, resolved, scene.parallel, glob.x)
        self.n_rebuilds = 0
        self.blocks = None
        self.n_owned = 0
        self.contacts = ContactStore.empty(joints.hist_width)
        self.halo = None
        self.cells = None
        self.estimate = None  # pre-flight cost estimate (pdem.config.preflight), set by create
        # the largest motion of a block in one step that cannot take it through another block
        # unseen (pdem.dynamics.motion.motion_bookkeeping)
        self.max_step = max_step_motion(resolved.ctol, thinnest_width(
            glob.vert_start, glob.verts_local, glob.face_start, glob.normals_local,
            glob.offsets_local))

    @staticmethod
    def create(scene: Scene, comm, *, check_overlaps: bool = True) -> ModelState:
        """Build the blocks, resolve the scene's ``auto`` values and check the start."""
        # refuse a scene too large for the machine before its blocks exist (docs/limits.md);
        # the smallest node's memory, so that every rank refuses alike (no rank left waiting)
        memory = min(allgather(comm, machine_memory()))
        warn = comm.rank == 0
        estimate = preflight(scene, comm.size, memory, warn)
        specs = expand_blocks(scene, estimate.max_blocks)
        if len(specs) != estimate.blocks:  # cuts and mesh cells are counted only once built
            estimate = rescaled(estimate, len(specs))
            if len(specs) > estimate.max_blocks or estimate.bytes_per_rank > estimate.max_bytes:
                raise ConfigError([f"limits: the scene makes {estimate} (limits.max_blocks, "
                                   "limits.max_memory_per_rank; docs/limits.md)"])
        glob, group_names = block_store(scene, specs)
        joints = joint_table(scene, group_names)
        resolved = resolve(scene, comm.size, specs, glob, joints)
        check_derived(scene, specs, glob, joints, group_names, resolved.dt, warn, resolved.ctol)
        state = ModelState(scene, comm, specs, glob, group_names, joints, resolved)
        state.estimate = estimate
        apply_scene(state)
        if check_overlaps:
            state.check_initial_overlaps()
        return state

    @property
    def ctol(self) -> float:
        return self.resolved.ctol

    def damping_args(self):
        """The damping kernel's constants now (alpha changes under adaptive damping)."""
        return self.damping.kernel_args(self.alpha)

    # ------------------------------------------------------------------ ownership
    def distribute(self, owned_gids, state: dict, contacts: ContactStore):
        """(Re)build this rank's blocks, contacts and halo (collective), see parallel.migrate."""
        with self.timers.phase("migrate"):
            r = self.resolved
            self.blocks, self.n_owned, self.contacts, self.halo = rebuild(
                self.comm, self.decomp, self.glob, owned_gids, state, contacts, 0.5 * r.ctol,
                r.margin, halo_fields(self.scene.solve.inactive is not None))
            b = self.blocks
            refresh_pose(b, 0.5 * r.ctol)
            # a rank whose brick holds no block has no cell space until blocks arrive; blocks
            # deleted from the model take no space
            present = b.out != 2
            self.cells = CellSpace(b.lo[present], b.hi[present], r.cell_size) \
                if present.any() else None
            self.n_rebuilds += 1

    def distribute_initial(self):
        """Every rank takes the blocks whose centroid lies in its brick (collective)."""
        g = self.glob
        owned = np.nonzero(self.decomp.owner_of(g.x) == self.comm.rank)[0]
        self.distribute(owned, {k: getattr(g, k)[owned] for k in MIGRATE},
                        ContactStore.empty(self.joints.hist_width))

    def redistribute(self):
        """Migrate blocks whose centroid left the brick and rebuild ghosts (collective)."""
        n = self.n_owned
        b = self.blocks
        self.distribute(b.gid[:n].copy(), {k: getattr(b, k)[:n].copy() for k in MIGRATE},
                        self.contacts)

    def rebalance(self) -> bool:
        """At a rebuild point, before :meth:`redistribute`: new cuts if the owned work is
        imbalanced (``parallel.rebalance``, balance rcb; collective), see parallel.decomposition."""
        return self.decomp.rebalance(self.blocks, self.n_owned, self.contacts)

    def owned_gids(self) -> np.ndarray:
        return self.blocks.gid[:self.n_owned]

    def owned_row(self, gid: int) -> int:
        """Row of block ``gid`` if this rank owns it, else -1."""
        owned = self.owned_gids()
        i = int(np.searchsorted(owned, gid))
        return i if i < len(owned) and owned[i] == gid else -1

    def restore(self, ck: dict):
        """Continue from a checkpoint's state (any rank count; see pdem.io.checkpoint)."""
        a = ck["attrs"]
        if int(a["n_blocks"]) != self.glob.n:
            # found by the fuzz: a checkpoint whose blocks do not match its scene
            raise UserError(f"checkpoint: {int(a['n_blocks'])} blocks stored, its scene makes "
                            f"{self.glob.n}: the file is damaged")
        self.step = int(a["step"])
        self.time = float(a["time"])
        self.dt = float(a["dt"])
        self.alpha = float(a["alpha"])
        self.ratio = float(a["ratio"]) if a["ratio"] >= 0 else math.inf
        self.run_id = str(a["run_id"])
        self.resolved = dataclasses.replace(self.resolved, dt=self.dt)
        blocks = ck["blocks"]
        gone = blocks["out"] > 0  # blocks that left the model domain act as fixed ones
        self.glob.fixed[gone] = 1
        self.glob.out[gone] = blocks["out"][gone]
        owned = np.nonzero(self.decomp.owner_of(blocks["x"]) == self.comm.rank)[0]
        self.distribute(owned, {k: blocks[k][owned] for k in MIGRATE}, ck["contacts"])

    # ------------------------------------------------------------------ start checks
    def check_initial_overlaps(self):
        """Blocks interpenetrating at start are an input error, named by block (collective:
        each rank checks a share of the candidate pairs, every rank raises alike)."""
        g = self.glob
        tol = self.resolved.overlap_tolerance
        cells = CellSpace(g.lo, g.hi, self.resolved.cell_size)
        qi, qj = cells.candidates(g.piece_lo, g.piece_hi, np.ones(g.n_pieces, np.uint8))
        other = g.piece_block[qi] != g.piece_block[qj]  # a joined block's pieces touch
        qi, qj = qi[other], qj[other]
        # in contact-key order (the probe's), then this rank's share: the messages gathered in
        # rank order are those of one rank checking every pair
        order = np.argsort(g.piece_gid[qi] * KEY_SHIFT + g.piece_gid[qj], kind="stable")
        size, rank = self.comm.size, self.comm.rank
        share = order[len(order) * rank // size:len(order) * (rank + 1) // size]
        msgs = self._overlaps(qi[share], qj[share], tol) if len(share) else []
        msgs = [m for part in allgather(self.comm, msgs) for m in part][:10]
        if msgs:
            raise ConfigError(msgs)

    def _overlaps(self, qi, qj, tol) -> list[str]:
        """Messages for the first 10 of the candidate piece pairs ``qi, qj`` that overlap by
        more than ``tol`` at start."""
        g = self.glob
        pi, pj = g.piece_block[qi], g.piece_block[qj]
        probe = ContactStore.empty(self.joints.hist_width).with_new_pairs(
            ia=pi, ib=pj, ka=qi, kb=qj, ga=g.gid[pi], gb=g.gid[pj], pga=g.piece_gid[qi],
            pgb=g.piece_gid[qj], joint=np.zeros(len(pi), np.int32))
        a = probe.arrays
        planes = Planes(a["ia"], a["ib"], a["ka"], a["kb"], a["normal"], a["point"], a["gap"],
                        a["ctype"], a["warm"])
        shapes = g.shapes()._replace(point_area=np.ones(g.n))
        keep = refresh_contacts(g.x, g.R, shapes, planes, np.zeros(probe.n + 1, np.int64),
                                probe.subs(), np.ones(probe.n, np.uint8), 1e300, TOUCH_FRACTION,
                                self.algorithm)[0]
        bad = keep.astype(bool) & (a["gap"] < -tol)
        msgs = []
        for c in np.nonzero(bad)[0][:10]:
            na, nb = self.specs[a["ga"][c]].name, self.specs[a["gb"][c]].name
            msgs.append(f"blocks {na!r} and {nb!r} overlap by {-a['gap'][c]:.4g} m at start "
                        f"(tolerance {tol:.3g} m: contact.overlap_tolerance)")
        return msgs

    # ------------------------------------------------------------------ reports
    def load_report(self) -> dict:
        """Blocks, ghosts and contacts per rank and the imbalance (collective)."""
        mine = (self.n_owned, self.blocks.n - self.n_owned, self.contacts.n,
                self.halo.bytes_per_step)
        rows = np.array(allgather(self.comm, mine))
        owned = rows[:, 0]
        imbalance = float(owned.max() / owned.mean()) if owned.mean() > 0 else 1.0
        return {"owned": rows[:, 0].tolist(), "ghosts": rows[:, 1].tolist(),
                "contacts": rows[:, 2].tolist(), "halo_bytes": rows[:, 3].tolist(),
                "imbalance": imbalance, "rebuilds": self.n_rebuilds}
