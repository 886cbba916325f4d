"""Zoned blocks in a scene: their grids, the block row's piece geometry from the surface grid.

A zoned block keeps its one row in the :class:`~pdem.model.blocks.BlockStore` (gid, centroid,
mass, envelopes, contacts) and ONE convex piece whose vertices are its surface gridpoints and
whose faces are its surface triangles (3DEC: "each original polygonal face is discretized into
triangular sub-faces ... each sub-face is exactly like a regular face"). Its pose is the
identity, so the piece's body frame is the world frame shifted to ``x``, the gridpoints'
mass-weighted centroid; every step :func:`pdem.deformable.contact.refresh_pieces` rewrites the
piece's vertices from the moved gridpoints and its planes are made from them before they are
read (:meth:`GridStore.fresh_planes`), and the common plane and sub-contacts work unchanged.

:class:`GridStore` holds the grids of the zoned blocks a rank holds (owned ones first, then
ghost copies; docs/deformable.md "On several ranks"), the node arrays of all of them flat
(``nodes``, ``vel``, ``force``, ...: CSR by ``node_start``, the zones' by ``zone_start``),
the owned blocks stepped by one call of :func:`pdem.deformable.motion.step_grids` (a call per
run of blocks of one constitutive table), each on its own slices.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from ..mpi import allgather
from ..parallel.halo import RowHalo
from .body import DeformableBody
from .columns import TRI, W
from .constitutive import material, reduced_table
from .contact import Grid, piece_planes, refresh_pieces
from .motion import (
    GRID_DAMPING,
    N_GW,
    N_SC,
    critical_timestep,
    nodal_stiffness,
    scaled_masses,
    servo_total,
    step_grids,
)
from .subcontacts import regrid
from .zones import zone_geometry

# margin under the grids' Gershgorin step (a guaranteed bound of the elastic grid with its
# joint springs; the margin covers the coupling to rigid blocks through their contacts)
GRID_FRAC = 0.9


class ZonedGrid:
    """One zoned block's grid as it travels between ranks (pickled by the rebuild's
    messages): its name, body (zones, gridpoints, stresses), surface gridpoints and the
    contact forces on its gridpoints (the next step's load) and their contact stiffness
    (the next step's masses; None: none yet)."""

    def __init__(self, name: str, body: DeformableBody, surf: np.ndarray, force: np.ndarray,
                 kc: np.ndarray | None = None):
        self.name, self.body, self.surf, self.force, self.kc = name, body, surf, force, kc


class GridStore:
    """The grids of a rank's zoned blocks (see module doc), in block-row order: the first
    ``n_owned`` are the blocks this rank owns (stepped here), the others ghost copies (their
    gridpoints forwarded by the owners every step, :meth:`forward`)."""

    def __init__(self, gravity, gids, grids: list[ZonedGrid], n_owned: int | None = None):
        self.gids = [int(g) for g in gids]
        self.names = [z.name for z in grids]
        self.bodies = [z.body for z in grids]
        self.surf = [z.surf for z in grids]
        self.n_owned = len(grids) if n_owned is None else int(n_owned)
        counts = [len(b.nodes) for b in self.bodies]
        self.node_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.zone_start = np.concatenate([[0], np.cumsum([len(b.tets) for b in self.bodies])]
                                         ).astype(np.int64)
        n, m, k = int(self.node_start[-1]), int(self.zone_start[-1]), len(self.bodies)
        # every array the grid step reads or writes is flat over the grids (CSR by
        # node_start, zone_start; one row a grid), the bodies' arrays views of them: the
        # step of all the owned grids is one kernel call (:meth:`step`)
        self.nodes = np.empty((n, 3))
        self.vel = np.zeros((n, 3))
        self.force = np.zeros((n, 3))  # contact forces on the gridpoints (F^c of eq. 54)
        # the contact springs' Gershgorin stiffness at each gridpoint, from the last force
        # pass's sub-contacts (pdem.deformable.contact.contact_forces_grid), and the joint
        # stiffness they count (:meth:`restage`)
        self.kc = np.zeros(n)
        self.kjoint = 0.0
        self.kn = 0.0  # the joint normal stiffness of the step's bound (:meth:`resolve`)
        self.gmass = np.empty(n)
        self.mass = np.empty(n)  # the stage's inertial masses (scale_masses)
        self.emass = np.empty(n)  # the last step's (inertial_masses)
        self.zstiff = np.zeros(n)  # the zones' Gershgorin stiffness (_zone_stiffness)
        self.applied = np.zeros((n, 3))
        self.fixed = np.zeros((n, 3), bool)
        self.fixed_vel = np.zeros((n, 3))
        self.prev = np.zeros((n, 3))
        self.tets = np.empty((m, 4), np.int64)  # (each grid's own gridpoint numbers)
        self.grad = np.empty((m, 4, 3))
        self.vol = np.empty(m)
        self.stress = np.empty((m, 6))
        self.plastic = np.empty(m, np.int32)
        self.scalars = np.zeros((k, N_SC))
        self.moduli = np.empty((k, 2))  # bulk, shear
        self.work = np.zeros((k, N_GW))
        self.servo = np.zeros((k, 2))
        self.unbalanced = np.zeros(k)
        self.stiffness_known = np.zeros(k, bool)
        # boundary stresses on the owned grids' faces this step (pdem.deformable.conditions)
        self.bload = np.zeros((n, 3))
        self.bloaded = False
        # quiet boundaries' dashpots at the owned grids' gridpoints (symmetric 3 x 3: xx yy zz
        # xy yz zx, N s/m; pdem.deformable.conditions.GridConditions.dashpots)
        self.quiet = np.zeros((n, 6))
        for d, (b, z) in enumerate(zip(self.bodies, grids, strict=True)):
            a, e = self.node_start[d], self.node_start[d + 1]
            za, ze = self.zone_start[d], self.zone_start[d + 1]
            self.force[a:e] = z.force
            if z.kc is not None:
                self.kc[a:e] = z.kc
            self.tets[za:ze] = b.tets
            self.moduli[d] = b.params.bulk, b.params.shear
            if b.zone_stiffness is not None:
                self.zstiff[a:e] = b.zone_stiffness
                b.zone_stiffness = self.zstiff[a:e]
                self.stiffness_known[d] = True
            # the bodies' arrays become views of the flat ones
            for name, flat in (("nodes", self.nodes), ("vel", self.vel),
                               ("gravity_mass", self.gmass), ("mass", self.mass),
                               ("emass", self.emass), ("applied", self.applied),
                               ("fixed", self.fixed), ("fixed_vel", self.fixed_vel),
                               ("prev_force", self.prev)):
                flat[a:e] = getattr(b, name)
                setattr(b, name, flat[a:e])
            for name, flat in (("grad", self.grad), ("vol", self.vol), ("stress", self.stress),
                               ("plastic", self.plastic)):
                flat[za:ze] = getattr(b, name)
                setattr(b, name, flat[za:ze])
            for name, flat in (("scalars", self.scalars), ("work", self.work),
                               ("servo", self.servo)):
                flat[d] = getattr(b, name)
                setattr(b, name, flat[d])
            self.unbalanced[d] = b.unbalanced[0]
            b.unbalanced = self.unbalanced[d:d + 1]
        # the step's scratch (gridpoint forces and loads, mid-step positions, zone strain
        # rates, spins, plastic volumetric corrections)
        self._nscratch = np.empty((5, n, 3))
        self._rate = np.empty((m, 6))
        self._spin = np.empty((m, 3))
        self._sigma_p = np.zeros(m)
        self._runs = None  # the owned grids in runs of one constitutive table (_table_runs)
        self._one_run = None  # whether every rank's are one run (one_run)
        self.gravity = np.asarray(gravity, float)
        self.rows = np.zeros(len(self.bodies), np.int64)
        self.dt = np.inf
        self.halo = None
        # solve.ratio's scale for the grids: the mean gridpoint weight of all zoned blocks
        # (set by resolve), and the last step's largest unbalanced gridpoint force over it
        self.ref_force = 1.0
        self.ratio = 0.0
        # adaptive damping: the grids take the servo's alpha every step (:meth:`step`)
        self.adaptive = False
        # whether the owned (0) and ghost (1) pieces' planes are behind their vertices
        # (:meth:`sync`, :meth:`fresh_planes`)
        self._stale = [False, False]

    @classmethod
    def build(cls, scene, specs, first_gid: int) -> GridStore:
        """The grids of the zoned blocks among ``specs`` (gids from ``first_gid``)."""
        gids, grids = [], []
        for i, s in enumerate(specs):
            if s.zoning is None:
                continue
            mesh, surf_nodes = s.zoning
            mat = scene.materials[s.material]
            body = DeformableBody(mesh, mat.zone_spec(), nmd=s.spec.zones.nmd)
            block_conditions(body, s.spec)
            gids.append(first_gid + i)
            grids.append(ZonedGrid(s.name, body, surf_nodes, np.zeros((len(body.nodes), 3))))
        return cls(scene.gravity, gids, grids)

    def __len__(self) -> int:
        return len(self.bodies)

    def payload(self) -> dict:
        """Each grid by gid, for :func:`pdem.parallel.migrate.rebuild` to send with its
        block (owned grids only: a ghost's owner sends it)."""
        return {g: ZonedGrid(self.names[d], self.bodies[d], self.surf[d],
                             self.force[self.node_start[d]:self.node_start[d + 1]],
                             self.kc[self.node_start[d]:self.node_start[d + 1]])
                for d, g in enumerate(self.gids[:self.n_owned])}

    @classmethod
    def arrived(cls, old: GridStore, blocks, n_owned: int, grids: dict) -> GridStore:
        """The store after a rebuild: the grids of the blocks held now (``grids`` by gid, as
        :func:`~pdem.parallel.migrate.rebuild` returns them), in row order, bound to
        ``blocks``."""
        row_of = {int(g): r for r, g in enumerate(blocks.gid)}
        gids = sorted(grids, key=lambda g: row_of[int(g)])
        new = cls(old.gravity, gids, [grids[g] for g in gids],
                  sum(row_of[int(g)] < n_owned for g in gids))
        new.dt, new.ref_force, new.adaptive = old.dt, old.ref_force, old.adaptive
        new.kjoint = old.kjoint
        new.bind(blocks)
        return new

    def zones_at(self, gids: np.ndarray) -> np.ndarray:
        """The zone count of each block of ``gids`` whose grid is held here (0 for the others:
        rigid blocks, or grids held elsewhere): RCB's work weights."""
        count = dict(zip(self.gids, (len(b.tets) for b in self.bodies), strict=True))
        return np.array([count.get(int(g), 0) for g in gids], np.int64)

    def saved(self) -> dict:
        """Copies of the owned grids by gid (gridpoints, velocities, contact forces, zone
        stresses and plastic state, conditions, energy accumulators): the state a factor of
        safety's trials start from (:meth:`restored`)."""
        return copy.deepcopy(self.payload())

    def restored(self, saved: dict) -> GridStore:
        """A store owning fresh copies of the grids ``saved`` (:meth:`saved`), with this
        one's step and settings: the grids a distribution of the saved blocks sends on."""
        gids = sorted(saved)
        new = GridStore(self.gravity, gids, [copy.deepcopy(saved[g]) for g in gids])
        new.dt, new.ref_force, new.adaptive = self.dt, self.ref_force, self.adaptive
        new.kjoint = self.kjoint
        return new

    def weaken(self, factor: float) -> None:
        """The zones' strength divided by ``factor`` (a factor of safety's trial; 1: the
        material's own): each grid's constitutive table from its material's parameters
        (:func:`~pdem.deformable.constitutive.reduced_table`; elastic zones unchanged)."""
        for b in self.bodies:
            b.model = reduced_table(b.params, factor)
        self._runs = None
        self._one_run = None

    def set_damping(self, mode: str, alpha: float, beta: float = 0.0) -> None:
        """The grids' damping: ``solve.damping.mode`` at the gridpoints (its form,
        pdem.deformable.motion's module doc) with coefficient ``alpha`` (none: 0; adaptive:
        the servo's, followed every step; rayleigh: its mass-proportional constant) and
        Rayleigh damping's stiffness-proportional constant ``beta`` (s; 0 for the others)."""
        form, keep = GRID_DAMPING[mode]
        self.adaptive = mode == "adaptive"
        for b in self.bodies:
            b.damping_mode = form
            b.damping = float(alpha) if keep else 0.0
            b.rayleigh_beta = float(beta)

    def _zone_stiffness(self, d: int) -> np.ndarray:
        """Grid ``d``'s Gershgorin gridpoint stiffness of its zones (eq. 84), on its reference
        (build) geometry: a stage's step and mass scaling are then the same whether the run
        went straight or was restarted (the replay of the stages sees the built grid).
        Computed once (it travels with the body: ``zone_stiffness``)."""
        a, e = self.node_start[d], self.node_start[d + 1]
        if not self.stiffness_known[d]:
            b = self.bodies[d]
            grad = np.empty_like(b.grad)
            vol = np.empty_like(b.vol)
            zone_geometry(b.nodes0, b.tets, grad, vol)
            self.zstiff[a:e] = nodal_stiffness(b.tets, grad, vol, b.params.bulk,
                                               b.params.shear, len(b.nodes0))
            b.zone_stiffness = self.zstiff[a:e]
            self.stiffness_known[d] = True
        return self.zstiff[a:e]

    def _stiffness(self, d: int, kn: float) -> np.ndarray:
        """:meth:`_zone_stiffness` with the joints' normal stiffness at its surface gridpoints
        (eq. 85's ``kn A_i``, ``A_i`` a third of its surface triangles' area, counted twice:
        on the diagonal and coupling). A joint spring couples the gridpoint to the other
        block: its Gershgorin row holds the spring on the diagonal and again off it (eq. 85's
        kn A_i alone bounds the step only against a fixed block). The other block's
        sub-contacts landing on the grid's triangles can load a gridpoint more than its own
        share: :meth:`step` raises its mass then (from the contacts of the step)."""
        b = self.bodies[d]
        return self._zone_stiffness(d) + 2.0 * kn * _shares(b.nodes0, b.mesh.surface)

    def timestep(self, kn: float, owned: bool = False) -> float:
        """The zone term of eq. 88 (:meth:`_stiffness`, the inertial masses): the smallest
        over the grids (``owned``: the owned ones; inf without)."""
        dt = np.inf
        for d in range(self.n_owned if owned else len(self.bodies)):
            b = self.bodies[d]
            dt = min(dt, critical_timestep(self._stiffness(d, kn), b.mass, b.stability_alpha(),
                                           b.rayleigh_beta))
        return float(dt)

    def scale_masses(self, kn: float, dt: float | None) -> None:
        """Mass scaling (``solve.mass_scaling``): each gridpoint's inertial mass raised, where
        it is too light, to make ``dt`` ``GRID_FRAC`` of its critical step (with the grid's
        damping's :func:`~pdem.deformable.motion.stability_alpha`); gravity keeps the true
        masses (``gravity_mass``). ``dt`` None: the
        true masses."""
        for d, b in enumerate(self.bodies):
            if dt is None:
                b.mass[:] = b.emass[:] = b.gravity_mass
                continue
            need = scaled_masses(self._stiffness(d, kn), dt, GRID_FRAC, b.stability_alpha(),
                                 b.rayleigh_beta)
            b.mass[:] = b.emass[:] = np.maximum(b.gravity_mass, need)

    def restage(self, scene, dt: float, alpha: float, comm) -> float:
        """A stage's settings on the grids (``scene``: the scene as the stage has it): its
        damping, its mass scaling to the rigid step ``dt``, and the model step, as
        :meth:`resolve` makes them at the start (collective). Returns the step. ``dt``:
        without mass scaling the rigid blocks' step alone (``inf`` when none is free,
        pdem.resolve.scene_timestep), with it the rigid estimate the grids are scaled to."""
        self.set_damping(scene.solve.damping.mode, alpha, scene.solve.damping.rayleigh[1])
        # the stiffest joint spring, normal or shear: the one every sub-contact's Gershgorin
        # row counts (:func:`joint_stiffness`); with the normal alone a joint whose shear is
        # stiffer raised its gridpoints' masses every step instead (partial density scaling),
        # which made the joint heavy and reflected waves (docs/dynamics.md)
        self.kjoint = joint_stiffness(scene)
        kn = self.kn = self.kjoint
        self.scale_masses(kn, dt if scene.solve.mass_scaling else None)
        grid_dt = min(allgather(comm, GRID_FRAC * self.timestep(kn, owned=True)))
        if scene.solve.mass_scaling and grid_dt >= dt * (1.0 - 1e-9):
            grid_dt = dt
        self.dt = grid_dt
        return min(dt, grid_dt)

    def resolve(self, scene, resolved, comm):
        """The model step: the rigid one or the grids' (eq. 88, with the largest joint normal
        stiffness at the surface gridpoints, times ``GRID_FRAC``; the smallest over the ranks'
        build shares), the smaller; the grids' damping from ``solve.damping``. Not the
        scene's ``timestep.frac`` (0.1 by default): that is the rigid estimate's margin, the
        Gershgorin step is a bound. Without mass scaling ``resolved.dt`` is the rigid
        blocks' step alone (``inf`` when none is free): a zoned block's mass against its
        contacts' stiffness says nothing its grid's bound does not (that bound holds its
        joint springs); with it, the rigid estimate the grids are scaled to."""
        import dataclasses

        self.set_damping(scene.solve.damping.mode, resolved.alpha,
                         scene.solve.damping.rayleigh[1])
        # the stiffest joint spring, normal or shear: the one every sub-contact's Gershgorin
        # row counts (:func:`joint_stiffness`); with the normal alone a joint whose shear is
        # stiffer raised its gridpoints' masses every step instead (partial density scaling),
        # which made the joint heavy and reflected waves (docs/dynamics.md)
        self.kjoint = joint_stiffness(scene)
        kn = self.kn = self.kjoint
        if scene.solve.mass_scaling:  # the grids' masses are scaled to the rigid step
            self.scale_masses(kn, resolved.dt)
        self.dt = min(allgather(comm, GRID_FRAC * self.timestep(kn)))
        if scene.solve.mass_scaling and self.dt >= resolved.dt * (1.0 - 1e-9):
            self.dt = resolved.dt  # scaled for it (up to the round-off of the bound)
        self.ref_force = self.force_scale(scene, comm)
        if self.dt < resolved.dt and comm.rank == 0:
            import logging

            logging.getLogger("pdem").info("%s", self.limit_line(resolved.dt))
        return dataclasses.replace(resolved, dt=min(resolved.dt, self.dt))

    def limit_line(self, rigid: float) -> str:
        """The log line of a model step the grids limit (``self.dt``, below the rigid
        blocks' step ``rigid``; inf: no free rigid block), after :meth:`resolve` or
        :meth:`restage`."""
        other = "no free rigid block" if not math.isfinite(rigid) \
            else f"the rigid blocks' step {rigid:.3g} s"
        return (f"the zoned blocks' grids limit the step: {self.dt:.3g} s ({GRID_FRAC:.2f} of "
                f"their Gershgorin bound with joint stiffness {self.kn:.3g}; {other})")

    def force_scale(self, scene, comm) -> float:
        """``solve.ratio``'s scale for the grids (collective): the larger of the mean
        gridpoint weight and the force of the scene's largest stress (in-situ, boundary, a
        stage's) on a zone face, ``sigma (mean zone volume)^(2/3)`` (FLAC's "average applied
        force" where stresses, not weight, load the model); 1 N if neither."""
        g = float(np.linalg.norm(self.gravity))
        vol = sum(float(b.vol.sum()) for b in self.bodies)
        zones = sum(len(b.vol) for b in self.bodies)
        sums = np.sum(allgather(comm, (g * float(self.gmass.sum()), len(self.gmass), vol, zones)),
                      axis=0)
        weight = float(sums[0] / sums[1]) if sums[1] > 0 else 0.0
        stress = [abs(v) for v in scene.insitu.stress] if scene.insitu is not None else []
        for source in (scene.boundary, *scene.stages):
            for cond in getattr(source, "stress", ()):
                stress.extend(abs(v) for row in cond.sigma() for v in row)
        face = (sums[2] / sums[3]) ** (2.0 / 3.0) if sums[3] > 0 else 0.0
        return max(weight, max(stress, default=0.0) * face) or 1.0

    # ------------------------------------------------------------------ in a model state
    def bind(self, blocks) -> None:
        """Rows of the grids in ``blocks`` (after a distribution) and the maps the kernels
        use: block row -> zoned index, vertex row -> gridpoint."""
        row_of = {int(g): r for r, g in enumerate(blocks.gid)}
        self.rows = np.array([row_of[g] for g in self.gids], np.int64)
        self.dindex = np.full(blocks.n, -1, np.int64)
        self.dindex[self.rows] = np.arange(len(self.rows))
        self.vnode_rows = self.vnode(blocks)
        self.surf_flat = np.concatenate(self.surf).astype(np.int64) if self.surf \
            else np.zeros(0, np.int64)
        self.surf_start = np.concatenate([[0], np.cumsum([len(x) for x in self.surf])]
                                         ).astype(np.int64)
        self.located = None  # the ContactStore whose sc_grid columns sc_node/sc_w hold
        self.sc_node = np.zeros((0, 2, 3), np.int32)
        self.sc_w = np.zeros((0, 2, 3))

    def plan_halo(self, halo) -> None:
        """The per-step forward of the ghost grids' gridpoints (positions and velocities),
        along the blocks' halo plan (``halo.send``/``halo.recv``: rows in gid order on both
        sides)."""
        def nodes_of(rows):
            d = self.dindex[rows]
            d = d[d >= 0]
            return np.concatenate([np.arange(self.node_start[i], self.node_start[i + 1])
                                   for i in d]) if len(d) else np.zeros(0, np.int64)

        self.halo = RowHalo(halo.comm, {r: nodes_of(rows) for r, rows in halo.send.items()},
                            {r: nodes_of(rows) for r, rows in halo.recv.items()}, 6)

    def forward(self, b) -> None:
        """The ghost grids' gridpoints from their owners, and their rows and pieces from
        them (collective among halo neighbours; after the blocks' halo)."""
        if self.halo is not None:
            self.halo.forward((self.nodes, self.vel))
        if self.n_owned < len(self.bodies):
            self.sync(b, ghosts=True)

    def regrid(self, old, new, todo, b, tol):
        """Sub-contacts of the updated contacts of zoned blocks at their gridpoints
        (:func:`pdem.deformable.subcontacts.regrid`)."""
        return regrid(self, old, new, todo, b, tol)

    def rigid_fixed(self, fixed: np.ndarray) -> np.ndarray:
        """``fixed`` (owned rows) with the zoned rows set: the rigid integration leaves
        them alone."""
        out = fixed.copy()
        out[self.rows[:self.n_owned]] = 1
        return out

    def sync(self, b, ghosts: bool = False) -> None:
        """Block rows and piece vertices from the gridpoints: of the owned grids (after a
        grid step) or of the ghosts (after their forward). Their pieces' planes (triangle
        normals and offsets, edge directions) are left behind the vertices until
        :meth:`fresh_planes`."""
        args = self.sync_args(b, ghosts)
        if not len(args[0]):
            return
        refresh_pieces(*args)
        self.planes_moved(ghosts)

    def sync_args(self, b, ghosts: bool = False) -> tuple:
        """:func:`~pdem.deformable.contact.refresh_pieces`' arguments for the owned grids
        or the ghosts (:meth:`sync`; the compiled loop of steps calls it with them)."""
        part = slice(self.n_owned, None) if ghosts else slice(0, self.n_owned)
        ends = slice(part.start, None if ghosts else self.n_owned + 1)
        return (self.rows[part], self.node_start[ends], self.surf_start[ends], self.surf_flat,
                self.nodes, self.vel, self.gmass, b.x, b.v, b.dx, b.radius, b.piece_start,
                b.vert_start, b.verts_local, b.dtheta, b.w, b.L)

    def planes_moved(self, ghosts: bool) -> None:
        """The owned (or ghost) pieces' vertices moved: their planes are made again before
        they are next read (:meth:`fresh_planes`)."""
        if (self.n_owned == len(self.bodies)) if ghosts else self.n_owned == 0:
            return
        self._stale[int(ghosts)] = True

    def fresh_planes(self, b) -> None:
        """The planes of the pieces :meth:`sync` moved since they were last made, from their
        vertices: before anything reads them (a contact update, a snapshot or a migration of
        the blocks' geometry). Only there: a step's contacts read the vertices alone, and the
        planes of 1,000 zoned cubes (108,000 triangles) were 5 % of a rock mass's step; made
        when read, they are the numbers a refresh every step made."""
        for ghosts, stale in enumerate(self._stale):
            if not stale:
                continue
            rows = self.rows[self.n_owned:] if ghosts else self.rows[:self.n_owned]
            piece_planes(rows, b.piece_start, b.verts_local, b.face_start, b.fvert_start,
                         b.face_verts, b.normals_local, b.offsets_local, b.edge_start, b.edges,
                         b.edir_start, b.edirs_local)
            self._stale[ghosts] = False

    def record(self, b, contacts):
        """The contact kernel's :class:`~pdem.deformable.contact.Grid`: the sub-contacts'
        gridpoints (flat) and weights from their ``sc_grid`` columns, turned afresh when the
        contact store changed. The gridpoints are int32 (a rank's flat gridpoint numbers, far
        below 2**31): the force kernel streams these columns every step, 24 bytes a
        sub-contact less than int64's (~3 % of its time on a rock mass of 1,000 zoned cubes)."""
        if self.located is not contacts:
            g = contacts.sub["sc_grid"]
            counts = np.diff(contacts.sc_start)
            n = len(g)
            self.sc_node = np.zeros((n, 2, 3), np.int32)
            self.sc_w = np.zeros((n, 2, 3))
            for side, rows in enumerate((contacts.ia, contacts.ib)):
                d = np.repeat(self.dindex[rows], counts)
                zoned = d >= 0
                base = np.where(zoned, self.node_start[np.maximum(d, 0)], 0)
                self.sc_node[:, side] = np.where(zoned[:, None],
                                                 g[:, TRI[side]].astype(np.int64)
                                                 + base[:, None], 0)
                self.sc_w[:, side] = np.where(zoned[:, None], g[:, W[side]], 0.0)
            self.located = contacts
        return Grid(self.dindex, self.vel, self.force, self.sc_node, self.sc_w, self.kc,
                    self.kjoint)

    def vnode(self, blocks) -> np.ndarray:
        """The gridpoint (flat index) of every vertex row of ``blocks``; -1 for rigid pieces."""
        out = np.full(len(blocks.verts_local), -1, np.int64)
        for d, r in enumerate(self.rows):
            k = blocks.piece_start[r]
            out[blocks.vert_start[k]:blocks.vert_start[k + 1]] = self.node_start[d] + self.surf[d]
        return out

    def remove(self, gids) -> None:
        """Grids of blocks taken out of the model (excavated, deleted, frozen): held still
        and no longer stepped (their zones keep their last stresses)."""
        gone = {int(g) for g in gids}
        for d, g in enumerate(self.gids):
            if g in gone:
                b = self.bodies[d]
                b.active = False
                b.fixed[:] = True
                b.fixed_vel[:] = 0.0
                b.vhist[:] = -1
                b.vel[:] = 0.0
                self.force[self.node_start[d]:self.node_start[d + 1]] = 0.0

    def step(self, dt: float, alpha: float = 0.0) -> int:
        """One grid step of every owned zoned block: forces at t (contacts + gravity +
        zones). Returns the gid of the first block whose grid folded (a zone inverted),
        -1 if none: the stepper's reduction makes every rank raise alike. ``ratio``: the
        largest unbalanced gridpoint force over the mean gridpoint weight (``solve.ratio``).
        ``alpha``: the model's damping constant now, taken under adaptive damping (the
        servo's, eq. 77: rigid blocks and grids damped by one constant).

        The grids step in row order in one kernel call per run of grids of one constitutive
        table (:func:`~pdem.deformable.motion.step_grids`: a rock mass of one material is
        one call), each with the masses, loads and arithmetic of a grid's own
        :func:`~pdem.deformable.motion.cycle`: the loads (a block's ``force`` spread over
        its gridpoints, boundary stresses on its faces) apart, their work booked apart; the
        masses raised where the step's contact springs need it (:func:`inertial_masses`).
        The table is a compile-time constant of the kernel (its model's update,
        pdem.deformable.constitutive): grids of several materials in turn are several calls."""
        big = 0.0
        for run in self.table_runs():
            bad, top = step_grids(*self.step_args(run, dt, alpha))
            if bad >= 0:
                return self.gids[bad]
            big = max(big, top)
        self.ratio = big / self.ref_force
        return -1

    def table_runs(self) -> list:
        """The owned grids as runs ``(d0, d1, table)`` of consecutive grids of one
        constitutive table (:meth:`step`'s kernel calls; none when this rank owns no grid)."""
        if self._runs is None:
            self._runs = self._table_runs()
        return self._runs

    def step_args(self, run: tuple, dt: float, alpha: float) -> tuple:
        """:func:`~pdem.deformable.motion.step_grids`' arguments for a run of grids
        (:meth:`table_runs`) and the step ``dt`` (:meth:`step`; the compiled loop of steps
        calls it with them)."""
        d0, d1, table = run
        q = (dt / (2.0 * GRID_FRAC)) ** 2  # (scaled_masses' factor, as it makes it)
        ap, gf, load, force, mid = self._nscratch
        return (d0, d1, table, dt, q, self.gravity, self.adaptive, float(alpha), self.bloaded,
                self.node_start, self.zone_start, self.scalars, self.moduli, self.work,
                self.servo, self.unbalanced, self.nodes, self.vel, self.force, self.kc,
                self.gmass, self.mass, self.emass, self.zstiff, self.applied, self.fixed,
                self.fixed_vel, self.prev, self.bload, self.quiet, self.tets, self.grad, self.vol,
                self.stress, self.plastic, ap, gf, load, force, mid, self._rate, self._spin,
                self._sigma_p)

    def one_run(self, comm) -> bool:
        """Whether every rank's owned grids step in at most one kernel call (one constitutive
        table): then the compiled loop of steps steps them (pdem.compiled_runs); collective,
        decided once per store and set of tables (:meth:`weaken` makes new ones)."""
        if self._one_run is None:
            self._one_run = all(allgather(comm, len(self.table_runs()) <= 1))
        return self._one_run

    def any_run(self) -> tuple:
        """A run of no grid, for a rank owning none in a compiled loop of steps (the table of
        a ghost grid, else an elastic one: it is not stepped)."""
        if self.bodies:
            return (0, 0, self.bodies[0].model)
        return (0, 0, material({"density": 1.0, "young": 1.0, "poisson": 0.25})[1])

    def _table_runs(self) -> list:
        """The owned grids as runs ``(d0, d1, table)`` of consecutive grids of one
        constitutive table (equal type and constants), each with its zone stiffness known:
        :meth:`step`'s kernel calls."""
        runs = []
        for d in range(self.n_owned):
            self._zone_stiffness(d)
            t = self.bodies[d].model
            if runs and type(runs[-1][2]) is type(t) and runs[-1][2] == t:
                runs[-1][1] = d + 1
            else:
                runs.append([d, d + 1, t])
        return [tuple(r) for r in runs]

    def servo_sums(self) -> np.ndarray:
        """The owned grids' share of the adaptive servo's sums of the last step (eq. 77):
        damping power and sum over the gridpoints of ``|dEk/dt|``."""
        return servo_total(self.servo, self.scalars, self.n_owned)

    def kinetic_at(self, rows, ke: np.ndarray) -> np.ndarray:
        """``ke`` (the kinetic energies of the owned block ``rows``) with those of zoned rows
        replaced by their grids' (:meth:`DeformableBody.kinetic_as_integrated`)."""
        out = np.array(ke, float)
        for j, r in enumerate(np.asarray(rows, np.int64)):
            d = self.dindex[r]
            if 0 <= d < self.n_owned:
                out[j] = self.bodies[d].kinetic_as_integrated()
        return out

    def energy_rows(self, dt: float):
        """The energy budget's view of the owned grids after a step of ``dt``: their block
        rows, kinetic energies (:meth:`DeformableBody.kinetic_as_integrated`, at t - dt/2),
        works since the start (``(k, N_GW)``, pdem.deformable.motion.GW_*), and the change
        that brings their contacts' spring energy from t back to the kinetic energy's time
        t - dt/2: ``dt/2 sum F_c . v`` over their gridpoints (the springs' energy falls at
        the rate ``-F_c . v``; the budget adds the rigid blocks' alike). Without it the
        balance would swing by that term, the joints' force times the gridpoints' motion in
        half a step: 1.2 % of the energy put in at a zoned cube's bounce on a stiff floor
        (docs/deformable.md, "Energy")."""
        own = range(self.n_owned)
        shift = np.empty(self.n_owned)
        for d in own:
            a, e = self.node_start[d], self.node_start[d + 1]
            shift[d] = 0.5 * dt * math.fsum((self.force[a:e] * self.vel[a:e]).ravel().tolist())
        return (self.rows[:self.n_owned],
                np.array([self.bodies[d].kinetic_as_integrated() for d in own]),
                np.array([self.bodies[d].work for d in own]).reshape(len(own), N_GW), shift)



def block_conditions(body: DeformableBody, spec) -> None:
    """A zoned block's ``blocks[i]`` motion keys, at its gridpoints (3DEC's meaning):
    ``velocity`` and ``angular_velocity`` start every gridpoint at ``v + w x (x - c)`` (``c``
    the block's centre of mass); ``fixed`` holds every gridpoint (velocity 0),
    ``velocity_fixed`` prescribes ``velocity`` on every gridpoint; ``force`` is spread over
    the gridpoints by their mass, so it moves the block as it would a rigid one (no moment
    about the centre of mass) and strains it only where the block resists."""
    m = body.gravity_mass
    centre = m @ body.nodes / m.sum()
    v0 = np.asarray(spec.velocity, float)
    if spec.fixed:
        body.fix(slice(None))
        body.vel[:] = 0.0
    elif spec.velocity_fixed:  # (no angular velocity: the scene grammar refuses it)
        for k in range(3):
            body.fix(slice(None), (k,), float(v0[k]))
        body.vel[:] = v0
    else:
        body.vel[:] = v0
        w = np.asarray(spec.angular_velocity, float)
        if w.any():
            body.vel += np.cross(w, body.nodes - centre)
    force = np.asarray(spec.force, float)
    body.loaded = bool(force.any())
    if body.loaded:
        body.applied[:] = np.outer(m / m.sum(), force)


def joint_stiffness(scene) -> float:
    """The stiffest joint's ``max(kn, ks)`` (Pa/m): the spring per area every sub-contact's
    Gershgorin row counts (the 3 x 3 spring ``kn nn + ks (I - nn)`` is bounded by it)."""
    return max(max(float(getattr(j, "kn", 0.0)), float(getattr(j, "ks", 0.0)))
               for j in scene.joints.values())


def inertial_masses(mass: np.ndarray, zone_stiffness: np.ndarray, kc: np.ndarray, dt: float,
                    alpha: float) -> np.ndarray:
    """The masses a grid steps with: ``mass`` (true or scaled at the stage's start), raised
    where the step's contact springs (``kc``, pdem.deformable.contact.contact_forces_grid) with the
    zones' stiffness make ``dt`` more than ``GRID_FRAC`` of the gridpoint's critical step
    (partial density scaling). The stage's estimate counts a surface gridpoint's own area
    share, which bounds the springs at its own sub-contacts but not those of a neighbour
    landing on its triangles: found on a sliver piece between stiff fictitious joints
    (kn = 1e11), whose gridpoints ran away at step 5. Where the estimate holds, the masses
    are ``mass``'s bits."""
    return np.maximum(mass, scaled_masses(zone_stiffness + kc, dt, GRID_FRAC, alpha))


def _shares(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Each gridpoint's share of the surface: a third of its surface triangles' area."""
    area = 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]],
                                         x[tri[:, 2]] - x[tri[:, 0]]), axis=1)
    share = np.zeros(len(x))
    np.add.at(share, tri.ravel(), np.repeat(area / 3.0, 3))
    return share
