"""The calculation cycle compiled: the step's phases, and many steps in one numba call.

A step's first half is defined once, here, as two compiled phases: :func:`motion_phase`
(integrate the owned blocks; the clock, the motion bound and the state check) and
:func:`force_phase` (rotation matrices, the contact forces, the inactive blocks), with the
forward halo between them; its reduction is one record filled by :func:`step_flags`. The
stepper (:meth:`pdem.stepper.Stepper.first_half`) calls the phases for one step, with its
Python hooks between them (boundary loads, a zoned block's grid step, the halo by mpi4py);
:func:`fused_steps` calls them for many.

A small scene spends most of a step in the interpreter (about 70 us of Python per step, for a
few microseconds of arithmetic). Between Python-level events (output, checkpoints, energy
samples, a contact search, a contact geometry update with work to do, the end of the run)
:func:`fused_steps` runs the steps inside one compiled loop, on the same arrays, so the result
is bitwise that of the step-by-step path (and so of any rank count).

The loop does a step's first half and then, if nothing needs Python, its second half. At a
periodic contact update it marks the stale contacts (pdem.contact.staleness) and, if any,
updates them by the stepper's own three calls (:mod:`pdem.contact.update`; not one wrapper
kernel, which would compile the re-detection once more), carrying on with the new sub-contact
columns.
Otherwise it returns after the first half and the stepper finishes that step in Python: a
search, an update that found contacts apart (the stepper drops them from every column), a bad
state, an event.

On several ranks the loop makes the step's two MPI calls itself (pdem.parallel.native): the
forward halo after the motion, and the step's reduction after the contact forces. A rank
that needs Python for a step of its own (a search, a bad state) returns before the
reduction and makes it in Python: the messages are the same, so the other ranks' compiled
calls meet it. What the reduction says (migrate, stop, a bad state anywhere, the ratio
target) ends the loop on every rank after the same step (docs/parallel.md).
"""

from __future__ import annotations

from .contact.detect import refresh_contacts
from .contact.forces import contact_forces
from .contact.staleness import stale_contacts
from .contact.update import begin_update, end_update, keeps_all
from .deformable.contact import contact_forces_grid, refresh_pieces
from .deformable.motion import step_grids
from .dynamics import motion
from .dynamics.inactive import update_inactive
from .dynamics.kinematics import rotation_matrices, world_vertices
from .jit import inline_kernel, kernel
from .model.contacts import Pairs, Subs
from .model.fields import kernel_record
from .parallel.native import allreduce_max, forward_halo

# why a compiled run of steps returned (the stepper finishes the last step in Python)
DONE = 0  # the step budget, a plugin's event step or time, or the ratio target was reached
NEEDS_PYTHON = 1  # a search, a periodic update the stepper must do, or a bad state
# the last step's periodic update was done and found contacts apart: the stepper drops them
# (the returned ``keep``) and finishes the step without updating again
DROPS = 2
# (several ranks) the step's reduction, made in the loop, ends the run of steps on every rank:
# the stepper finishes the step with the reduced flags (``net.reduced``)
REDUCED = 3
# (several ranks) an MPI call in the loop failed (its error code is returned as ``bad``)
MPI_FAILED = 4
# The step's reduction (one Allreduce(MAX) of STEP_FLAGS floats), made by the Python path
# (pdem.stepper.Stepper.second_half) and the compiled one (_reduce) alike, its columns by name:
FLAG_FORCE = 0  # the largest unbalanced force of a free block
FLAG_BAD = 1  # a bad (non-finite) state on some rank
FLAG_MIGRATE = 2  # a block moved past half the ghost margin: migrate after the step
FLAG_LEFT = 3  # a block left the model domain
FLAG_SIGNAL = 4  # the stop signal some rank received (its number)
FLAG_FOLDED = 5  # a folded zone on some rank (1 + its index)
FLAG_GRID_RATIO = 6  # the grids' unbalanced-force ratio
STEP_FLAGS = 7
# the flags that end a compiled run of steps on every rank: FLAG_BAD .. FLAG_FOLDED
STOP_FLAGS = (FLAG_BAD, FLAG_MIGRATE, FLAG_LEFT, FLAG_SIGNAL, FLAG_FOLDED)


# The first half of a step is two compiled phases, called by the stepper for one step (with
# its Python hooks between them: boundary loads, a zoned block's grid step, the halo in
# Python) and by fused_steps for many (with the compiled halo between them): one definition.
# Inlined into fused_steps at numba's level, so a scene that steps only in the compiled loop
# compiles no separate phase (each would cost a few seconds of a cold start).
MOTION = 1  # motion_phase's parts: integrate the owned blocks (eqs. 44-52) ...
CLOCK = 2  # ... and t + dt, eq. 1's motion bound, the state check (after a grid step)
MOTION_AND_CLOCK = MOTION | CLOCK


@inline_kernel
def motion_phase(parts, m, gravity, dt, damping, scalar_inertia, stats, radius, fixed, u_acc,
                 u_geo, u_mig, step, time, speed_limit, speed_growth, max_step):
    """The motion of a step: ``parts`` :data:`MOTION` integrates ``m`` (the owned rows'
    :data:`pdem.dynamics.motion.Motion`, its ``fixed`` the flags the integrator holds;
    ``stats`` zeroed first) and :data:`CLOCK` advances ``step`` and ``time`` and does
    :func:`pdem.dynamics.motion.motion_bookkeeping` with the blocks' true ``fixed`` flags.
    Returns ``(step, time, bad, u_mig_max)`` (``-1``, ``0.0`` without :data:`CLOCK`)."""
    bad = -1
    u_mig_max = 0.0
    if parts & MOTION:
        stats[:] = 0.0
        motion.integrate(m, gravity, dt, damping, scalar_inertia, stats)
    if parts & CLOCK:
        step += 1
        time += dt
        # a block moving more in a step than max_step could tunnel
        bad, u_mig_max = motion.motion_bookkeeping(m.dx, m.dtheta, radius, fixed, u_acc, u_geo,
                                                   u_mig, m.v, m.x,
                                                   speed_limit + speed_growth * time, max_step)
    return step, time, bad, u_mig_max


@inline_kernel
def force_phase(dt, q, R, bodies, pairs, subs, joints, still, grid, m_true, gravity, radius,
                calm, speed, sleep_steps, force_frac, ref_force):
    """The forces of a step, after the forward halo: rotation matrices, the sub-contact
    forces at t + dt (``grid``: the zoned blocks' :class:`pdem.deformable.contact.Grid`, or
    None), and the inactive blocks' bookkeeping (``m_true``: the owned rows' record with the
    true ``fixed`` flags where ``solve.inactive`` holds blocks, else None)."""
    rotation_matrices(q, R)
    bodies.force[:] = 0.0
    bodies.moment[:] = 0.0
    if grid is None:
        contact_forces(dt, bodies, pairs, subs, joints, still)
    else:
        grid.force[:] = 0.0
        grid.kc[:] = 0.0
        contact_forces_grid(dt, bodies, pairs, subs, joints, grid)
    if m_true is not None:
        update_inactive(m_true, gravity, radius, calm, still, speed, sleep_steps, force_frac,
                        ref_force)


@kernel
def step_flags(flags, max_force, bad, rebuild, left, signum, folded, grid_ratio):
    """This rank's side of the step's reduction (:data:`STEP_FLAGS`, by name), for the
    stepper's ``Allreduce`` and the compiled one alike."""
    flags[:] = 0.0
    flags[FLAG_FORCE] = max_force
    flags[FLAG_BAD] = 1.0 if bad >= 0 else 0.0
    flags[FLAG_MIGRATE] = 1.0 if rebuild else 0.0
    flags[FLAG_LEFT] = 1.0 if left else 0.0
    flags[FLAG_SIGNAL] = signum
    flags[FLAG_FOLDED] = folded
    flags[FLAG_GRID_RATIO] = grid_ratio


def motion_record(b, n: int, still: bool = False) -> motion.Motion:
    """The owned rows' arrays for :func:`pdem.dynamics.motion.integrate`; with ``still`` the
    held inactive blocks are fixed for it too (pdem.dynamics.inactive)."""
    return kernel_record(motion.Motion, b, n, fixed=b.still if still else b.fixed)


@kernel
def fused_steps(m, gravity, dt, damping, scalar_inertia, stats, radius, fixed, u_acc, u_geo,
                u_mig,
                q, R, bodies, pairs, subs, joints, c_moved, up, pieces, rel_x, rel_q, radius_all,
                m_true, calm, still,
                speed, sleep_steps, force_frac, remap_at,
                detect_every, refresh_tolerance, stop_at_update, speed_limit, speed_growth,
                step, time, max_steps, stop_step, stop_time, ratio_target, ref_force, max_step,
                todo, net, columns, rebuild_at):
    """Up to ``max_steps`` steps; returns ``(steps, step, time, why, bad, u_mig_max,
    redetected, keep, pairs, subs)``: ``bad`` and ``u_mig_max`` from the last step's
    :func:`pdem.dynamics.motion.motion_bookkeeping`, how many contacts the periodic updates
    re-detected, the last update's ``keep`` (valid when ``why`` is :data:`DROPS`) and the
    contacts' ``pairs``/``subs`` after the updates (a new CSR start and sub-contact columns
    when any contact was re-detected).

    ``m``: the owned rows' :data:`pdem.dynamics.motion.Motion` record (serial: every row),
    ``fixed`` their true flags (:func:`motion_phase`); ``q``, ``R``, ``u_acc``, ``u_geo``,
    ``bodies``, ``radius_all``: all rows; ``rel_x``, ``rel_q``: the contacts' columns the
    periodic check reads (pdem.contact.staleness);
    ``up``: :data:`pdem.contact.update.GeometryUpdate`; ``pieces``: the pieces' centres and
    body-frame vertices (their world vertices are made before an update). Stops after the
    step that reaches ``stop_step`` or ``stop_time`` (a plugin's event, the end of the run) or
    whose unbalanced ratio is at most ``ratio_target`` (negative: none), with the step's
    second half left to the stepper, as for ``NEEDS_PYTHON``. ``stop_at_update``: every
    periodic update goes to Python (the model domain is checked there). ``m_true``: the
    record with the true ``fixed`` flags when inactive blocks are held (``m``'s are
    ``still``; pdem.dynamics.inactive), else None. ``todo`` (uint8, one per contact): where a
    periodic update's staleness marks are written.

    Several ranks: ``net`` (:class:`pdem.parallel.native.Net`) and ``columns`` (the halo
    fields' arrays, :func:`pdem.parallel.halo.halo_columns`); ``rebuild_at``: the
    ghost-rebuild measure that asks for a migration. A serial run passes an idle ``net``
    (``single``, no neighbours: :func:`pdem.parallel.native.idle_net`) and the same columns,
    so that a scene compiles the loop once for any rank count (~1 min a variant), or None
    for both where a halo field is not float64 (``solve.inactive``, which does not fuse on
    ranks). The step's budget and event limits end the loop (``DONE``) before the
    reduction, a step that needs Python on this rank alone (``NEEDS_PYTHON``) too; after the
    reduction ``REDUCED`` when its flags end the loop on every rank, ``DROPS`` as serial.
    """
    n_steps = 0
    redetected = 0
    keep = todo
    while True:
        # first half: the stepper's phases (pdem.stepper.Stepper.first_half)
        step, time, bad, u_mig_max = motion_phase(
            MOTION_AND_CLOCK, m, gravity, dt, damping, scalar_inertia, stats, radius, fixed,
            u_acc, u_geo, u_mig, step, time, speed_limit, speed_growth, max_step)
        n_steps += 1
        single = True  # one rank (with or without an idle ``net``: see the docstring)
        if net is not None:
            single = net.single
            if not single:  # the ghosts' rows from their owners
                rc = forward_halo(net, columns)
                if rc != 0:
                    why, bad = MPI_FAILED, rc
                    break
        force_phase(dt, q, R, bodies, pairs, subs, joints, still, None, m_true, gravity, radius,
                    calm, speed, sleep_steps, force_frac, ref_force)
        periodic = step % detect_every == 0
        own = bad >= 0 or _remap_due(u_acc, remap_at) or (periodic and stop_at_update)
        done = n_steps >= max_steps or step >= stop_step or time >= stop_time
        if single:
            if own:
                why = NEEDS_PYTHON
                break
            if done or stats[motion.STAT_MAX_FORCE] / ref_force <= ratio_target:
                why = DONE
                break
        else:
            if done:  # on every rank after the same step
                why = DONE
                break
            if own:  # this rank makes the step's reduction in Python
                why = NEEDS_PYTHON
                break
            if net is not None:  # (always, here)
                rebuild = m.x.shape[0] > 0 and u_mig_max > rebuild_at
                if _reduce(net, stats[motion.STAT_MAX_FORCE], rebuild, 0.0, 0.0) != 0:
                    why = MPI_FAILED
                    break
                if _reduced_stop(net.reduced, ref_force, ratio_target):
                    why = REDUCED
                    break
        # second half, when no search is due
        # (pdem.stepper.Stepper.second_half with refresh(periodic=True): the stale contacts
        # are updated by the stepper's three calls, pdem.contact.update, inline here: a kernel
        # around them would compile the re-detection once more)
        if periodic:
            u_geo[:] = 0.0
            x = bodies.x
            planes = up.planes
            n = stale_contacts(x, q, R, radius_all, pairs.ia, pairs.ib, rel_x, rel_q,
                               planes.gap, planes.warm, pairs.sc_start, subs.un,
                               refresh_tolerance, c_moved, todo)
            if n == 0:  # nothing to update: its bookkeeping is done
                continue
            redetected += n
            shapes = up.shapes
            world_vertices(x, R, shapes.piece_block, pieces[0], shapes.piece_x,
                           shapes.vert_start, pieces[1], shapes.verts_world)
            before, new = begin_update(x, q, R, up, pairs, subs, joints, c_moved, rel_x, rel_q,
                                       todo)
            keep, start, pa, area, un, fs, us, dil, state, hist = refresh_contacts(
                x, R, shapes, planes, pairs.sc_start, subs, todo, up.ctol, up.touch_frac,
                up.alg, up.trim, up.in_place)
            pairs = Pairs(pairs.ia, pairs.ib, pairs.joint, pairs.normal, start, pairs.held,
                          pairs.frozen)
            subs = Subs(pa, area, un, fs, us, dil, state, hist)
            end_update(x, R, up, pairs, subs, joints, bodies, todo, keep, new, before, True)
            if not keeps_all(keep):
                why = DROPS
                break
    return n_steps, step, time, why, bad, u_mig_max, redetected, keep, pairs, subs


@kernel
def fused_grid_steps(m, gravity, dt, damping, scalar_inertia, stats, radius, fixed, u_acc,
                     u_geo, u_mig, q, R, bodies, pairs, subs, joints, still, grid, grid_step,
                     own_sync, ghost_sync, gids, grid_ref, grid_ratio, remap_at, detect_every,
                     speed_limit, speed_growth, step, time, max_steps, stop_step, stop_time,
                     ratio_target, ref_force, max_step, net, columns, grid_net, grid_columns,
                     rebuild_at):
    """:func:`fused_steps` for a scene with zoned blocks: up to ``max_steps`` steps of the
    stepper's first half with the grid step (pdem.stepper.Stepper.first_half's hooks, the
    same kernels on the same arrays); returns ``(steps, step, time, why, bad, u_mig_max,
    folded, grid_ratio)``: ``folded`` the gid of a zoned block whose grid folded in the last
    step (-1: none), ``grid_ratio`` the grids' unbalanced-force ratio of the last step that
    folded none (``grid_ratio`` as given before the first).

    Between :func:`motion_phase`'s two parts the owned grids step
    (:func:`pdem.deformable.motion.step_grids` with ``grid_step``, its arguments for one
    constitutive table: :meth:`pdem.deformable.store.GridStore.step_args`) and move their
    blocks (:func:`pdem.deformable.contact.refresh_pieces` with ``own_sync``); after the
    blocks' halo the ghost grids' gridpoints come (``grid_net``, ``grid_columns``: the
    gridpoints' positions and velocities) and move theirs (``ghost_sync``); then the forces
    with the zoned blocks' ``grid`` (:class:`pdem.deformable.contact.Grid`). ``m``'s fixed
    flags hold the zoned rows (the rigid integration leaves them to their grids).

    Every periodic contact update, search and bad state returns to Python
    (``NEEDS_PYTHON``): the regrid of a zoned block's sub-contacts is Python's
    (pdem.deformable.subcontacts). ``gids``: the owned grids' block gids, ``grid_ref``
    their ratio's scale. The other arguments and the ends of a run are :func:`fused_steps`'
    (``net`` and ``columns`` as there, never None: ``solve.inactive`` does not fuse with
    zones)."""
    n_steps = 0
    folded = -1
    why = DONE
    bad = -1
    u_mig_max = 0.0
    while True:
        step, time, bad, u_mig_max = motion_phase(
            MOTION, m, gravity, dt, damping, scalar_inertia, stats, radius, fixed, u_acc, u_geo,
            u_mig, step, time, speed_limit, speed_growth, max_step)
        d, big = step_grids(*grid_step)
        if d >= 0:
            folded = gids[d]
        else:
            grid_ratio = big / grid_ref
        refresh_pieces(*own_sync)
        step, time, bad, u_mig_max = motion_phase(
            CLOCK, m, gravity, dt, damping, scalar_inertia, stats, radius, fixed, u_acc, u_geo,
            u_mig, step, time, speed_limit, speed_growth, max_step)
        n_steps += 1
        single = net.single
        if not single:  # the ghosts' rows, then their gridpoints, from their owners
            rc = forward_halo(net, columns)
            if rc == 0 and not grid_net.single:
                rc = forward_halo(grid_net, grid_columns)
            if rc != 0:
                why, bad = MPI_FAILED, rc
                break
        refresh_pieces(*ghost_sync)
        force_phase(dt, q, R, bodies, pairs, subs, joints, still, grid, None, gravity, radius,
                    still, 0.0, 0, 0.0, ref_force)
        own = bad >= 0 or folded >= 0 or step % detect_every == 0 or _remap_due(u_acc, remap_at)
        done = n_steps >= max_steps or step >= stop_step or time >= stop_time
        ratio = max(stats[motion.STAT_MAX_FORCE] / ref_force, grid_ratio)
        if single:
            if own:
                why = NEEDS_PYTHON
                break
            if done or ratio <= ratio_target:
                why = DONE
                break
        else:
            if done:
                why = DONE
                break
            if own:
                why = NEEDS_PYTHON
                break
            rebuild = m.x.shape[0] > 0 and u_mig_max > rebuild_at
            if _reduce(net, stats[motion.STAT_MAX_FORCE], rebuild, 0.0, grid_ratio) != 0:
                why = MPI_FAILED
                break
            if _reduced_stop(net.reduced, ref_force, ratio_target):
                why = REDUCED
                break
    return n_steps, step, time, why, bad, u_mig_max, folded, grid_ratio


@kernel
def _reduce(net, max_force, rebuild, folded, grid_ratio):
    """The step's reduction (pdem.stepper.Stepper.second_half's flags, with no bad state,
    no block out of the model domain, no signal; ``folded`` and the grids' ratio as there):
    0 or MPI's error code."""
    step_flags(net.flags, max_force, -1, rebuild, False, 0.0, folded, grid_ratio)
    return allreduce_max(net)


@kernel
def _reduced_stop(red, ref_force, ratio_target):
    """Whether the reduced flags end the run of steps: a bad state, a migration, a block
    out of the domain, a signal or a folded grid on some rank, or the ratio target (the
    rigid blocks' and the grids', as pdem.stepper.Stepper.second_half makes the ratio)."""
    for k in STOP_FLAGS:
        if red[k] != 0.0:
            return True
    return max(red[FLAG_FORCE] / ref_force, red[FLAG_GRID_RATIO]) <= ratio_target


@kernel
def _remap_due(u_acc, remap_at):
    """Whether a block's accumulated motion calls for a search (the stepper's ``active``)."""
    for i in range(u_acc.shape[0]):
        if u_acc[i] > remap_at:
            return True
    return False
