"""The calculation cycle: one step of the model held in a :class:`pdem.state.ModelState`.

One step (``Stepper.advance``; steps 1-3 are the compiled phases of :mod:`pdem.cycle`, which
a compiled run of steps calls too):
1. motion of every free block by central differences (eqs. 44-52) from the forces at t;
2. forward halo: ghosts receive their owners' new pose and velocities;
3. sub-contact forces at t + dt from the relative motion of the step (eqs. 15-43);
4. accumulated motion u_acc (eq. 1); blocks past the trigger are remapped into the cell space
   and searched for new neighbours; every ``detect_every`` steps (or when contacts were
   created) the contact geometry is updated (common planes, types, sub-contacts);
5. one small reduction: the unbalanced force, trouble, whether blocks must migrate, and
   whether a rank received a stop signal (pdem.signals).
"""

from __future__ import annotations

import math

import numpy as np

from . import domain, mpi
from .compiled_runs import CompiledRuns
from .contact import forces
from .contact.detect import refresh_contacts
from .contact.forces import contact_energies, contact_forces
from .contact.rigid import Bodies
from .contact.staleness import stale_contacts
from .contact.update import GeometryUpdate, JointSets, begin_update, end_update, keeps_all
from .cycle import (
    CLOCK,
    FLAG_BAD,
    FLAG_FOLDED,
    FLAG_FORCE,
    FLAG_GRID_RATIO,
    FLAG_LEFT,
    FLAG_MIGRATE,
    FLAG_SIGNAL,
    MOTION,
    MOTION_AND_CLOCK,
    STEP_FLAGS,
    force_phase,
    motion_phase,
    motion_record,
    step_flags,
)
from .deformable.contact import contact_forces_grid
from .deformable.subcontacts import carry_grid_columns
from .dynamics import motion
from .dynamics.diagnosis import explain
from .dynamics.inactive import hold_fixed, inactive_args
from .dynamics.kinematics import update_world_vertices
from .errors import SimulationError
from .insitu import initialise
from .memory import large_blocks_mapped
from .model.contacts import ContactStore, Subs, sub_columns
from .model.fields import kernel_record
from .plugins.energy import energy_totals
from .reinforce import install_elements
from .resolve import REMAP_FRACTION, TOUCH_FRACTION
from .search import search


class Stepper:
    """Advances a ModelState by steps; every method is collective over the state's ranks."""

    def __init__(self, state):
        self.s = state
        self.stats = motion.new_stats()
        # a pdem.signals.StopRequest (or None): polled every step, agreed in the flag reduction
        self.stop = None
        self.stop_signal = 0  # the agreed stop signal after the last step (0: go on)
        self.grid_bad = -1  # gid of a zoned block whose grid folded this step (-1: none)
        self.migrate_due = False  # the last step's reduction asked for a migration
        self.runs = CompiledRuns(self)  # the compiled runs of steps (pdem.compiled_runs)
        # contacts whose geometry was updated since the start (its own update included): a
        # cost figure (bench/fidelity.py)
        self.redetected = 0

    @property
    def holds(self) -> bool:
        """Whether inactive blocks are held (solve.inactive)."""
        return self.s.scene.solve.inactive is not None

    # ------------------------------------------------------------------ start
    def start(self):
        """Contacts of the initial state, its forces, and the staggered start velocities."""
        s = self.s
        s.distribute_initial()
        self.search(np.ones(s.blocks.n, bool))
        self.refresh(all_contacts=True)
        if s.check_overlaps:
            s.check_initial_overlaps()
        if s.scene.insitu is not None:  # joints start loaded by the in-situ stress
            initialise(s)
        if s.reinforcement is not None:  # the elements no stage installs
            install_elements(s, s.scene, None)
        self.compute_forces(0.0)
        b = s.blocks
        if s.boundary is not None:
            s.boundary.at_start(s)
        motion.stagger_start(motion_record(b, s.n_owned), s.gravity, s.dt, s.scalar_inertia)
        s.halo.forward(b)

    # ------------------------------------------------------------------ contacts
    def search(self, active: np.ndarray) -> int:
        """Remap ``active`` blocks and create contacts with new neighbours
        (:func:`pdem.search.search`); the contacts created."""
        return search(self.s, active)

    def refresh(self, all_contacts: bool, periodic: bool = False):
        """Geometry update of contacts: all, or those not yet detected plus (periodically) those
        whose blocks moved more than the refresh tolerance since their last update. Like 3DEC's
        "no time wasted on relatively inactive blocks": a resting contact keeps its plane and
        sub-contacts (its overlaps still follow the motion every step). The update itself is
        :mod:`pdem.contact.update`'s, which a compiled run of steps calls too (pdem.cycle)."""
        s = self.s
        b = s.blocks
        c = s.contacts
        if periodic and s.grids is not None:  # zoned blocks deform: their accumulated motion
            c.moved[:] += b.u_geo[c.ia] + b.u_geo[c.ib]
        if periodic:
            b.u_geo[:] = 0.0
        if c.n == 0:
            return
        if periodic and s.grids is None:  # motion of B relative to A (pdem.contact.staleness)
            todo = np.empty(c.n, np.uint8)
            stale_contacts(b.x, b.q, b.R, b.radius, c.ia, c.ib, c.arrays["rel_x"],
                           c.arrays["rel_q"], c.gap, c.warm, c.sc_start, c.sub["sc_un"],
                           s.resolved.refresh_tolerance, c.moved, todo)
            todo = todo.astype(bool) | all_contacts
        else:
            todo = (c.warm == 0) | all_contacts
            if periodic:
                todo |= c.moved > s.resolved.refresh_tolerance
        if not todo.any():  # nothing to update
            return
        if s.grids is not None:  # the zoned pieces' planes, behind their vertices
            s.grids.fresh_planes(b)
        todo = todo.astype(np.uint8)
        self.redetected += int(np.count_nonzero(todo))
        joints = s.joints.kernel_args
        rigid = s.grids is None
        # the update's three calls (pdem.contact.update), as the compiled loop makes them
        up = self.geometry_update()
        a = c.arrays
        before, new = begin_update(b.x, b.q, b.R, up, c.pairs(), c.subs(), joints, c.moved,
                                   a["rel_x"], a["rel_q"], todo)
        keep, start, *columns = refresh_contacts(b.x, b.R, up.shapes, up.planes, c.sc_start,
                                                 c.subs(), todo, up.ctol, up.touch_frac, up.alg,
                                                 up.trim, up.in_place)
        end_update(b.x, b.R, up, c.pairs()._replace(sc_start=start), Subs(*columns), joints,
                   self.bodies(), todo, keep, new, before, rigid)
        sub = sub_columns(columns)
        # only the store holds the new columns: each is freed once taken (below)
        del a, up, columns
        if rigid:
            s.contacts = self.kept(ContactStore(c.arrays, sub, start), keep)
            return
        # zoned blocks: sub-contacts at their surface gridpoints, found after the update
        # the kept sub-contacts keep their gridpoints
        sub["sc_grid"] = carry_grid_columns(c.sub["sc_grid"], c.sc_start, start, todo)
        all_kept = keeps_all(keep)
        kept = None if all_kept else keep.astype(bool)
        # (the regrid reads the contacts before the update)
        s.contacts = ContactStore(c.arrays, sub, start)
        if not all_kept:
            s.contacts = s.contacts.select(kept)
        del sub
        todo_kept = todo if all_kept else todo[kept]
        s.contacts = s.grids.regrid(c, s.contacts, todo_kept, b, TOUCH_FRACTION * s.ctol)
        # energy budget: what the update changed in the joints' springs, with no work done
        # (after the regrid: the sub-contacts are its own)
        if len(before) == 0:  # (a contact deleted here added 0 to its blocks: nothing to book)
            forces.book_stored_energy(self.bodies(), s.contacts.pairs(), s.contacts.subs(),
                                      joints, todo_kept, motion.WORK_GEOMETRY)
            return
        after = contact_energies(s.contacts.pairs(), s.contacts.subs(), joints, todo_kept)
        if not all_kept:  # a deleted contact's energy after is 0
            after, kept_after = np.zeros(c.n), after
            after[kept] = kept_after
        full = np.zeros(c.n)  # (the marked contacts' energies before, in contact order)
        full[todo != 0] = before
        forces.book_contact_energy(self.bodies(), c.ia, c.ib, after - full,
                                   motion.WORK_GEOMETRY)

    @staticmethod
    def kept(store: ContactStore, keep: np.ndarray) -> ContactStore:
        """``store`` without the contacts an update found apart (``keep`` 0): column by column,
        each dropped once taken. The common case deletes none: no copy of every column (a
        select is a gather of all contact and sub-contact arrays, ~20 ms per 1e5 contacts)."""
        if keeps_all(keep):
            return store
        return store.take_consumed(np.nonzero(keep)[0])

    def geometry_update(self) -> GeometryUpdate:
        """What a contact update reads besides the poses and contacts
        (:data:`pdem.contact.update.GeometryUpdate`)."""
        s = self.s
        b = s.blocks
        planes = s.contacts.planes()
        sets = JointSets(b.face_start, b.normals_local, b.offsets_local, b.face_tag,
                         s.joints.cut_joint) if s.joints.by_set else None
        # set-up (large arrays mapped): the first update's slack stays untouched, untrimmed;
        # zoned blocks: their regrid reads the rows before the update, so not in place
        return GeometryUpdate(b.shapes(), planes, s.ctol, TOUCH_FRACTION, s.algorithm,
                              not large_blocks_mapped(), s.grids is None, sets)

    def bodies(self) -> Bodies:
        b = self.s.blocks
        return kernel_record(Bodies, b)

    def compute_forces(self, dt: float):
        b = self.s.blocks
        c = self.s.contacts
        b.force[:] = 0.0
        b.moment[:] = 0.0
        g = self.s.grids
        if g is None:
            contact_forces(dt, self.bodies(), c.pairs(), c.subs(), self.s.joints.kernel_args,
                           b.still)
        else:
            g.force[:] = 0.0
            g.kc[:] = 0.0
            contact_forces_grid(dt, self.bodies(), c.pairs(), c.subs(),
                                self.s.joints.kernel_args, g.record(b, c))
        if self.s.reinforcement is not None:  # the elements' reactions after the contacts'
            self.s.reinforcement.forces(self.s)

    def restate_forces(self):
        """The contact forces of the state as it stands (collective only in that every rank
        calls it): the sub-contacts' springs as they are (no displacement increment, no
        turn of the planes: the last step turned them), summed onto the blocks afresh."""
        b = self.s.blocks
        turn = b.dtheta.copy()
        b.dtheta[:] = 0.0
        try:
            self.compute_forces(0.0)
        finally:
            b.dtheta[:] = turn

    # ------------------------------------------------------------------ the step
    def advance(self):
        """One calculation cycle (docs/architecture.md, docs/parallel.md); True if blocks must
        migrate now."""
        self.first_half()
        return self.second_half()

    def fusable(self) -> bool:
        """Whether steps may run in one compiled call (:meth:`CompiledRuns.fusable`)."""
        return self.runs.fusable()

    def advance_many(self, max_steps: int, stop_step: int | None = None,
                     stop_time: float | None = None, ratio_target: float | None = None) -> int:
        """Up to ``max_steps`` steps, compiled where they can be (:meth:`CompiledRuns.advance`);
        the steps done, every rank after the same step."""
        return self.runs.advance(max_steps, stop_step, stop_time, ratio_target)

    @property
    def python_steps(self) -> int:
        """Steps :meth:`advance_many` took in Python so far."""
        return self.runs.python_steps

    def first_half(self):
        """Motion, the forward halo and the contact forces of a step: the compiled phases
        (pdem.cycle.motion_phase, force_phase) that a compiled run of steps calls too, with
        this step's Python hooks between them (boundary loads, the zoned blocks' grid step,
        the halo by mpi4py), each phase timed."""
        s = self.s
        b = s.blocks
        n = s.n_owned
        tm = s.timers
        r = s.resolved
        g = s.grids
        hold_fixed(s)
        with tm.phase("motion"):
            if s.boundary is not None:
                # velocity histories at t + dt/2, then boundary stresses at t on the pose at t
                s.boundary.before_step(s)
            rec = motion_record(b, n, self.holds)
            if g is not None:  # zoned blocks move with their grids
                rec = rec._replace(fixed=g.rigid_fixed(rec.fixed))
            # (a grid step between the motion and the clock: the grids move their blocks)
            parts = MOTION if g is not None else MOTION_AND_CLOCK
            while parts:
                s.step, s.time, self.bad, self.u_mig_max = motion_phase(
                    parts, rec, s.gravity, s.dt, s.damping_args(), s.scalar_inertia,
                    self.stats, b.radius[:n], b.fixed[:n], b.u_acc, b.u_geo, b.u_mig[:n],
                    s.step, s.time, r.speed_limit, r.speed_growth, s.max_step)
                if parts == MOTION:
                    self.grid_bad = g.step(s.dt, s.alpha)
                    g.sync(b)
                parts = CLOCK if parts == MOTION else 0
            if s.boundary is not None:  # what the conditions book of the step's motion
                s.boundary.after_motion(s)
        with tm.phase("halo"):
            s.halo.forward(b)
            if g is not None:  # the ghost grids' gridpoints, their rows and pieces
                g.forward(b)
        with tm.phase("forces"):
            speed, sleep_steps, frac = inactive_args(s.scene)
            m_true = None
            if self.holds:
                m_true = motion_record(b, n)
                if g is not None:  # a zoned block is never held: its grid steps on
                    m_true = m_true._replace(fixed=g.rigid_fixed(m_true.fixed))
            force_phase(s.dt, b.q, b.R, self.bodies(), s.contacts.pairs(), s.contacts.subs(),
                        s.joints.kernel_args, b.still,
                        g.record(b, s.contacts) if g is not None else None,
                        m_true, s.gravity, b.radius[:n],
                        b.calm[:n], speed, sleep_steps, frac, r.ref_force)
            if s.reinforcement is not None:  # the elements' step, their reactions added
                s.reinforcement.step(s)

    def second_half(self, updated: bool = False, flags: np.ndarray | None = None) -> bool:
        """Contact search and updates, and the step's one reduction; True if blocks must
        migrate. After :meth:`first_half` or a compiled run of steps (pdem.cycle), which
        leaves ``u_mig`` and the state check to be redone here (both are cheap). ``flags``:
        the reduction, made already by a compiled run of steps on several ranks."""
        s = self.s
        b = s.blocks
        n = s.n_owned
        r = s.resolved
        tm = s.timers
        with tm.phase("search"):
            active = b.u_acc > REMAP_FRACTION * s.ctol
            periodic = s.step % s.scene.contact.detect_every == 0
            created = 0
            if active.any() or periodic:
                update_world_vertices(b)
                created = self.search(active) if active.any() else 0
        with tm.phase("contacts"):
            if periodic and not updated:
                self.refresh(all_contacts=False, periodic=True)
            elif created:
                self.refresh(all_contacts=False)
        with tm.phase("halo"):
            # one small reduction a step: max unbalanced force, trouble, rebuild needed, blocks
            # that left the model domain (looked for at the contact updates), and a stop
            # signal received by any rank (so every rank stops after the same step)
            bad, u_mig_max = self.bad, self.u_mig_max
            rebuild = bool(n) and u_mig_max > 0.5 * r.margin
            left = periodic and s.scene.domain is not None and domain.outside(s).any()
            signum = self.stop.signum if self.stop is not None else 0
            if flags is None:  # (a compiled run of steps makes the same STEP_FLAGS)
                mine = np.zeros(STEP_FLAGS)
                step_flags(mine, self.stats[motion.STAT_MAX_FORCE], bad, rebuild, left,
                           float(signum), float(self.grid_bad + 1),
                           s.grids.ratio if s.grids is not None else 0.0)
                flags = mpi.allreduce_max_array(s.comm, mine)
        self.stop_signal = int(flags[FLAG_SIGNAL])
        if flags[FLAG_FOLDED]:
            self._raise_folded(int(flags[FLAG_FOLDED]) - 1)
        if flags[FLAG_BAD]:
            self._raise_non_finite(bad)
        if flags[FLAG_LEFT]:
            domain.take_out(s, self.bodies())
            flags[FLAG_MIGRATE] = 1.0
        if s.damping.adaptive and s.step % 10 == 0:
            sums = np.array([self.stats[motion.STAT_DAMP_POWER], self.stats[motion.STAT_DEK]])
            if s.grids is not None:  # the gridpoints are nodes of eq. 77's sums too
                sums += s.grids.servo_sums()
            sums = mpi.allreduce_sum_array(s.comm, sums)
            s.alpha = motion.adaptive_alpha_update(
                s.alpha or 1e-3, sums[0], sums[1], s.scene.solve.damping.ratio, dt=s.dt)
        # the unbalanced-force ratio: of the rigid blocks (their largest unbalanced force over
        # the mean block weight) or of the grids (gridpoints over the mean gridpoint weight)
        s.ratio = max(float(flags[FLAG_FORCE]) / r.ref_force, float(flags[FLAG_GRID_RATIO]))
        return bool(flags[FLAG_MIGRATE]) and s.comm.size > 1

    def _raise_folded(self, gid: int):
        """Every rank raises alike: a zoned block's grid folded this step (found by its
        owner, the gid agreed in the step's reduction)."""
        s = self.s
        raise SimulationError(f"step {s.step} (t={s.time:.6g} s): zoned block "
                              f"{s.specs[gid].name!r}: a zone inverted (the grid folded: a load "
                              "or speed too large for its zones)")

    def _raise_non_finite(self, row: int):
        """Every rank raises the same SimulationError, naming the first bad block (by gid) and
        what the energy budget says made it (pdem.dynamics.diagnosis)."""
        s = self.s
        b = s.blocks
        mine = (int(b.gid[row]), float(np.sqrt((b.v[row] ** 2).sum()))) if row >= 0 else None
        found = [m for m in mpi.allgather(s.comm, mine) if m]
        gid, speed = min(found)
        what = "non-finite state" if not math.isfinite(speed) else f"runaway speed {speed:.3g} m/s"
        totals = energy_totals(s) if math.isfinite(speed) else None
        raise SimulationError(
            f"step {s.step} (t={s.time:.6g} s): block {s.specs[gid].name!r} has a {what}."
            + explain(s, totals, s.energy_start, gid))
