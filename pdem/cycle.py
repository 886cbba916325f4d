"""The calculation cycle compiled: many steps of a serial run in one numba call.

A small scene spends most of a step in the interpreter (about 70 us of Python per step, for a
few microseconds of arithmetic). Between Python-level events (output, checkpoints, energy
samples, a contact search, a contact geometry update with work to do, the end of the run)
:func:`fused_steps` runs the steps of :meth:`pdem.stepper.Stepper.advance` inside one compiled
loop, calling the same kernels in the same order on the same arrays, so the result is bitwise
that of the step-by-step path (and so of any rank count, whose steps exchange halos in Python).

The loop does a step's first half (motion, bookkeeping, rotation matrices, contact forces)
and then, if nothing needs Python, its second half: at a periodic contact update with no
contact to update (pdem.contact.staleness: no contact new or stale) it does what
the update would have done, which is only bookkeeping. Otherwise it returns after the first
half and the stepper finishes that step in Python. Runs on several ranks never fuse: their
halo and reductions run every step (docs/architecture.md).
"""

from __future__ import annotations

from .contact.forces import contact_forces
from .contact.staleness import stale_contacts
from .dynamics import motion
from .dynamics.inactive import update_inactive
from .dynamics.kinematics import rotation_matrices
from .jit import kernel

# why a compiled run of steps returned (the stepper finishes the last step in Python)
DONE = 0  # the step budget, a plugin's event step or time, or the ratio target was reached
NEEDS_PYTHON = 1  # a search, a contact update with work, or a bad state
# a periodic contact update with work: ``todo`` and ``c_moved`` hold what
# pdem.contact.staleness.stale_contacts found, for the stepper's update to reuse
STALE_FOUND = 2


@kernel
def _noop_refresh(x, q, R, radius, pairs, rel_x, rel_q, gap, c_moved, c_warm, sc_un, u_geo,
                  refresh_tolerance, todo):
    """True if a periodic contact update would update no contact (pdem.stepper.refresh): then
    its bookkeeping (each contact's relative motion in ``c_moved``, ``u_geo`` reset) is done."""
    if stale_contacts(x, q, R, radius, pairs.ia, pairs.ib, rel_x, rel_q, gap, c_warm,
                      pairs.sc_start, sc_un, refresh_tolerance, c_moved, todo) > 0:
        return False
    u_geo[:] = 0.0
    return True


@kernel
def fused_steps(m, gravity, dt, damping, scalar_inertia, stats, radius, u_acc, u_geo, u_mig,
                q, R, bodies, pairs, subs, joints, c_moved, c_warm, rel_x, rel_q, gap, radius_all,
                m_true, calm, still,
                speed, sleep_steps, force_frac, remap_at,
                detect_every, refresh_tolerance, stop_at_update, speed_limit, speed_growth,
                step, time, max_steps, stop_step, stop_time, ratio_target, ref_force, max_step,
                todo):
    """Up to ``max_steps`` steps; returns ``(steps, step, time, why, bad, u_mig_max)``, the
    last two from the last step's :func:`pdem.dynamics.motion.motion_bookkeeping`.

    ``m``: the owned rows' :data:`pdem.dynamics.motion.Motion` record (serial: every row);
    ``q``, ``R``, ``u_acc``, ``u_geo``, ``bodies``, ``radius_all``: all rows; ``rel_x``,
    ``rel_q``, ``gap``: the contacts' columns the periodic check reads
    (pdem.contact.staleness). Stops after the step that reaches ``stop_step`` or
    ``stop_time`` (a plugin's event, the end of the run) or whose unbalanced ratio is at most
    ``ratio_target`` (negative: none), with the step's second half left to the stepper, as for
    ``NEEDS_PYTHON``. ``stop_at_update``: every periodic update goes to Python
    (the model domain is checked there). ``m_true``: the record with the true ``fixed`` flags
    when inactive blocks are held (``m``'s are ``still``; pdem.dynamics.inactive), else None.
    ``todo`` (uint8, one per contact): where a periodic update's staleness marks are written;
    valid when the call returns :data:`STALE_FOUND`.
    """
    n_steps = 0
    while True:
        # first half: pdem.stepper.Stepper.advance up to the contact forces
        stats[:] = 0.0
        motion.integrate(m, gravity, dt, damping, scalar_inertia, stats)
        step += 1
        time += dt
        n_steps += 1
        bad, u_mig_max = motion.motion_bookkeeping(m.dx, m.dtheta, radius, m.fixed, u_acc, u_geo,
                                           u_mig, m.v, m.x, speed_limit + speed_growth * time,
                                           max_step)
        rotation_matrices(q, R)
        bodies.force[:] = 0.0
        bodies.moment[:] = 0.0
        contact_forces(dt, bodies, pairs, subs, joints, still)
        if m_true is not None:
            update_inactive(m_true, gravity, radius, calm, still, speed, sleep_steps, force_frac,
                            ref_force)
        if bad >= 0:
            return n_steps, step, time, NEEDS_PYTHON, bad, u_mig_max
        for i in range(u_acc.shape[0]):
            if u_acc[i] > remap_at:
                return n_steps, step, time, NEEDS_PYTHON, bad, u_mig_max
        periodic = step % detect_every == 0
        if periodic and stop_at_update:
            return n_steps, step, time, NEEDS_PYTHON, bad, u_mig_max
        if n_steps >= max_steps or step >= stop_step or time >= stop_time or \
                stats[motion.STAT_MAX_FORCE] / ref_force <= ratio_target:
            return n_steps, step, time, DONE, bad, u_mig_max
        # second half, when it is only bookkeeping
        if periodic:
            if not _noop_refresh(bodies.x, q, R, radius_all, pairs, rel_x, rel_q, gap, c_moved,
                                 c_warm, subs.un, u_geo, refresh_tolerance, todo):
                return n_steps, step, time, STALE_FOUND, bad, u_mig_max
