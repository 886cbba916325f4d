"""The calculation cycle (docs/architecture.md) as readable orchestration of kernel calls.

One step:
1. motion of every free block by central differences (eqs. 44-52) from the forces at t;
2. sub-contact forces at t + dt from the relative motion of the step (eqs. 15-43);
3. accumulated motion u_acc (eq. 1); blocks past the trigger are remapped into the cell space
   and searched for new neighbours; every ``detect_every`` steps (or when contacts were
   created) the contact geometry is updated (common planes, types, sub-contacts);
4. histories, output and progress at their intervals.
"""

from __future__ import annotations

import logging
import math
import time as wallclock

import numpy as np

from . import __version__
from .config import Scene
from .config.load import dump_scene
from .contact.cellspace import CellSpace, envelopes
from .contact.detect import ALGORITHMS, refresh_contacts, update_verts_world
from .contact.forces import contact_forces, rotation_matrices
from .contact.joint import joint_table
from .dynamics import motion
from .dynamics.timestep import auto_timestep, mass_scale_factors
from .errors import SimulationError, UserError
from .io.checkpoint import new_run_id
from .model.blocks import DYNAMIC_FIELDS
from .model.build import block_store, expand_blocks
from .model.contacts import ContactStore
from .parallel.decomposition import Decomposition, choose_dims
from .parallel.migrate import rebuild
from .timers import Timers

log = logging.getLogger("pdem")

# u_acc trigger as a fraction of CTOL. 3DEC remaps at CTOL; at CTOL/2 no pair can close a gap
# larger than CTOL unseen (each block moves less than CTOL/2 between searches), so a contact
# always exists before two blocks touch.
REMAP_FRACTION = 0.5
# vertices within this fraction of CTOL of the common plane count as touching it
TOUCH_FRACTION = 0.5


class Solver:
    """A pdem model in memory: blocks, contacts, cell space, clock; ``run()`` marches it."""

    def __init__(self, scene: Scene, comm, *, output: bool = True, state=None):
        self.scene = scene
        self.scene_yaml = dump_scene(scene)
        self.comm = comm
        self.timers = Timers()
        self.run_id = comm.bcast(new_run_id() if comm.rank == 0 else None, root=0)
        self.specs = expand_blocks(scene)
        # The static model (shapes, masses, initial state) is built on every rank from the scene,
        # keyed by gid; ranks hold rows of it (owned + ghosts) in self.blocks.
        self.glob, self.group_names = block_store(scene, self.specs)
        g = self.glob
        self.joints, self.pair_joint, _ = joint_table(scene, self.group_names)
        cs = scene.contact
        sizes = np.array([s.shape.volume for s in self.specs]) ** (1.0 / 3.0)
        self.ctol = 0.02 * sizes.min() if cs.ctol == "auto" else float(cs.ctol)
        self.point_area_glob = cs.point_area * sizes**2
        self.algorithm = ALGORITHMS[cs.algorithm]
        self.detect_every = cs.detect_every
        self.refresh_tol = cs.refresh_tolerance * self.ctol
        self.gravity = np.array(scene.gravity, float)
        self.step = 0
        self.time = 0.0
        R = np.zeros((g.n, 3, 3))
        rotation_matrices(g.q, R)
        update_verts_world(g.x, R, g.vert_start, g.verts_local, g.verts_world)
        lo = np.zeros((g.n, 3))
        hi = np.zeros((g.n, 3))
        envelopes(g.vert_start, g.verts_world, 0.5 * self.ctol, lo, hi)
        free = g.fixed == 0
        ext = (hi - lo)[free] if free.any() else hi - lo
        self.cell_size = float(np.mean(ext.max(axis=1))) if cs.cell_size == "auto" \
            else float(cs.cell_size)
        # one tolerance for every rank (it must not depend on which blocks a rank holds)
        self.snap_tol = 1e-9 * max(1.0, float(np.abs(g.verts_world).max(initial=1.0)))
        if state is None:
            self._check_initial_overlaps(cs, lo, hi)
        self._setup_damping()
        self._setup_timestep()
        self.ratio = math.inf
        self.ref_force = self._reference_force()
        # Runaway threshold: no block can honestly move faster than its start speed plus a fall
        # across the whole model (or what gravity and applied loads add over time); ten times
        # that is a blow-up, typically a timestep too large for the stiffness.
        free = g.fixed == 0
        acc = float(np.linalg.norm(self.gravity))
        if free.any():
            acc += float((np.linalg.norm(g.applied_force[free], axis=1) / g.mass[free]).max())
        size = float(np.linalg.norm(hi.max(0) - lo.min(0)))
        v0 = float((np.linalg.norm(g.v, axis=1) + np.linalg.norm(g.w, axis=1) * g.radius)
                   .max(initial=0.0))
        self.speed_limit = (10.0 * (v0 + math.sqrt(2.0 * acc * size)) + 1.0, 2.0 * acc)
        self.stats = motion.new_stats()
        par = scene.parallel
        self.margin = self.cell_size if par.margin == "auto" else float(par.margin)
        dims = choose_dims(comm.size, hi.max(0) - lo.min(0), self.gravity) \
            if par.dims == "auto" else list(par.dims)
        self.decomp = Decomposition(comm, lo.min(0), hi.max(0), dims)
        self.n_rebuilds = 0
        if state is None:
            owner = self.decomp.owner_of(g.x)
            owned = np.nonzero(owner == comm.rank)[0]
            self._distribute(owned, {k: getattr(g, k)[owned] for k in DYNAMIC_FIELDS},
                             ContactStore.empty())
            self.search(np.ones(self.blocks.n, bool))
            self.refresh(all_contacts=True)
            self.compute_forces(0.0)
            b, n = self.blocks, self.n_owned
            motion.stagger_start(b.q[:n], b.v[:n], b.w[:n], b.L[:n], b.mass[:n], b.inertia[:n],
                                 b.mscale[:n], b.fixed[:n], b.vfix[:n], self.total_force()[:n],
                                 b.moment[:n], self.gravity, self.dt, self.scalar_inertia)
            self.halo.forward(b, self.dtheta)
        else:
            self._restore(state)
        self.writer = None
        if output:
            self._open_output()

    def _distribute(self, owned_gids, state, contacts):
        """(Re)build this rank's blocks, contacts and halo (collective), see parallel.migrate."""
        with self.timers.phase("migrate"):
            self.blocks, self.n_owned, self.contacts, self.halo = rebuild(
                self.comm, self.decomp, self.glob, owned_gids, state, contacts,
                0.5 * self.ctol, self.margin)
            b = self.blocks
            self.point_area = self.point_area_glob[b.gid]
            self.R = np.zeros((b.n, 3, 3))
            rotation_matrices(b.q, self.R)
            update_verts_world(b.x, self.R, b.vert_start, b.verts_local, b.verts_world)
            self.lo = np.zeros((b.n, 3))
            self.hi = np.zeros((b.n, 3))
            envelopes(b.vert_start, b.verts_world, 0.5 * self.ctol, self.lo, self.hi)
            # a rank whose brick holds no block has no cell space until blocks arrive
            self.cells = CellSpace(self.lo, self.hi, self.cell_size) if b.n else None
            self.dx = np.zeros((b.n, 3))
            self.dtheta = np.zeros((b.n, 3))
            self.owned_free = b.gid[:self.n_owned][b.fixed[:self.n_owned] == 0]
            self.n_rebuilds += 1

    def redistribute(self):
        """Migrate blocks whose centroid left the brick and rebuild ghosts (collective)."""
        self.flush_histories()
        n = self.n_owned
        b = self.blocks
        self._distribute(b.gid[:n].copy(), {k: getattr(b, k)[:n].copy() for k in DYNAMIC_FIELDS},
                         self.contacts)

    # ------------------------------------------------------------------ set-up
    def _check_initial_overlaps(self, cs, lo, hi):
        """Blocks interpenetrating at start are an input error, named by block."""
        g = self.glob
        tol = 0.1 * self.ctol if cs.overlap_tolerance == "auto" else float(cs.overlap_tolerance)
        cells = CellSpace(lo, hi, self.cell_size)
        pi, pj = cells.candidates(lo, hi, np.ones(g.n, np.uint8))
        if len(pi) == 0:
            return
        probe = ContactStore.empty().with_new_pairs(pi, pj, g.gid[pi], g.gid[pj],
                                                    np.zeros(len(pi), np.int32))
        R = np.zeros((g.n, 3, 3))
        rotation_matrices(g.q, R)
        res = refresh_contacts(
            g.x, R, g.vert_start, g.verts_world, g.face_start, g.normals_local,
            g.edir_start, g.edirs_local, np.ones(g.n), probe.ia, probe.ib, probe.normal,
            probe.point, probe.gap, probe.ctype, probe.warm, np.zeros(probe.n + 1, np.int64),
            *[probe.sub[k] for k in ("sc_pa", "sc_area", "sc_un", "sc_fs", "sc_us", "sc_dil",
                                     "sc_state")],
            np.ones(probe.n, np.uint8), 1e300, TOUCH_FRACTION, self.algorithm, self.snap_tol)
        gaps = probe.gap
        bad = res[0].astype(bool) & (gaps < -tol)
        if bad.any():
            msgs = []
            for c in np.nonzero(bad)[0][:10]:
                na, nb = self.specs[probe.ga[c]].name, self.specs[probe.gb[c]].name
                msgs.append(f"blocks {na!r} and {nb!r} overlap by {-gaps[c]:.4g} m at start "
                            f"(tolerance {tol:.3g} m: contact.overlap_tolerance)")
            from .config import ConfigError

            raise ConfigError(msgs)

    def _setup_damping(self):
        d = self.scene.solve.damping
        self.damping_mode = {"none": motion.NONE, "local": motion.LOCAL,
                             "combined": motion.COMBINED, "viscous": motion.VISCOUS,
                             "adaptive": motion.ADAPTIVE}[d.mode]
        if d.alpha is not None:
            self.alpha = d.alpha
        elif d.mode in ("local", "combined"):
            self.alpha = 0.8
        elif d.mode == "viscous":
            raise UserError("solve.damping.alpha: viscous damping needs alpha (1/s)")
        else:
            self.alpha = 0.0
        self.adaptive_target = d.ratio
        self.scalar_inertia = self.scene.solve.inertia == "scalar"

    def _estimated_stiffness(self) -> np.ndarray:
        """Per block, the stiffness of contacts on a third of its surface (top and bottom of a
        cube): the timestep must be stable before the first contact forms, and must not depend
        on which contacts a rank holds."""
        kmax = float(np.maximum(self.joints["kn"], self.joints["ks"]).max())
        surf = np.array([sum(s.shape.face_area(f) for f in range(s.shape.n_faces))
                         for s in self.specs])
        return kmax * surf / 3.0

    def _setup_timestep(self):
        g = self.glob
        ts = self.scene.solve.timestep
        k = self._estimated_stiffness()
        if self.scene.solve.mass_scaling:
            # static solve: every block gets the critical step of the mean block (eq. 89)
            free = g.fixed == 0
            dt_target = ts.dt or ts.frac * 2.0 * math.sqrt(
                float(np.mean(g.mass[free])) / float(np.mean(k[free])))
            g.mscale[:] = mass_scale_factors(g.mass, k, dt_target, ts.frac, g.inertia, g.radius)
            self.dt = dt_target
        elif ts.dt is not None:
            self.dt = ts.dt
        else:
            self.dt = auto_timestep(g.mass, k, ts.frac, g.inertia, g.radius, g.fixed, g.mscale)
        if not math.isfinite(self.dt):
            raise UserError("solve.timestep: no free block, cannot choose a timestep; give dt")

    def _reference_force(self) -> float:
        """Mean weight (plus applied force) of the free blocks: the unbalanced-ratio scale."""
        g = self.glob
        free = g.fixed == 0
        if not free.any():
            return 1.0
        ref = np.linalg.norm(g.mass[free, None] * self.gravity + g.applied_force[free], axis=1)
        return float(ref.mean()) or 1.0

    # ------------------------------------------------------------------ contacts
    def search(self, active: np.ndarray):
        """Remap ``active`` blocks and create contacts with new neighbours (gap <= CTOL is
        decided by the next refresh; pairs found farther apart are dropped there)."""
        b = self.blocks
        if b.n == 0:
            return 0
        envelopes(b.vert_start, b.verts_world, 0.5 * self.ctol, self.lo, self.hi)
        # Every search maps all blocks afresh, so a grown cell space needs no extra remap; which
        # pairs are found depends only on the envelopes, never on the cell layout (a rank's
        # cell space differs from another's, the contacts they create must not).
        self.cells.grow_to(self.lo, self.hi)
        moving = active & (b.fixed == 0) if self.step > 0 else active
        pi, pj = self.cells.candidates(self.lo, self.hi, moving.astype(np.uint8))
        b.u_acc[active] = 0.0
        if len(pi) == 0:
            return 0
        gi, gj = b.gid[pi], b.gid[pj]
        # this rank computes the contacts in which it owns a free block
        mine = ((b.owned[pi] == 1) & (b.fixed[pi] == 0)) | ((b.owned[pj] == 1) & (b.fixed[pj] == 0))
        keys = np.minimum(gi, gj) * (1 << 31) + np.maximum(gi, gj)
        existing = self.contacts.keys()
        new = ~np.isin(keys, existing) & mine
        if not new.any():
            return 0
        pi, pj, gi, gj = pi[new], pj[new], gi[new], gj[new]
        swap = gi > gj
        ia = np.where(swap, pj, pi)
        ib = np.where(swap, pi, pj)
        ga, gb = b.gid[ia], b.gid[ib]
        _, first = np.unique(ga * (1 << 31) + gb, return_index=True)
        ia, ib, ga, gb = ia[first], ib[first], ga[first], gb[first]
        joint = self.pair_joint[b.group[ia], b.group[ib]].astype(np.int32)
        before = self.contacts.n
        self.contacts = self.contacts.with_new_pairs(ia, ib, ga, gb, joint)
        return self.contacts.n - before

    def refresh(self, all_contacts: bool, periodic: bool = False):
        """Geometry update of contacts: all, or those not yet detected plus (periodically) those
        whose blocks moved more than ``refresh_tol`` since their last update. Like 3DEC's
        "no time wasted on relatively inactive blocks": a resting contact keeps its plane and
        sub-contacts (its overlaps still follow the motion every step)."""
        b = self.blocks
        c = self.contacts
        if periodic:
            c.moved[:] += b.u_geo[c.ia] + b.u_geo[c.ib]
            b.u_geo[:] = 0.0
        if c.n == 0:
            return
        todo = (c.warm == 0) | all_contacts
        if periodic:
            todo |= c.moved > self.refresh_tol
        c.moved[todo] = 0.0
        todo = todo.astype(np.uint8)
        res = refresh_contacts(
            b.x, self.R, b.vert_start, b.verts_world, b.face_start, b.normals_local,
            b.edir_start, b.edirs_local, self.point_area, c.ia, c.ib, c.normal, c.point, c.gap,
            c.ctype, c.warm, c.sc_start, c.sc_pa, c.sc_area, c.sc_un, c.sc_fs, c.sc_us, c.sc_dil,
            c.sc_state, todo, self.ctol, TOUCH_FRACTION, self.algorithm, self.snap_tol)
        keep, start, pa, area, un, fs, us, dil, state = res
        sub = {"sc_pa": pa, "sc_area": area, "sc_un": un, "sc_fn": np.zeros(len(area)),
               "sc_fs": fs, "sc_us": us, "sc_dil": dil, "sc_state": state}
        # normal forces of refreshed sub-contacts are recomputed by the next force update;
        # carry the old ones for untouched contacts so force output stays meaningful
        self.contacts = ContactStore(c.arrays, sub, start).select(keep.astype(bool))

    def compute_forces(self, dt: float):
        b = self.blocks
        c = self.contacts
        b.force[:] = 0.0
        b.moment[:] = 0.0
        j = self.joints
        contact_forces(dt, b.x, self.R, b.v, b.w, self.dtheta, b.force, b.moment,
                       c.ia, c.ib, c.joint, c.normal, c.sc_start, c.sc_pa, c.sc_area,
                       c.sc_un, c.sc_fn, c.sc_fs, c.sc_us, c.sc_dil, c.sc_state,
                       j["kn"], j["ks"], j["tan_phi"], j["tan_psi"], j["cohesion"],
                       j["tension"], j["us_lim"])

    def total_force(self) -> np.ndarray:
        """Contact + applied force (gravity is added by the integrator with the true mass)."""
        return self.blocks.force + self.blocks.applied_force

    # ------------------------------------------------------------------ stepping
    def advance(self):
        """One calculation cycle (docs/architecture.md, docs/parallel.md)."""
        b = self.blocks
        n = self.n_owned
        tm = self.timers
        self.stats[:] = 0.0
        with tm.phase("motion"):
            motion.integrate(b.x[:n], b.q[:n], b.v[:n], b.w[:n], b.L[:n], b.mass[:n],
                             b.inertia[:n], b.fixed[:n], b.vfix[:n], self.total_force()[:n],
                             b.moment[:n], self.gravity, self.dt, self.damping_mode, self.alpha,
                             self.scalar_inertia, b.mscale[:n], b.prev_force[:n],
                             b.prev_moment[:n], self.dx[:n], self.dtheta[:n], self.stats)
            self.step += 1
            self.time += self.dt
            # eq. 1 (bounded by the centroid motion plus rotation times the block radius), the
            # state check and the ghost-rebuild measure, in one kernel
            limit = self.speed_limit[0] + self.speed_limit[1] * self.time
            bad, u_mig_max = motion.motion_bookkeeping(
                self.dx[:n], self.dtheta[:n], b.radius[:n], b.fixed[:n], b.u_acc[:n],
                b.u_geo[:n], b.u_mig[:n], b.v[:n], b.x[:n], limit)
        with tm.phase("halo"):
            self.halo.forward(b, self.dtheta)
        rotation_matrices(b.q, self.R)
        with tm.phase("forces"):
            self.compute_forces(self.dt)
        with tm.phase("search"):
            active = b.u_acc > REMAP_FRACTION * self.ctol
            periodic = self.step % self.detect_every == 0
            created = 0
            if active.any() or periodic:
                update_verts_world(b.x, self.R, b.vert_start, b.verts_local, b.verts_world)
                created = self.search(active) if active.any() else 0
        with tm.phase("contacts"):
            if periodic:
                self.refresh(all_contacts=False, periodic=True)
            elif created:
                self.refresh(all_contacts=False)
        with tm.phase("halo"):
            # one small reduction a step: max unbalanced force, trouble, rebuild needed
            rebuild = bool(n) and u_mig_max > 0.5 * self.margin
            flags = np.array([self.stats[motion.STAT_MAX_FORCE], float(bad >= 0), float(rebuild)])
            if self.comm.size > 1:
                from mpi4py import MPI

                self.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
        if flags[1]:
            self._raise_non_finite(bad)
        if self.damping_mode == motion.ADAPTIVE and self.step % 10 == 0:
            sums = np.array([self.stats[motion.STAT_DAMP_POWER], self.stats[motion.STAT_DEK]])
            if self.comm.size > 1:
                from mpi4py import MPI

                self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
            self.alpha = motion.adaptive_alpha_update(
                self.alpha or 1e-3, sums[0], sums[1], self.adaptive_target, dt=self.dt)
        self.ratio = float(flags[0]) / self.ref_force
        if flags[2] and self.comm.size > 1:
            self.redistribute()

    def _raise_non_finite(self, row: int):
        """Every rank raises the same SimulationError, naming the first bad block (by gid)."""
        b = self.blocks
        mine = (int(b.gid[row]), float(np.sqrt((b.v[row] ** 2).sum()))) if row >= 0 else None
        found = [m for m in (self.comm.allgather(mine) if self.comm.size > 1 else [mine]) if m]
        gid, speed = min(found)
        what = "non-finite state" if not math.isfinite(speed) else f"runaway speed {speed:.3g} m/s"
        raise SimulationError(
            f"step {self.step} (t={self.time:.6g} s): block {self.specs[gid].name!r} has a "
            f"{what}. Probable cause: timestep {self.dt:.3g} s too large for the joint stiffness "
            f"(lower solve.timestep.frac or give a smaller dt) or blocks created deeply "
            f"overlapping.")

    # ------------------------------------------------------------------ output
    def load_report(self) -> dict:
        """Blocks, ghosts and contacts per rank and the imbalance (collective)."""
        mine = (self.n_owned, self.blocks.n - self.n_owned, self.contacts.n, self.halo.bytes_per_step)
        rows = np.array(self.comm.allgather(mine)) if self.comm.size > 1 else np.array([mine])
        owned = rows[:, 0]
        imbalance = float(owned.max() / owned.mean()) if owned.mean() > 0 else 1.0
        return {"owned": rows[:, 0].tolist(), "ghosts": rows[:, 1].tolist(),
                "contacts": rows[:, 2].tolist(), "halo_bytes": rows[:, 3].tolist(),
                "imbalance": imbalance, "rebuilds": self.n_rebuilds}

    def log_load(self):
        r = self.load_report()
        if self.comm.size > 1:
            log.info("load: owned %s ghosts %s contacts %s halo B/step %s; imbalance %.2f; "
                     "rebuilds %d", r["owned"], r["ghosts"], r["contacts"], r["halo_bytes"],
                     r["imbalance"], r["rebuilds"])

    def owned_gids(self) -> np.ndarray:
        return self.blocks.gid[:self.n_owned]

    def _open_output(self):
        from .io.writer import OutputWriter

        out = self.scene.output
        shapes = [s.shape.principal_frame()[0] for s in self.specs]
        faces = [[list(sh.face_verts[sh.face_start[f]:sh.face_start[f + 1]])
                  for f in range(sh.n_faces)] for sh in shapes]
        self.writer = OutputWriter(
            out.file, self.comm, block_names=[s.name for s in self.specs],
            body_vertices=[sh.vertices for sh in shapes], body_faces=faces,
            scene_yaml=self.scene_yaml, initial_centroid=self.glob.x0, group=self.glob.group,
            group_names=self.group_names, fixed=self.glob.fixed,
            attrs={"pdem_version": __version__, "scene_name": self.scene.name, "dt": self.dt,
                   "ctol": self.ctol, "run_id": self.run_id, "first_step": self.step})
        self.histories = []
        names = {s.name: i for i, s in enumerate(self.specs)}
        for h in out.histories:
            name = f"{h.block}.{h.quantity}"
            self.writer.add_history(name, 3, {"block": h.block, "quantity": h.quantity})
            self.histories.append((name, names[h.block], h.quantity, h.every))
        self._next_hist = {h[0]: 0.0 for h in self.histories}
        self._hist_buf = {h[0]: ([], []) for h in self.histories}

    def write_snapshot(self):
        if self.writer is None:
            return
        b = self.blocks
        n = self.n_owned
        with self.timers.phase("io"):
            self.writer.write_snapshot(self.step, self.time, b.gid[:n], b.x[:n], b.q[:n], b.v[:n],
                                       b.w[:n])
        self.flush_histories()

    def sample_histories(self, force: bool = False):
        """Buffer history samples that are due (written in batches by ``flush_histories``)."""
        if self.writer is None or not self.histories:
            return
        b = self.blocks
        for name, gid, qty, every in self.histories:
            due = force or every is None or self.time >= self._next_hist[name] - 1e-9 * self.dt
            if not due:
                continue
            if every is not None:
                while self._next_hist[name] <= self.time + 1e-9 * self.dt:
                    self._next_hist[name] += every
            row = self._owned_row(gid)
            if row < 0:
                continue
            value = {"displacement": b.x[row] - b.x0[row], "position": b.x[row],
                     "velocity": b.v[row], "angular_velocity": b.w[row]}[qty]
            times, values = self._hist_buf[name]
            times.append(self.time)
            values.append(value.copy())

    def _owned_row(self, gid: int) -> int:
        owned = self.blocks.gid[:self.n_owned]
        i = int(np.searchsorted(owned, gid))
        return i if i < len(owned) and owned[i] == gid else -1

    def flush_histories(self):
        """Collective: the owner of each history's block writes its buffered rows."""
        if self.writer is None:
            return
        for name, gid, _, _ in self.histories:
            times, values = self._hist_buf[name]
            mine = self._owned_row(gid) >= 0
            self.writer.write_history(name, np.array(times), np.array(values).reshape(-1, 3)
                                      if mine else None)
            times.clear()
            values.clear()

    # ------------------------------------------------------------------ driver
    def run(self, *, time: float | None = None, steps: int | None = None) -> dict:
        """March until the scene's end condition (or the given model time / step count)."""
        sv = self.scene.solve
        out = self.scene.output
        if time is None and steps is None:
            # the scene's end condition is absolute, so a restart runs to the same end
            end_step, end_time, ratio_target = sv.steps, sv.time, sv.ratio
        else:
            end_step = self.step + steps if steps is not None else None
            end_time = self.time + time if time is not None else None
            ratio_target = None
        max_steps = sv.max_steps or (10_000_000 if ratio_target else None)
        if end_time is not None:
            n_est = int(math.ceil((end_time - self.time) / self.dt))
        elif end_step is not None:
            n_est = end_step - self.step
        else:
            n_est = max_steps
        every_steps = self._interval(out.every_steps, out.every)
        ck = self.scene.checkpoint
        ck_every = self._interval(ck.every_steps, ck.every) if ck else None
        log.info("%s: %d blocks, %d contacts, dt=%.4g s, ctol=%.4g m, %s damping; %d steps",
                 self.scene.name, self.glob.n, self.contacts.n, self.dt, self.ctol,
                 sv.damping.mode, n_est)
        if self.comm.size > 1:
            log.info("decomposition: %s ranks on a %s grid, ghost margin %.3g m",
                     self.comm.size, "x".join(map(str, self.decomp.dims)), self.margin)
        self.log_load()
        if self.step == 0:
            self.write_snapshot()
            self.sample_histories(force=True)
        t0 = wallclock.perf_counter()
        s0 = self.step
        last_report = t0
        while True:
            if end_step is not None and self.step >= end_step:
                break
            if end_time is not None and self.time >= end_time - 1e-9 * self.dt:
                break
            if ratio_target is not None and self.ratio <= ratio_target:
                break
            if max_steps is not None and self.step - s0 >= max_steps:
                log.warning("stopped at solve.max_steps=%d before reaching the target",
                            max_steps)
                break
            try:
                self.advance()
            except SimulationError:
                if ck is not None:  # raised on every rank alike, so this is collective
                    path = self.checkpoint(final=True)
                    log.error("final checkpoint written: %s", path)
                raise
            if ck_every and self.step % ck_every == 0:
                self.checkpoint()
            if self.writer is not None:
                if self.step % every_steps == 0:
                    self.write_snapshot()
                    self.log_load()
                self.sample_histories()
            now = wallclock.perf_counter()
            if now - last_report >= sv.progress_every and self.comm.rank == 0:
                last_report = now
                rate = (self.step - s0) / (now - t0)
                left = (n_est - (self.step - s0)) / rate if rate > 0 and n_est else float("nan")
                log.info("step %d  t=%.5g s  ratio=%.3g  contacts=%d  %.0f steps/s  ETA %.0f s",
                         self.step, self.time, self.ratio, self.contacts.n, rate, left)
        if self.writer is not None:
            if self.step % every_steps != 0:
                self.write_snapshot()
            else:
                self.flush_histories()
        elapsed = wallclock.perf_counter() - t0
        summary = {"steps": self.step - s0, "time": self.time, "ratio": self.ratio,
                   "wall": elapsed, "contacts": self.contacts.n}
        log.info("time per phase (rank 0): %s", self.timers.report())
        log.info("done: %d steps in %.1f s (%.0f steps/s, %.3g block-steps/s), t=%.5g s, "
                 "ratio=%.3g", summary["steps"], elapsed, summary["steps"] / max(elapsed, 1e-9),
                 summary["steps"] * self.glob.n / max(elapsed, 1e-9), self.time, self.ratio)
        return summary

    def _interval(self, every_steps, every) -> int:
        """Steps between outputs: given, or from model seconds, or 100 per scene run."""
        if every_steps:
            return int(every_steps)
        if every:
            return max(1, int(round(every / self.dt)))
        sv = self.scene.solve
        total = sv.steps or (int(math.ceil(sv.time / self.dt)) if sv.time else 100_000)
        return max(1, total // 100)

    def checkpoint(self, final: bool = False) -> str:
        """Write a checkpoint now (collective); keep the newest ``checkpoint.keep``."""
        from .io.checkpoint import prune, write_checkpoint

        ck = self.scene.checkpoint
        prefix = ck.file if ck else "checkpoint"
        name = f"{prefix}-{self.step:09d}{'-failed' if final else ''}.h5"
        with self.timers.phase("io"):
            path = write_checkpoint(name, self)
            if not final:
                prune(prefix, ck.keep if ck else 2, self.comm)
        log.info("checkpoint %s", path)
        return path

    def _restore(self, ck: dict):
        """Continue from a checkpoint's state (any rank count; see pdem.io.checkpoint)."""
        a = ck["attrs"]
        self.step = int(a["step"])
        self.time = float(a["time"])
        self.dt = float(a["dt"])
        self.alpha = float(a["alpha"])
        self.ratio = float(a["ratio"]) if a["ratio"] >= 0 else math.inf
        self.run_id = str(a["run_id"])
        blocks = ck["blocks"]
        owned = np.nonzero(self.decomp.owner_of(blocks["x"]) == self.comm.rank)[0]
        nsub = ck["nsub"]
        start = np.zeros(len(nsub) + 1, np.int64)
        np.cumsum(nsub, out=start[1:])
        contacts = ContactStore(dict(ck["contacts"]), dict(ck["sub"]), start)
        self._distribute(owned, {k: blocks[k][owned] for k in DYNAMIC_FIELDS}, contacts)

    def close(self):
        if self.writer is not None:
            self.writer.close()
            self.writer = None
