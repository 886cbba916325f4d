"""Per-step sub-contact force update and assembly on the blocks (eqs. 15, 20-32)."""

from __future__ import annotations

import math

import numpy as np
from numba.extending import overload

from ..jit import access, force_kernel, inline_kernel, kernel
from .laws import OPEN, SLIPPING, apply_law, joint_dissipation, law_energy, law_stays_open
from .rigid import (
    WORK_DAMPING,
    add_point_force,
    apply_pair,
    energy_shares,
    pair_motion,
    point_motion,
)

# Both the normal's renormalisation and the shear force's rescaling after a turn are a square
# root of a number within ~dθ² of 1. A sampling profile of the cube stack (perf, cpu-clock)
# put ~11 % of the force loop on the normal's sqrt and division alone: the next sub-contact's
# arithmetic waits for them. Within 1e-6 of 1 a two-term series is exact to rounding (the
# first term left out is below 4e-19, a 300th of an ulp); beyond, the library root.
SERIES_RANGE = 1e-6


@inline_kernel
def unit_scale(m2):
    """``1 / sqrt(m2)``, by ``1 - e/2 + 3e²/8`` (e = m2 - 1) when m2 is within
    :data:`SERIES_RANGE` of 1: no square root, no division."""
    e = m2 - 1.0
    if -SERIES_RANGE < e < SERIES_RANGE:
        return 1.0 - e * (0.5 - 0.375 * e)
    return 1.0 / math.sqrt(m2)


@inline_kernel
def root_near_one(r):
    """``sqrt(r)``, by ``1 + d/2 - d²/8`` (d = r - 1) when r is within :data:`SERIES_RANGE`
    of 1: no square root."""
    d = r - 1.0
    if -SERIES_RANGE < d < SERIES_RANGE:
        return 1.0 + d * (0.5 - 0.125 * d)
    return math.sqrt(r)


@inline_kernel
def turn_normal(normal, dtheta, c, a, b):
    """Turn contact c's plane normal with the mean incremental rotation of its blocks."""
    nx, ny, nz = normal[c, 0], normal[c, 1], normal[c, 2]
    tx = 0.5 * (dtheta[a, 0] + dtheta[b, 0])
    ty = 0.5 * (dtheta[a, 1] + dtheta[b, 1])
    tz = 0.5 * (dtheta[a, 2] + dtheta[b, 2])
    mx = nx + (ty * nz - tz * ny)
    my = ny + (tz * nx - tx * nz)
    mz = nz + (tx * ny - ty * nx)
    inv = unit_scale(mx * mx + my * my + mz * mz)
    nx, ny, nz = mx * inv, my * inv, mz * inv
    normal[c, 0], normal[c, 1], normal[c, 2] = nx, ny, nz
    return nx, ny, nz


@inline_kernel
def carry_shear(fx, fy, fz, nx, ny, nz):
    """Eq. 23: keep the shear force in the (turned) plane, magnitude preserved."""
    fdn = fx * nx + fy * ny + fz * nz
    if fdn != 0.0:
        mag0 = fx * fx + fy * fy + fz * fz
        fx -= fdn * nx
        fy -= fdn * ny
        fz -= fdn * nz
        mag1 = fx * fx + fy * fy + fz * fz
        if mag1 > 0.0:
            sc = root_near_one(mag0 / mag1)
            fx *= sc
            fy *= sc
            fz *= sc
    return fx, fy, fz


def has_dashpots(dash):
    """Whether the joints' ``dash`` (:data:`pdem.contact.laws.Joints`) holds dashpots: a
    compile-time constant (its rows, 2-d; without Rayleigh damping an empty 1-d array), so
    a scene without them compiles the force loops without a branch of their code."""
    return dash.ndim == 2


def dashpot_constants(dash, j):
    """``(beta kn, beta ks)`` of joint row ``j`` (0, 0 without dashpots)."""
    return (dash[j, 0], dash[j, 1]) if dash.ndim == 2 else (0.0, 0.0)


@overload(has_dashpots, inline="always")
def _has_dashpots(dash):
    if dash.ndim == 2:
        return lambda dash: True
    return lambda dash: False


@overload(dashpot_constants, inline="always")
def _dashpot_constants(dash, j):
    if dash.ndim == 2:
        return lambda dash, j: (dash[j, 0], dash[j, 1])
    return lambda dash, j: (0.0, 0.0)


@inline_kernel
def dashpot(cn, cs, area, vx, vy, vz, nx, ny, nz, dt):
    """Rayleigh damping's stiffness-proportional term at a closed sub-contact: the viscous
    force on B ``-(cn A v_n n + cs A v_s)`` (``cn = beta kn``, ``cs = beta ks`` per unit
    area, ``v`` the velocity of B relative to A at t - dt/2, as the joint's increment uses
    it, split into its normal and shear parts), and the energy it takes out over the step,
    ``(cn A v_n^2 + cs A |v_s|^2) dt`` (>= 0; the work of the force at that velocity)."""
    vn = vx * nx + vy * ny + vz * nz
    sx = vx - vn * nx
    sy = vy - vn * ny
    sz = vz - vn * nz
    an = cn * area
    as_ = cs * area
    fn = an * vn
    return (-(fn * nx + as_ * sx), -(fn * ny + as_ * sy), -(fn * nz + as_ * sz),
            (fn * vn + as_ * (sx * sx + sy * sy + sz * sz)) * dt)


@access(reads="x R v w dtheta force moment fixed work still ia ib joint normal held frozen sc_pa "
              "sc_area sc_un sc_fs sc_us sc_dil sc_state sc_hist",
        writes="force moment work normal held frozen sc_un sc_fs sc_us sc_dil sc_state sc_hist")
@force_kernel
def contact_forces(dt, bodies, pairs, subs, joints, still):
    """Advance every sub-contact by one step and add the contact forces to the blocks.

    ``bodies`` (:class:`pdem.contact.rigid.Bodies`), ``pairs`` and ``subs``
    (:mod:`pdem.model.contacts`), ``joints`` (:class:`pdem.contact.laws.Joints`).
    The relative displacement increment at each sub-contact is ``V dt`` with ``V`` the velocity
    of B relative to A there (eq. 15, 20), split into normal and shear parts (eqs. 21-22). The
    common-plane normal turns with the mean incremental rotation of the two blocks, and the
    existing shear force is turned with it (eq. 23). Forces follow the joint law and are summed
    on both blocks (eqs. 28-32) in contact order, which is the canonical key order, so the sum
    does not depend on how contacts were distributed over ranks.

    Sign convention: ``n`` points from A to B; the force on B is ``fn n + fs`` (``fn`` > 0 in
    compression) and the force on A is its opposite. (Eq. 28 writes the action with the
    opposite sign and correspondingly flips eq. 29/31.)

    ``still`` (blocks): 1 for fixed or held inactive blocks (pdem.dynamics.inactive), all 0
    without ``solve.inactive``. A contact between two still blocks keeps the force it had when
    they became still (``pairs.held``, valid while ``pairs.frozen``) instead of updating its
    joint: neither block moves, so the joint would see no motion. Without ``solve.inactive``
    ``pairs.held`` has no columns (pdem.model.fields.held_width) and is never read or written.

    Rayleigh damping's stiffness term (``joints.dash``, rows only where the scene's ``beta``
    is positive, :func:`has_dashpots`): every sub-contact the law leaves closed adds
    :func:`dashpot`'s viscous force to the force its blocks feel (never to the joint's stored
    force: the joint keeps its elastic and plastic history), and what the dashpots took out
    is booked on the blocks' ``work[:, WORK_DAMPING]`` as joint dissipation is. Without
    dashpots the loop compiles without their code: the undamped step's operations, and
    speed, are as they were.
    """
    holds = pairs.held.shape[1] != 0
    # bound once above the loop, as the zoned kernel binds its arrays
    dash = joints.dash
    damped = has_dashpots(dash)
    for c in range(pairs.ia.shape[0]):
        # unsigned, as the sub-contact index below: no negative-index wrap on the ~40 block-row
        # reads and writes of a contact (3% of the loop on the 10³ cube stack, same bits)
        a = np.uint64(pairs.ia[c])
        b = np.uint64(pairs.ib[c])
        both_still = holds and still[a] != 0 and still[b] != 0
        if both_still and pairs.frozen[c]:
            h = pairs.held
            apply_pair(bodies, a, b, pair_motion(bodies, a, b),
                       (h[c, 0], h[c, 1], h[c, 2], h[c, 3], h[c, 4], h[c, 5]), 0.0)
            continue
        pairs.frozen[c] = 0
        nx, ny, nz = turn_normal(pairs.normal, bodies.dtheta, c, a, b)
        s0 = pairs.sc_start[c]
        s1 = pairs.sc_start[c + 1]
        if s1 == s0:
            continue
        rel = pair_motion(bodies, a, b)
        jrow = pairs.joint[c]
        slot = joints.slot[jrow]
        j = joints.row[jrow]
        acc = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        dissipated = 0.0
        damped_out = 0.0
        cn, cs = dashpot_constants(dash, jrow)
        # unsigned: numba then drops the negative-index wrap of every sub-contact column read
        for s in range(np.uint64(s0), np.uint64(s1)):
            rax, ray, raz, vx, vy, vz = point_motion(rel, subs.pa[s, 0], subs.pa[s, 1],
                                                     subs.pa[s, 2])
            dun = (vx * nx + vy * ny + vz * nz) * dt  # eqs. 20-21
            dsx = vx * dt - dun * nx  # eq. 22
            dsy = vy * dt - dun * ny
            dsz = vz * dt - dun * nz
            un0 = subs.un[s]
            un = un0 - dun
            subs.un[s] = un
            ux = subs.us[s, 0] + dsx
            uy = subs.us[s, 1] + dsy
            uz = subs.us[s, 2] + dsz
            subs.us[s, 0], subs.us[s, 1], subs.us[s, 2] = ux, uy, uz
            area = subs.area[s]
            dil0 = subs.dil[s]
            st0 = subs.state[s]
            # Separated and staying so (a third or more of a settled stack's sub-contacts: its
            # diagonal neighbours): the law would return zero forces and the same state, so
            # only its zero shear force is stored. Its force, +0, would leave every sum as it
            # is (the sums start at +0 and never become -0), and it dissipates nothing.
            if st0 & OPEN and law_stays_open(joints.laws, slot, j, s, subs.hist, un, dil0,
                                             area, st0):
                subs.fs[s, 0], subs.fs[s, 1], subs.fs[s, 2] = 0.0, 0.0, 0.0
                continue
            fx, fy, fz = carry_shear(subs.fs[s, 0], subs.fs[s, 1], subs.fs[s, 2], nx, ny, nz)
            gx, gy, gz = fx, fy, fz
            fn, dil, st, fx, fy, fz = apply_law(
                joints.laws, slot, j, s, subs.hist, un, dil0, fx, fy, fz, dsx, dsy, dsz,
                area, ux, uy, uz, st0)
            # stored only when changed: a sticking joint's lines of these stay clean
            if dil != dil0:
                subs.dil[s] = dil
            if st != st0:
                subs.state[s] = st
            subs.fs[s, 0], subs.fs[s, 1], subs.fs[s, 2] = fx, fy, fz
            # Energy budget: the work done on the joint over the step (trapezoid) less the
            # change of its stored energy is what it dissipated. For an elastic step of linear
            # springs that is exactly zero, so it is evaluated only when the joint yielded
            # (SLIPPING) or changed state or dilation: the common elastic step costs nothing.
            if (st & SLIPPING) or st != st0 or dil != dil0:
                dissipated += joint_dissipation(joints.laws, slot, j, s, subs.hist, dun, dsx,
                                                dsy, dsz, area, un0, dil0, gx, gy, gz, st0, un,
                                                dil, fn, fx, fy, fz, st)
            # force on B (eq. 28 with our sign) at the sub-contact
            tx, ty, tz = fx + fn * nx, fy + fn * ny, fz + fn * nz
            if damped and not st & OPEN:
                dx, dy, dz, de = dashpot(cn, cs, area, vx, vy, vz, nx, ny, nz, dt)
                tx += dx
                ty += dy
                tz += dz
                damped_out += de
            acc = add_point_force(acc, rax, ray, raz, tx, ty, tz)
        apply_pair(bodies, a, b, rel, acc, dissipated)
        if damped:
            book_on_blocks(bodies, a, b, damped_out, WORK_DAMPING)
        if both_still:
            h = pairs.held
            h[c, 0], h[c, 1], h[c, 2], h[c, 3], h[c, 4], h[c, 5] = acc
            pairs.frozen[c] = 1


@inline_kernel
def spring_energy(pairs, subs, joints, c):
    """Spring energy stored in contact c's joint: its sub-contacts' sum, in their order."""
    jrow = pairs.joint[c]
    slot = joints.slot[jrow]
    j = joints.row[jrow]
    e = 0.0
    for s in range(pairs.sc_start[c], pairs.sc_start[c + 1]):
        _, es = law_energy(joints.laws, slot, j, s, subs.hist, subs.un[s], subs.dil[s],
                           subs.fs[s, 0], subs.fs[s, 1], subs.fs[s, 2], subs.area[s],
                           subs.state[s])
        e += es
    return e


@kernel
def stored_energy(bodies, pairs, subs, joints, out):
    """Spring energy stored in every contact's joint, booked on its blocks as the dissipation
    is (:func:`pdem.contact.rigid.energy_shares`): ``out[b] +=`` block b's share."""
    for c in range(pairs.ia.shape[0]):
        a = pairs.ia[c]
        b = pairs.ib[c]
        e = spring_energy(pairs, subs, joints, c)
        wa, wb = energy_shares(bodies, a, b)
        out[a] += wa * e
        out[b] += wb * e


@kernel
def normal_forces(pairs, subs, joints, out):
    """``out[s]``: sub-contact s's normal force by its law in its stored state (overlap,
    dilation, state bits), as the force step computes it (sub-contacts keep no force
    column)."""
    for c in range(pairs.ia.shape[0]):
        jrow = pairs.joint[c]
        slot = joints.slot[jrow]
        j = joints.row[jrow]
        for s in range(pairs.sc_start[c], pairs.sc_start[c + 1]):
            fn, _ = law_energy(joints.laws, slot, j, s, subs.hist, subs.un[s], subs.dil[s],
                               subs.fs[s, 0], subs.fs[s, 1], subs.fs[s, 2], subs.area[s],
                               subs.state[s])
            out[s] = fn


@kernel
def contact_energies(pairs, subs, joints, which):
    """Spring energy stored in the joint of each contact with ``which[c] != 0`` (0 for the
    others)."""
    out = np.zeros(pairs.ia.shape[0])
    for c in range(pairs.ia.shape[0]):
        if which[c] != 0:
            out[c] = spring_energy(pairs, subs, joints, c)
    return out


@inline_kernel
def book_on_blocks(bodies, a, b, e, column):
    """Book a contact's energy ``e`` on its blocks a and b, ``work[:, column]``, by
    :func:`pdem.contact.rigid.energy_shares`."""
    wa, wb = energy_shares(bodies, a, b)
    bodies.work[a, column] += wa * e
    bodies.work[b, column] += wb * e


@access(reads="fixed work ia ib joint sc_area sc_un sc_fs sc_dil sc_state sc_hist", writes="work")
@kernel
def book_stored_energy(bodies, pairs, subs, joints, which, column):
    """``book_contact_energy(bodies, ia, ib, contact_energies(pairs, subs, joints, which),
    column)``, the same operations, without the per-contact array: the start's first contact
    update books every contact's energy at the set-up's peak."""
    for c in range(pairs.ia.shape[0]):
        e = spring_energy(pairs, subs, joints, c) if which[c] != 0 else 0.0
        book_on_blocks(bodies, pairs.ia[c], pairs.ib[c], e, column)


@kernel
def book_contact_energy(bodies, ia, ib, energy, column):
    """Book a per-contact energy change on the blocks' ``work[:, column]``
    (:func:`pdem.contact.rigid.energy_shares`): a geometry update's jump of the stored energy
    (``WORK_GEOMETRY``), or what contacts of blocks leaving the model held (``WORK_REMOVED``)."""
    for c in range(ia.shape[0]):
        book_on_blocks(bodies, ia[c], ib[c], energy[c], column)
