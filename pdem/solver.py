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
from .dynamics.timestep import auto_timestep, block_stiffness, mass_scale_factors
from .errors import SimulationError, UserError
from .model.build import block_store, expand_blocks
from .model.contacts import ContactStore
from .parallel.mpi import gid_ranges
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

    def __init__(self, scene: Scene, comm, *, output: bool = True):
        self.scene = scene
        self.comm = comm
        self.timers = Timers()
        self.specs = expand_blocks(scene)
        self.blocks, self.group_names = block_store(scene, self.specs)
        b = self.blocks
        self.joints, self.pair_joint, _ = joint_table(scene, self.group_names)
        cs = scene.contact
        sizes = np.array([s.shape.volume for s in self.specs]) ** (1.0 / 3.0)
        self.ctol = 0.02 * sizes.min() if cs.ctol == "auto" else float(cs.ctol)
        self.point_area = cs.point_area * sizes**2
        self.algorithm = ALGORITHMS[cs.algorithm]
        self.detect_every = cs.detect_every
        self.gravity = np.array(scene.gravity, float)
        self.step = 0
        self.time = 0.0
        self.contacts = ContactStore.empty()
        self.R = np.zeros((b.n, 3, 3))
        rotation_matrices(b.q, self.R)
        update_verts_world(b.x, self.R, b.vert_start, b.verts_local, b.verts_world)
        self.lo = np.zeros((b.n, 3))
        self.hi = np.zeros((b.n, 3))
        envelopes(b.vert_start, b.verts_world, 0.5 * self.ctol, self.lo, self.hi)
        free = b.fixed == 0
        ext = (self.hi - self.lo)[free] if free.any() else self.hi - self.lo
        cell = float(np.mean(ext.max(axis=1))) if cs.cell_size == "auto" else float(cs.cell_size)
        self.cells = CellSpace(self.lo, self.hi, cell)
        self._check_initial_overlaps(cs)
        self._setup_damping()
        self._setup_timestep()
        self.refresh_tol = cs.refresh_tolerance * self.ctol
        self.u_geo = np.zeros(b.n)  # motion since the last periodic geometry update
        self.dx = np.zeros((b.n, 3))
        self.dtheta = np.zeros((b.n, 3))
        self.stats = motion.new_stats()
        self.ratio = math.inf
        self.search(np.ones(b.n, bool))
        self.refresh(all_contacts=True)
        self.compute_forces(0.0)
        motion.stagger_start(b.q, b.v, b.w, b.L, b.mass, b.inertia, b.mscale, b.fixed, b.vfix,
                             self.total_force(), b.moment, self.gravity, self.dt,
                             self.scalar_inertia)
        self.writer = None
        if output:
            self._open_output()

    # ------------------------------------------------------------------ set-up
    def _check_initial_overlaps(self, cs):
        """Blocks interpenetrating at start are an input error, named by block."""
        b = self.blocks
        tol = 0.1 * self.ctol if cs.overlap_tolerance == "auto" else float(cs.overlap_tolerance)
        pi, pj = self.cells.candidates(self.lo, self.hi, np.ones(b.n, np.uint8))
        if len(pi) == 0:
            return
        probe = ContactStore.empty().with_new_pairs(pi, pj, b.gid[pi], b.gid[pj],
                                                    np.zeros(len(pi), np.int32))
        res = refresh_contacts(
            b.x, self.R, b.vert_start, b.verts_world, b.face_start, b.normals_local,
            b.edir_start, b.edirs_local, np.ones(b.n), probe.ia, probe.ib, probe.normal,
            probe.point, probe.gap, probe.ctype, probe.warm,
            np.zeros(probe.n + 1, np.int64), *[probe.sub[k] for k in
                                              ("sc_pa", "sc_area", "sc_un", "sc_fs", "sc_us",
                                               "sc_dil",
                                               "sc_state")],
            np.ones(probe.n, np.uint8), 1e300, TOUCH_FRACTION, self.algorithm, self._snap_tol())
        gaps = probe.gap
        keep = res[0].astype(bool)
        bad = keep & (gaps < -tol)
        if bad.any():
            msgs = []
            for c in np.nonzero(bad)[0][:10]:
                na, nb = self.specs[probe.ga[c]].name, self.specs[probe.gb[c]].name
                msgs.append(f"blocks {na!r} and {nb!r} overlap by {-gaps[c]:.4g} m at start "
                            f"(tolerance {tol:.3g} m: contact.overlap_tolerance)")
            from .config import ConfigError

            raise ConfigError(msgs)

    def _snap_tol(self) -> float:
        return 1e-9 * max(1.0, float(np.abs(self.blocks.verts_world).max(initial=1.0)))

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
        cube): the timestep must be stable before the first contact forms."""
        b = self.blocks
        kmax = float(np.maximum(self.joints["kn"], self.joints["ks"]).max())
        surf = np.array([sum(s.shape.face_area(f) for f in range(s.shape.n_faces))
                         for s in self.specs])
        est = kmax * surf / 3.0
        if self.contacts.n:
            c = self.contacts
            counts = np.diff(c.sc_start)
            jrow = np.repeat(c.joint, counts)
            k_area = np.maximum(self.joints["kn"], self.joints["ks"])[jrow] * c.sc_area
            ia = np.repeat(c.ia, counts)
            ib = np.repeat(c.ib, counts)
            est = np.maximum(est, block_stiffness(b.n, ia, ib, k_area))
        return est

    def _setup_timestep(self):
        b = self.blocks
        ts = self.scene.solve.timestep
        k = self._estimated_stiffness()
        if self.scene.solve.mass_scaling:
            # static solve: every block gets the critical step of the mean block (eq. 89)
            free = b.fixed == 0
            dt_target = ts.dt or ts.frac * 2.0 * math.sqrt(
                float(np.mean(b.mass[free])) / float(np.mean(k[free])))
            b.mscale[:] = mass_scale_factors(b.mass, k, dt_target, ts.frac, b.inertia, b.radius)
            self.dt = dt_target
        elif ts.dt is not None:
            self.dt = ts.dt
        else:
            self.dt = auto_timestep(b.mass, k, ts.frac, b.inertia, b.radius, b.fixed, b.mscale)
        if not math.isfinite(self.dt):
            raise UserError("solve.timestep: no free block, cannot choose a timestep; give dt")

    # ------------------------------------------------------------------ contacts
    def search(self, active: np.ndarray):
        """Remap ``active`` blocks and create contacts with new neighbours (gap <= CTOL is
        decided by the next refresh; pairs found farther apart are dropped there)."""
        b = self.blocks
        envelopes(b.vert_start, b.verts_world, 0.5 * self.ctol, self.lo, self.hi)
        if self.cells.grow_to(self.lo, self.hi):
            active = np.ones(b.n, bool)  # the space changed: complete remap
        moving = active & (b.fixed == 0) if self.step > 0 else active
        pi, pj = self.cells.candidates(self.lo, self.hi, moving.astype(np.uint8))
        b.u_acc[active] = 0.0
        if len(pi) == 0:
            return 0
        gi, gj = b.gid[pi], b.gid[pj]
        both_fixed = (b.fixed[pi] == 1) & (b.fixed[pj] == 1)
        keys = np.minimum(gi, gj) * (1 << 31) + np.maximum(gi, gj)
        existing = self.contacts.keys()
        new = ~np.isin(keys, existing) & ~both_fixed
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
            c.moved[:] += self.u_geo[c.ia] + self.u_geo[c.ib]
            self.u_geo[:] = 0.0
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
            c.sc_state, todo, self.ctol, TOUCH_FRACTION, self.algorithm, self._snap_tol())
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
        """One calculation cycle."""
        b = self.blocks
        tm = self.timers
        self.stats[:] = 0.0
        with tm.phase("motion"):
            motion.integrate(b.x, b.q, b.v, b.w, b.L, b.mass, b.inertia, b.fixed, b.vfix,
                             self.total_force(), b.moment, self.gravity, self.dt,
                             self.damping_mode, self.alpha, self.scalar_inertia, b.mscale,
                             b.prev_force, b.prev_moment, self.dx, self.dtheta, self.stats)
            self.step += 1
            self.time += self.dt
            self._check_finite()
            rotation_matrices(b.q, self.R)
        with tm.phase("forces"):
            self.compute_forces(self.dt)
        with tm.phase("search"):
            # eq. 1 (bounded by the centroid motion plus rotation times the block radius)
            moved = np.sqrt((self.dx**2).sum(1)) + np.sqrt((self.dtheta**2).sum(1)) * b.radius
            b.u_acc += moved
            self.u_geo += moved
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
        if self.damping_mode == motion.ADAPTIVE and self.step % 10 == 0:
            self.alpha = motion.adaptive_alpha_update(
                self.alpha or 1e-3, self.stats[motion.STAT_DAMP_POWER],
                self.stats[motion.STAT_DEK], self.adaptive_target, dt=self.dt)
        self.ratio = self.unbalanced_ratio()

    def unbalanced_ratio(self) -> float:
        """Max unbalanced force over the mean weight (plus applied force) of the free blocks:
        3DEC's equilibrium ratio, 0 at rest."""
        b = self.blocks
        free = b.fixed == 0
        if not free.any():
            return 0.0
        ref = np.linalg.norm(b.mass[free, None] * self.gravity + b.applied_force[free], axis=1)
        ref_mean = float(ref.mean())
        if ref_mean == 0.0:
            f = np.linalg.norm(b.force[free], axis=1)
            ref_mean = float(f.mean()) or 1.0
        return float(self.stats[motion.STAT_MAX_FORCE]) / ref_mean

    def _check_finite(self):
        b = self.blocks
        speed = np.sqrt((b.v**2).sum(1))
        bad = ~np.isfinite(speed) | ~np.isfinite(b.x).all(1)
        limit = 1e3 * (1.0 + float(np.sqrt((self.gravity**2).sum())) * max(self.time, 1.0))
        runaway = speed > limit
        if bad.any() or runaway.any():
            i = int(np.nonzero(bad | runaway)[0][0])
            what = "non-finite state" if bad[i] else f"runaway speed {speed[i]:.3g} m/s"
            raise SimulationError(
                f"step {self.step} (t={self.time:.6g} s): block {self.specs[b.gid[i]].name!r} "
                f"has a {what}. Probable cause: timestep {self.dt:.3g} s too large for the "
                f"joint stiffness (lower solve.timestep.frac or dt) or blocks created "
                f"deeply overlapping.")

    # ------------------------------------------------------------------ output
    def owned_gids(self) -> np.ndarray:
        """Until the domain decomposition lands, every rank holds the whole model and owns a
        contiguous gid range for output."""
        r = gid_ranges(self.blocks.n, self.comm.size)
        return np.arange(r[self.comm.rank], r[self.comm.rank + 1])

    def _open_output(self):
        from .io.writer import OutputWriter

        out = self.scene.output
        shapes = [s.shape.principal_frame()[0] for s in self.specs]
        faces = [[list(sh.face_verts[sh.face_start[f]:sh.face_start[f + 1]])
                  for f in range(sh.n_faces)] for sh in shapes]
        self.writer = OutputWriter(
            out.file, self.comm, block_names=[s.name for s in self.specs],
            body_vertices=[sh.vertices for sh in shapes], body_faces=faces,
            scene_yaml=dump_scene(self.scene),
            attrs={"pdem_version": __version__, "scene_name": self.scene.name, "dt": self.dt,
                   "ctol": self.ctol})
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
        rows = self.owned_gids()  # rows == gids while the model is replicated
        self.writer.write_snapshot(self.step, self.time, b.gid[rows], b.x[rows], b.q[rows],
                                   b.v[rows], b.w[rows])
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
            if not self._owns(gid):
                continue
            value = {"displacement": b.x[gid] - b.x0[gid], "position": b.x[gid],
                     "velocity": b.v[gid], "angular_velocity": b.w[gid]}[qty]
            times, values = self._hist_buf[name]
            times.append(self.time)
            values.append(value.copy())

    def _owns(self, gid: int) -> bool:
        r = gid_ranges(self.blocks.n, self.comm.size)
        return bool(r[self.comm.rank] <= gid < r[self.comm.rank + 1])

    def flush_histories(self):
        """Collective: the owner of each history's block writes its buffered rows."""
        if self.writer is None:
            return
        for name, gid, _, _ in self.histories:
            times, values = self._hist_buf[name]
            mine = self._owns(gid)
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
            time, steps = sv.time, sv.steps
        end_step = self.step + steps if steps is not None else None
        end_time = self.time + time if time is not None else None
        ratio_target = sv.ratio if (time is None and steps is None) else None
        max_steps = sv.max_steps or (10_000_000 if ratio_target else None)
        if end_time is not None:
            n_est = int(math.ceil((end_time - self.time) / self.dt))
        elif end_step is not None:
            n_est = end_step - self.step
        else:
            n_est = max_steps
        every_steps = out.every_steps or (
            max(1, int(round(out.every / self.dt))) if out.every else max(1, n_est // 100))
        log.info("%s: %d blocks, %d contacts, dt=%.4g s, ctol=%.4g m, %s damping; %d steps",
                 self.scene.name, self.blocks.n, self.contacts.n, self.dt, self.ctol,
                 sv.damping.mode, n_est)
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
            self.advance()
            if self.writer is not None:
                if self.step % every_steps == 0:
                    self.write_snapshot()
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
        log.info("done: %d steps in %.1f s (%.0f steps/s, %.3g block-steps/s), t=%.5g s, "
                 "ratio=%.3g", summary["steps"], elapsed, summary["steps"] / max(elapsed, 1e-9),
                 summary["steps"] * self.blocks.n / max(elapsed, 1e-9), self.time, self.ratio)
        return summary

    def close(self):
        if self.writer is not None:
            self.writer.close()
            self.writer = None
