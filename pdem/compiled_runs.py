"""Compiled runs of steps: when a stepper's steps may run in one compiled call
(pdem.cycle.fused_steps), how a run of them is scheduled and entered, and how a step that
needs Python on one rank is finished there (docs/architecture.md, "The compiled loop").

The cycle itself is the stepper's (:class:`pdem.stepper.Stepper`: ``first_half``,
``second_half``); this module decides where its steps run.
"""

from __future__ import annotations

import math

import numpy as np

from .cycle import (
    DONE,
    DROPS,
    MPI_FAILED,
    NEEDS_PYTHON,
    REDUCED,
    STEP_FLAGS,
    fused_grid_steps,
    fused_steps,
    motion_record,
)
from .dynamics.inactive import hold_fixed, inactive_args
from .errors import SimulationError
from .jit import drop_linking_ir
from .memory import return_freed_memory
from .model.contacts import ContactStore, sub_columns
from .model.fields import row_width
from .mpi import reduces_nonblocking
from .parallel import native
from .parallel.halo import GRID_HALO_TAG, halo_columns
from .resolve import REMAP_FRACTION

NO_STEP = 2**62  # no step bound for a compiled run of steps
# most steps taken in Python before the compiled loop is tried again, after it returned
# after its first step again and again (CompiledRuns.advance)
PYTHON_RUN = 64


class CompiledRuns:
    """A stepper's compiled runs of steps (every method collective over its ranks)."""

    def __init__(self, stepper):
        self.stepper = stepper
        self.net = None  # (halo, its pdem.parallel.native.Net) for compiled runs on ranks
        self.grid_net = None  # (the grids' halo, its Net) for the zoned blocks' gridpoints
        self.dropped_ir = set()  # the compiled loops whose inlining IR is freed (pdem.jit)
        self.python_run = 0  # steps taken in Python after the loop's last 1-step return
        self.python_left = 0  # of them, still to take
        self.python_steps = 0  # steps taken in Python so far

    def fusable(self) -> bool:
        """Whether steps may run in one compiled call (pdem.cycle), unless ``solve.fused`` is
        off: runs without prescribed boundary motion; with zoned blocks, where each rank's
        grids are of one constitutive table (one kernel call steps them,
        :meth:`pdem.deformable.store.GridStore.one_run`) and without ``solve.inactive``; on
        several ranks also where the ranks spin while they wait (pdem.mpi.configure_waits),
        every halo field is float64 (not with solve.inactive) and MPI can be called from
        compiled code (pdem.parallel.native.link, collective on its first call). Decided
        alike on every rank."""
        st = self.stepper
        s = st.s
        if not (s.scene.solve.fused and not (s.boundary is not None and s.boundary.active)):
            return False
        if s.reinforcement is not None and s.reinforcement.n_nodes:  # (stepped in Python)
            return False
        if s.grids is not None and not (s.scene.solve.inactive is None
                                        and s.grids.one_run(s.comm)):
            return False
        if s.comm.size == 1:
            return True
        # (decided alike on every rank: link is collective)
        return (not reduces_nonblocking(s.comm) and s.scene.solve.inactive is None
                and native.link(s.comm))

    def advance(self, max_steps: int, stop_step: int | None = None,
                stop_time: float | None = None, ratio_target: float | None = None) -> int:
        """Up to ``max_steps`` steps, ending early after the step that reaches ``stop_step`` or
        ``stop_time`` or the ``ratio_target``, or after a step whose reduction asks for a
        migration (``migrate_due``: the caller migrates) or stops the run; compiled runs of
        steps when :meth:`fusable` (one step else). Returns the steps done; every rank returns
        after the same step. ``max_steps`` must be the same on every rank.

        A step that needs Python on this rank (a search, an update that dropped contacts)
        is finished here and the steps go on. Where the compiled loop keeps returning after
        its first step, entering it costs more than a step in Python (~20 us of argument
        checks for a few-block scene), so the next steps are taken in Python, twice as many
        each time it happens again (:data:`PYTHON_RUN` at most), then the loop is tried
        again: both paths give the same bits and make the same MPI calls."""
        st = self.stepper
        s = st.s
        st.migrate_due = False
        if max_steps <= 1 or not self.fusable():
            st.migrate_due = st.advance()
            return 1
        several = s.comm.size > 1
        done = 0
        while True:
            if self.python_left > 0:
                self.python_left -= 1
                self.python_steps += 1
                st.first_half()
                st.migrate_due = st.second_half()
                done += 1
            else:
                steps, why = self.run(max_steps - done, stop_step, stop_time, ratio_target)
                done += steps
                if why == MPI_FAILED:
                    raise SimulationError(f"step {s.step}: an MPI call from compiled code "
                                          f"failed (error code {st.bad}); "
                                          "PDEM_MPI_NATIVE=0 keeps the steps in Python")
                if why == NEEDS_PYTHON and steps == 1:
                    self.python_run = min(2 * self.python_run or 1, PYTHON_RUN)
                    self.python_left = self.python_run
                elif steps > 1:
                    self.python_run = 0
                # after the reduction (in the loop) its flags finish the step; before it (a
                # step this rank needed Python for, or the end of the run of steps) it is made
                # here and meets the other ranks' compiled one
                reduced = self.net[1].reduced.copy() \
                    if several and why in (REDUCED, DROPS) else None
                st.migrate_due = st.second_half(updated=why == DROPS, flags=reduced)
                if why in (DONE, REDUCED):  # on every rank after this step
                    return done
            if st.migrate_due or st.stop_signal:
                return done
            # the reduction said go on: so does every other rank, until its own budget and
            # limits end its steps after the same step as these
            if done >= max_steps or (stop_step is not None and s.step >= stop_step) or \
                    (stop_time is not None and s.time >= stop_time) or \
                    (ratio_target is not None and s.ratio <= ratio_target):
                return done

    def net_for(self, halo):
        """The compiled MPI calls' record for this halo plan (made again after a migration);
        a serial run's is idle."""
        comm = self.stepper.s.comm
        if self.net is None or self.net[0] is not halo:
            if comm.size == 1:  # one compiled loop for any rank count
                net = native.idle_net(row_width(halo.fields), STEP_FLAGS)
            else:
                net = native.make_net(comm, halo, STEP_FLAGS)
            if net is None:  # (link found them on every rank)
                raise SimulationError("internal: the MPI functions went missing")
            self.net = (halo, net)
        return self.net[1]

    def grid_net_for(self, halo):
        """The compiled forward's record for the grids' halo plan
        (:meth:`pdem.deformable.store.GridStore.plan_halo`; idle on one rank or without one)."""
        comm = self.stepper.s.comm
        if self.grid_net is None or self.grid_net[0] is not halo:
            if comm.size == 1 or halo is None:
                net = native.idle_net(6, STEP_FLAGS)
            else:
                net = native.make_net(comm, halo, STEP_FLAGS, GRID_HALO_TAG)
            if net is None:
                raise SimulationError("internal: the MPI functions went missing")
            self.grid_net = (halo, net)
        return self.grid_net[1]

    def _drop_ir(self, loop) -> None:
        """After a compiled loop's first call (loaded, or compiled and saved): its IR for
        inlining is freed."""
        if loop not in self.dropped_ir:
            drop_linking_ir(loop)
            return_freed_memory()
            self.dropped_ir.add(loop)

    def run(self, max_steps: int, stop_step, stop_time, ratio_target):
        """One compiled run of steps (pdem.cycle.fused_steps, or fused_grid_steps with zoned
        blocks): (steps done, why it ended); the contacts' columns are taken over when the
        loop updated them."""
        st = self.stepper
        s = st.s
        hold_fixed(s)
        b = s.blocks
        c = s.contacts
        n = s.n_owned
        r = s.resolved
        if s.damping.adaptive:  # its servo updates every 10 steps, in Python
            nxt = (s.step // 10 + 1) * 10
            stop_step = nxt if stop_step is None else min(stop_step, nxt)
        columns = halo_columns(b, s.halo.fields) if s.halo is not None else None
        net = self.net_for(s.halo) if columns is not None else None
        if net is None and s.comm.size > 1:  # (fusable: only `still` is not float64)
            raise SimulationError("internal: a halo field is not a float64 array")
        st.stats[:] = 0.0
        if s.grids is not None:
            return self.run_grids(max_steps, stop_step, stop_time, ratio_target, net, columns)
        speed, sleep_steps, frac = inactive_args(s.scene)
        todo = np.empty(c.n, np.uint8)
        with s.timers.phase("fused"):
            steps, s.step, s.time, why, st.bad, st.u_mig_max, redetected, keep, pairs, \
                subs = fused_steps(
                    motion_record(b, n, st.holds), s.gravity, s.dt, s.damping_args(),
                    s.scalar_inertia, st.stats, b.radius[:n], b.fixed[:n], b.u_acc, b.u_geo,
                    b.u_mig[:n],
                    b.q, b.R, st.bodies(), c.pairs(), c.subs(), s.joints.kernel_args,
                    c.moved, st.geometry_update(), (b.piece_center, b.verts_local),
                    c.arrays["rel_x"], c.arrays["rel_q"], b.radius,
                    motion_record(b, n) if st.holds else None, b.calm[:n], b.still,
                    speed, sleep_steps, frac,
                    REMAP_FRACTION * s.ctol, s.scene.contact.detect_every,
                    r.refresh_tolerance, s.scene.domain is not None, r.speed_limit,
                    r.speed_growth, s.step, s.time, max_steps,
                    NO_STEP if stop_step is None else stop_step,
                    math.inf if stop_time is None else stop_time,
                    -1.0 if ratio_target is None else ratio_target, r.ref_force, s.max_step,
                    todo, net, columns, 0.5 * r.margin)
        self._drop_ir(fused_steps)
        st.redetected += redetected
        if redetected:  # the loop updated contacts (pdem.contact.update): their new columns
            sub = sub_columns(subs)
            start = pairs.sc_start
            del pairs, subs
            s.contacts = ContactStore(c.arrays, sub, start)
            if why == DROPS:  # the last update found contacts apart
                s.contacts = st.kept(s.contacts, keep)
        return steps, why

    def run_grids(self, max_steps: int, stop_step, stop_time, ratio_target, net, columns):
        """:meth:`run` with zoned blocks (pdem.cycle.fused_grid_steps): the owned grids'
        one run of a constitutive table (:meth:`fusable`), their sync and halo arguments."""
        st = self.stepper
        s = st.s
        b = s.blocks
        n = s.n_owned
        r = s.resolved
        g = s.grids
        runs = g.table_runs()
        run = runs[0] if runs else g.any_run()
        if columns is None:  # (fusable: not with solve.inactive)
            raise SimulationError("internal: a halo field is not a float64 array")
        m = motion_record(b, n)
        with s.timers.phase("fused"):
            steps, s.step, s.time, why, st.bad, st.u_mig_max, folded, g.ratio = \
                fused_grid_steps(
                    m._replace(fixed=g.rigid_fixed(m.fixed)), s.gravity, s.dt,
                    s.damping_args(), s.scalar_inertia, st.stats, b.radius[:n], b.fixed[:n],
                    b.u_acc, b.u_geo, b.u_mig[:n], b.q, b.R, st.bodies(), s.contacts.pairs(),
                    s.contacts.subs(), s.joints.kernel_args, b.still,
                    g.record(b, s.contacts), g.step_args(run, s.dt, s.alpha),
                    g.sync_args(b), g.sync_args(b, ghosts=True),
                    np.array(g.gids[:g.n_owned], np.int64), g.ref_force, g.ratio,
                    REMAP_FRACTION * s.ctol, s.scene.contact.detect_every, r.speed_limit,
                    r.speed_growth, s.step, s.time, max_steps,
                    NO_STEP if stop_step is None else stop_step,
                    math.inf if stop_time is None else stop_time,
                    -1.0 if ratio_target is None else ratio_target, r.ref_force, s.max_step,
                    net, columns, self.grid_net_for(g.halo), (g.nodes, g.vel), 0.5 * r.margin)
        self._drop_ir(fused_grid_steps)
        st.grid_bad = int(folded)
        g.planes_moved(False)
        g.planes_moved(True)
        return steps, why
