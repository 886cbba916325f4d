"""Rigid-block motion: one central-difference step for every block (eqs. 44-52, 77-83).

Time levels (the staggered leap-frog of eqs. 47-48)
---------------------------------------------------
On entry to :func:`integrate`:

* ``x``, ``q``            -- centroid and orientation at ``t``;
* ``v``, ``w``, ``L``     -- velocity, angular velocity (world) and angular momentum (world)
  at ``t - dt/2``;
* ``force``, ``moment``   -- contact + applied force and moment about the centroid (world)
  at ``t``, *without* gravity (gravity is added here as ``m g``, with the true mass).

On exit ``x``, ``q`` are at ``t + dt`` and ``v``, ``w``, ``L`` at ``t + dt/2``;
``out_dx = v(t+dt/2) dt`` and ``out_dtheta = w(t+dt/2) dt`` (eq. 50, world frame).

Start-up: the integrator is exact for constant acceleration when the initial velocity is
staggered, ``v(-dt/2) = v0 - a0 dt/2`` (and ``L(-dt/2) = L0 - M0 dt/2``).
:func:`stagger_start` does that shift from velocities given at ``t = 0``.  Starting with
``v(-dt/2) = v0`` instead (what a scene file literally says) is also legitimate; it only
shifts the trajectory by ``O(dt)``.

Rotation
--------
3DEC integrates eq. (49) for the angular velocity with an explicit, lagged gyroscopic term,
or -- its default -- uses the scalar-inertia approximation (46).  The explicit form does not
conserve angular momentum of a free tumbling body, and its energy error grows secularly.
pdem by default keeps the **world angular momentum** ``L`` as the rotational state:

    L(t + dt/2) = L(t - dt/2) + (M(t) - M_d) dt          (eq. 45 in the world frame: dL/dt = M)

which, for ``M = 0``, conserves ``L`` to round-off.  The orientation is then advanced with an
implicit-midpoint (time-reversible) step: ``w_mid = R_mid I^-1 R_mid^T L(t+dt/2)`` where
``R_mid = R(exp(w_mid dt/2) ⊗ q(t))`` -- a fixed point iterated until it changes by less than
``ROT_TOL`` relative (typically 3-5 iterations for ``|w| dt ~ 1e-3``) -- and

    q(t + dt) = exp(w_mid dt) ⊗ q(t),    dtheta = w_mid dt,    w(t + dt/2) = w_mid.

Reversibility gives bounded (non-drifting) kinetic-energy error for free rotation.  Because the
inertia is taken at the mid-step orientation this solves Euler's equations (45) to second
order, exactly as (49) does for the linear equations.  ``scalar_inertia=True`` reproduces
3DEC's approximation (46): ``I = mean principal moment``, ``w = L / I`` (no iteration).

Damping (``damping``, a mode of :mod:`pdem.dynamics.damping`)
-----------------------------------------------------------
``NONE``      alpha ignored.
``VISCOUS``   mass-proportional, eq. (49): ``v+ = (D1 v- + a dt) D2``,
              ``D1 = 1 - alpha dt/2``, ``D2 = 1/(1 + alpha dt/2)``; applied to ``L`` alike.
``ADAPTIVE``  the same viscous form; alpha is servo-controlled by the caller with
              :func:`adaptive_alpha_update` from the stats written by :func:`integrate` (eq. 77).
``LOCAL``     eqs. (78)-(79): per component ``F_d = alpha |F_tot| sgn(v(t - dt/2))`` is
              subtracted, ``F_tot = F + m g`` the total unbalanced force; the moment alike with
              ``sgn(w(t - dt/2))`` (world components).
``COMBINED``  eq. (83).  Written in the convention of (78) (``F_d`` subtracted) it reads
              ``F_d = alpha |F_tot| (sgn(v) - sgn(dF/dt)) / 2``: for periodic motion
              ``sgn(dF/dt) = -sgn(v)`` (eqs. 80-81), so this equals local damping there.
              (83) as printed carries the opposite overall sign because it is the force
              *added*; with the (78) sign it would pump energy in.)
              ``dF/dt`` is estimated from ``F_tot - prev_force``.

Mass scaling: ``mass_scale`` multiplies mass and principal moments in the inertial terms only;
gravity uses the true mass: ``a = (F + m g) / (mass_scale m)``.  ``L`` and the energies in
``out_stats`` are the *inertial* (scaled) ones; :mod:`pdem.dynamics.energy` reports physical
values.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from pdem.dynamics.damping import damped_momentum
from pdem.dynamics.rotation import (
    quat_from_rotvec_s,
    quat_mul_s,
    quat_normalize_s,
    rotate_inv_s,
    rotate_s,
)
from pdem.jit import access, kernel

# The block arrays integrate reads and writes (owned rows): ``force`` and ``moment`` are the
# contact sums, ``applied`` the applied loads (gravity is added with the true mass); ``work``
# the energy accumulators (pdem.dynamics.energy.WORK_*).
# ``bforce``/``bmoment``: boundary-stress force and moment about the centroid at t (world;
# pdem.boundary), booked as applied work.
Motion = namedtuple("Motion", "x q v w L mass inertia fixed vfix force applied moment mscale "
                              "prev_force prev_moment dx dtheta work bforce bmoment")

# ``vfix`` codes: 0 free; VFIX_ALL the velocity and angular velocity prescribed (the block is
# moved with them); otherwise a mask of prescribed translation components (the others and the
# rotation are integrated).
VFIX_ALL = 1
VFIX_X = 2
VFIX_Y = 4
VFIX_Z = 8

# columns of the per-block ``work`` field
WORK_GRAVITY = 0
WORK_APPLIED = 1
WORK_CONTACT = 2
WORK_DAMPING = 3  # dissipated (>= 0 for every damping mode's intent)
WORK_BOUNDARY = 4  # put in by prescribed velocities
WORK_JOINT = 5  # dissipated in the joints (slip, failure; dilation counts negative)
WORK_JOINT_MADE = 6  # steps in which a contact's joint gave back more than it took (timestep)
WORK_GEOMETRY = 7  # change of stored joint energy made by contact geometry updates
WORK_REMOVED = 8  # kinetic and joint energy taken out with blocks that left the model domain
WORK_QUIET = 9  # absorbed by quiet faces' dashpots (pdem.dynamics.quiet; moved out of APPLIED)

# Layout of ``out_stats`` (local to the blocks passed in; reduce over ranks yourself:
# max for the MAX_* entries, sum for the rest).  Only free blocks (not fixed, not vfix) count.
STAT_MAX_FORCE = 0  # max |F + m g|
STAT_SUM_FORCE = 1  # sum |F + m g|
STAT_MAX_MOMENT = 2  # max |M|
STAT_N_FREE = 3  # number of free blocks
STAT_DAMP_POWER = 4  # sum of damping power P (eq. 77), >= 0 for viscous damping
STAT_DEK = 5  # sum over blocks of |dEk/dt| (eq. 77), inertial energies
STAT_KE = 6  # inertial kinetic energy at t + dt/2 (translational + rotational)
STAT_ROT_ITER = 7  # largest number of midpoint iterations used
N_STATS = 8

ROT_TOL = 1e-15  # relative change of w_mid that ends the fixed-point iteration
ROT_MAX_ITER = 10


@kernel
def _block_inertia(inertia, i, ms, scalar_inertia):
    """Inertial principal moments of block i (scaled); the mean if scalar_inertia."""
    i1 = inertia[i, 0]
    i2 = inertia[i, 1]
    i3 = inertia[i, 2]
    if scalar_inertia:
        if not (i1 == i2 and i2 == i3):
            i1 = (i1 + i2 + i3) / 3.0
        i2 = i1
        i3 = i1
    return i1 * ms, i2 * ms, i3 * ms


@kernel
def omega_from_L_s(qw, qx, qy, qz, lx, ly, lz, i1, i2, i3):
    """World w = R I^-1 R^T L for orientation q and principal moments (i1, i2, i3)."""
    bx, by, bz = rotate_inv_s(qw, qx, qy, qz, lx, ly, lz)
    return rotate_s(qw, qx, qy, qz, bx / i1, by / i2, bz / i3)


@kernel
def L_from_omega_s(qw, qx, qy, qz, wx, wy, wz, i1, i2, i3):
    """World L = R I R^T w."""
    bx, by, bz = rotate_inv_s(qw, qx, qy, qz, wx, wy, wz)
    return rotate_s(qw, qx, qy, qz, bx * i1, by * i2, bz * i3)


@kernel
def midpoint_omega_s(qw, qx, qy, qz, lx, ly, lz, i1, i2, i3, dt):
    """Solve w = R(exp(w dt/2) ⊗ q) I^-1 R(...)^T L by fixed-point iteration.

    Returns (wx, wy, wz, iterations).
    """
    wx, wy, wz = omega_from_L_s(qw, qx, qy, qz, lx, ly, lz, i1, i2, i3)
    it = 0
    h = 0.5 * dt
    while it < ROT_MAX_ITER:
        it += 1
        dw, dx, dy, dz = quat_from_rotvec_s(wx * h, wy * h, wz * h)
        mw, mx, my, mz = quat_mul_s(dw, dx, dy, dz, qw, qx, qy, qz)
        nx, ny, nz = omega_from_L_s(mw, mx, my, mz, lx, ly, lz, i1, i2, i3)
        ex = nx - wx
        ey = ny - wy
        ez = nz - wz
        wx = nx
        wy = ny
        wz = nz
        if ex * ex + ey * ey + ez * ez <= (ROT_TOL * ROT_TOL) * (nx * nx + ny * ny + nz * nz):
            break
    return wx, wy, wz, it


@access(reads="x q v w L mass inertia fixed vfix force applied_force moment mscale prev_force "
              "prev_moment work bforce bmoment",
        writes="x q v w L prev_force prev_moment dx dtheta work")
@kernel
def integrate(m, gravity, dt, damping, scalar_inertia, out_stats):
    """Advance all blocks one step; see the module docstring for time levels and damping.

    ``m`` (:data:`Motion`): updates x, q, v, w, L, prev_force, prev_moment in place and writes
    dx, dtheta (n, 3); ``damping``: a mode of :mod:`pdem.dynamics.damping`; ``out_stats``
    (N_STATS,). ``fixed``/``vfix`` are uint8 (or bool) flags.
    """
    x, q, v, w, L = m.x, m.q, m.v, m.w, m.L
    mass, inertia, fixed, vfix, mass_scale = m.mass, m.inertia, m.fixed, m.vfix, m.mscale
    force, moment, prev_force, prev_moment = m.force, m.moment, m.prev_force, m.prev_moment
    applied, work = m.applied, m.work
    bforce, bmoment = m.bforce, m.bmoment
    out_dx, out_dtheta = m.dx, m.dtheta
    n = x.shape[0]
    gx = gravity[0]
    gy = gravity[1]
    gz = gravity[2]

    max_f = 0.0
    sum_f = 0.0
    max_m = 0.0
    n_free = 0
    p_damp = 0.0
    dek = 0.0
    ke = 0.0
    max_it = 0

    for i in range(n):
        mb = mass[i]
        ms = mass_scale[i]
        mi = mb * ms
        ftx = (force[i, 0] + (applied[i, 0] + bforce[i, 0])) + mb * gx
        fty = (force[i, 1] + (applied[i, 1] + bforce[i, 1])) + mb * gy
        ftz = (force[i, 2] + (applied[i, 2] + bforce[i, 2])) + mb * gz
        mx = moment[i, 0] + bmoment[i, 0]
        my = moment[i, 1] + bmoment[i, 1]
        mz = moment[i, 2] + bmoment[i, 2]
        pf = (prev_force[i, 0], prev_force[i, 1], prev_force[i, 2])
        pm = (prev_moment[i, 0], prev_moment[i, 1], prev_moment[i, 2])
        prev_force[i, 0] = ftx
        prev_force[i, 1] = fty
        prev_force[i, 2] = ftz
        prev_moment[i, 0] = mx
        prev_moment[i, 1] = my
        prev_moment[i, 2] = mz

        if fixed[i]:
            for k in range(3):
                v[i, k] = 0.0
                w[i, k] = 0.0
                L[i, k] = 0.0
                out_dx[i, k] = 0.0
                out_dtheta[i, k] = 0.0
            continue

        i1, i2, i3 = _block_inertia(inertia, i, ms, scalar_inertia)
        qw = q[i, 0]
        qx = q[i, 1]
        qy = q[i, 2]
        qz = q[i, 3]

        code = vfix[i]
        if code == VFIX_ALL:
            # Prescribed velocities: keep v and w, move the block with them.
            vx = v[i, 0]
            vy = v[i, 1]
            vz = v[i, 2]
            wx = w[i, 0]
            wy = w[i, 1]
            wz = w[i, 2]
            h = 0.5 * dt
            hw, hx, hy, hz = quat_from_rotvec_s(wx * h, wy * h, wz * h)
            aw, ax, ay, az = quat_mul_s(hw, hx, hy, hz, qw, qx, qy, qz)
            lx, ly, lz = L_from_omega_s(aw, ax, ay, az, wx, wy, wz, i1, i2, i3)
            # the prescribed motion takes the work the contacts do on the block out of the
            # model (and puts the opposite in)
            work[i, WORK_BOUNDARY] -= (force[i, 0] * vx + force[i, 1] * vy + force[i, 2] * vz
                                       + moment[i, 0] * wx + moment[i, 1] * wy
                                       + moment[i, 2] * wz) * dt
            L[i, 0] = lx
            L[i, 1] = ly
            L[i, 2] = lz
        else:
            n_free += 1
            # free translation components (1.0) and prescribed ones (0.0): a prescribed
            # component keeps the velocity set on entry, its force is a reaction
            ex_ = 0.0 if code & VFIX_X else 1.0
            ey_ = 0.0 if code & VFIX_Y else 1.0
            ez_ = 0.0 if code & VFIX_Z else 1.0
            fn = math.sqrt((ftx * ex_) ** 2 + (fty * ey_) ** 2 + (ftz * ez_) ** 2) if code \
                else math.sqrt(ftx * ftx + fty * fty + ftz * ftz)
            mn = math.sqrt(mx * mx + my * my + mz * mz)
            sum_f += fn
            if fn > max_f:
                max_f = fn
            if mn > max_m:
                max_m = mn

            v0x = v[i, 0]
            v0y = v[i, 1]
            v0z = v[i, 2]
            w0x = w[i, 0]
            w0y = w[i, 1]
            w0z = w[i, 2]
            l0x = L[i, 0]
            l0y = L[i, 1]
            l0z = L[i, 2]

            # --- translation and angular momentum with the scene's damping (eqs. 49, 78-83)
            vn, ln, fd, md = damped_momentum(
                damping, mi, dt, (v0x, v0y, v0z), (l0x, l0y, l0z), (w0x, w0y, w0z),
                (ftx, fty, ftz), (mx, my, mz), pf, pm)
            vx, vy, vz = vn
            lx, ly, lz = ln
            fdx, fdy, fdz = fd
            mdx, mdy, mdz = md
            if code:
                if ex_ == 0.0:
                    vx = v0x
                    fdx = 0.0
                if ey_ == 0.0:
                    vy = v0y
                    fdy = 0.0
                if ez_ == 0.0:
                    vz = v0z
                    fdz = 0.0

            # --- angular velocity at t + dt/2
            if scalar_inertia or (i1 == i2 and i2 == i3):
                # isotropic (a cube, a regular polyhedron, or solve.inertia scalar):
                # w = R I^-1 R^T L = L / i at any orientation, so the midpoint iteration
                # would only add its rounding (bench/cube_stack.py: 12% of a step)
                wx = lx / i1
                wy = ly / i1
                wz = lz / i1
            else:
                wx, wy, wz, it = midpoint_omega_s(qw, qx, qy, qz, lx, ly, lz, i1, i2, i3, dt)
                if it > max_it:
                    max_it = it

            # --- adaptive-damping sums (eq. 77) and kinetic energy
            pd = (
                fdx * 0.5 * (v0x + vx)
                + fdy * 0.5 * (v0y + vy)
                + fdz * 0.5 * (v0z + vz)
                + mdx * 0.5 * (w0x + wx)
                + mdy * 0.5 * (w0y + wy)
                + mdz * 0.5 * (w0z + wz)
            )
            p_damp += pd
            # --- energy budget: work over the step with the mean velocity, which makes the
            # translational balance exact for the leap-frog (dEk = F . (v- + v+)/2 dt)
            vbx = 0.5 * (v0x + vx)
            vby = 0.5 * (v0y + vy)
            vbz = 0.5 * (v0z + vz)
            wbx = 0.5 * (w0x + wx)
            wby = 0.5 * (w0y + wy)
            wbz = 0.5 * (w0z + wz)
            if code:
                # prescribed components: the contacts' work on them goes out through the
                # boundary (as for a fully prescribed block); they hold no kinetic energy
                work[i, WORK_BOUNDARY] -= (force[i, 0] * vx * (1.0 - ex_)
                                           + force[i, 1] * vy * (1.0 - ey_)
                                           + force[i, 2] * vz * (1.0 - ez_)) * dt
                vbx *= ex_
                vby *= ey_
                vbz *= ez_
            work[i, WORK_GRAVITY] += mb * (gx * vbx + gy * vby + gz * vbz) * dt
            work[i, WORK_APPLIED] += ((applied[i, 0] + bforce[i, 0]) * vbx
                                      + (applied[i, 1] + bforce[i, 1]) * vby
                                      + (applied[i, 2] + bforce[i, 2]) * vbz
                                      + (bmoment[i, 0] * wbx + bmoment[i, 1] * wby
                                         + bmoment[i, 2] * wbz)) * dt
            work[i, WORK_CONTACT] += (force[i, 0] * vbx + force[i, 1] * vby + force[i, 2] * vbz
                                      + moment[i, 0] * wbx + moment[i, 1] * wby
                                      + moment[i, 2] * wbz) * dt
            work[i, WORK_DAMPING] += pd * dt
            e0 = 0.5 * (
                mi * ((v0x * ex_) ** 2 + (v0y * ey_) ** 2 + (v0z * ez_) ** 2)
                + w0x * l0x + w0y * l0y + w0z * l0z
            ) if code else 0.5 * (
                mi * (v0x * v0x + v0y * v0y + v0z * v0z) + w0x * l0x + w0y * l0y + w0z * l0z
            )
            e1 = 0.5 * (
                mi * ((vx * ex_) ** 2 + (vy * ey_) ** 2 + (vz * ez_) ** 2)
                + wx * lx + wy * ly + wz * lz
            ) if code else 0.5 * (
                mi * (vx * vx + vy * vy + vz * vz) + wx * lx + wy * ly + wz * lz)
            dek += abs(e1 - e0) / dt
            ke += e1

            v[i, 0] = vx
            v[i, 1] = vy
            v[i, 2] = vz
            L[i, 0] = lx
            L[i, 1] = ly
            L[i, 2] = lz
            w[i, 0] = wx
            w[i, 1] = wy
            w[i, 2] = wz

        # --- pose update (eqs. 50-51), orientation by the exact exponential map
        tx = wx * dt
        ty = wy * dt
        tz = wz * dt
        out_dx[i, 0] = vx * dt
        out_dx[i, 1] = vy * dt
        out_dx[i, 2] = vz * dt
        out_dtheta[i, 0] = tx
        out_dtheta[i, 1] = ty
        out_dtheta[i, 2] = tz
        x[i, 0] += vx * dt
        x[i, 1] += vy * dt
        x[i, 2] += vz * dt
        dw, dx, dy, dz = quat_from_rotvec_s(tx, ty, tz)
        nw, nx, ny, nz = quat_mul_s(dw, dx, dy, dz, qw, qx, qy, qz)
        nw, nx, ny, nz = quat_normalize_s(nw, nx, ny, nz)
        q[i, 0] = nw
        q[i, 1] = nx
        q[i, 2] = ny
        q[i, 3] = nz

    out_stats[STAT_MAX_FORCE] = max_f
    out_stats[STAT_SUM_FORCE] = sum_f
    out_stats[STAT_MAX_MOMENT] = max_m
    out_stats[STAT_N_FREE] = n_free
    out_stats[STAT_DAMP_POWER] = p_damp
    out_stats[STAT_DEK] = dek
    out_stats[STAT_KE] = ke
    out_stats[STAT_ROT_ITER] = max_it


@kernel
def momentum_from_omega(q, w, inertia, mass_scale, scalar_inertia, out_L):
    """out_L[i] = R_i I_i R_i^T w[i] (inertial, i.e. scaled, moments)."""
    for i in range(q.shape[0]):
        i1, i2, i3 = _block_inertia(inertia, i, mass_scale[i], scalar_inertia)
        r = L_from_omega_s(
            q[i, 0], q[i, 1], q[i, 2], q[i, 3], w[i, 0], w[i, 1], w[i, 2], i1, i2, i3
        )
        out_L[i, 0], out_L[i, 1], out_L[i, 2] = r


@access(reads="q v L mass inertia mscale fixed vfix force applied_force moment bforce bmoment",
        writes="v w L")
@kernel
def stagger_start(m, gravity, dt, scalar_inertia):
    """Turn velocities given at t = 0 into the t = -dt/2 values the integrator expects.

    Call once, with v and L at t = 0 (e.g. L from :func:`momentum_from_omega`) and the
    forces/moments at t = 0 (``m``: :data:`Motion`): ``v -= (F + m g)/m_s dt/2``,
    ``L -= M dt/2``, and ``w`` is recomputed from ``L`` at ``q(0)``.  Undamped; fixed and vfix
    blocks are left alone.
    """
    q, v, w, L, mass, inertia = m.q, m.v, m.w, m.L, m.mass, m.inertia
    mass_scale, fixed, vfix, force, moment = m.mscale, m.fixed, m.vfix, m.force, m.moment
    applied, bforce, bmoment = m.applied, m.bforce, m.bmoment
    for i in range(q.shape[0]):
        if fixed[i] or vfix[i] == VFIX_ALL:
            continue
        mi = mass[i] * mass_scale[i]
        h = 0.5 * dt
        for k in range(3):
            if not (vfix[i] & (VFIX_X << k)):  # a prescribed component is set, not staggered
                v[i, k] -= ((force[i, k] + (applied[i, k] + bforce[i, k]))
                            + mass[i] * gravity[k]) / mi * h
            L[i, k] -= (moment[i, k] + bmoment[i, k]) * h
        i1, i2, i3 = _block_inertia(inertia, i, mass_scale[i], scalar_inertia)
        r = omega_from_L_s(
            q[i, 0], q[i, 1], q[i, 2], q[i, 3], L[i, 0], L[i, 1], L[i, 2], i1, i2, i3
        )
        w[i, 0], w[i, 1], w[i, 2] = r


@access(reads="dx dtheta radius fixed u_acc u_geo u_mig v x", writes="u_acc u_geo u_mig")
@kernel
def motion_bookkeeping(dx, dtheta, radius, fixed, u_acc, u_geo, u_mig, v, x, speed_limit,
                       max_step=math.inf):
    """After :func:`integrate`: accumulate each block's motion bound (eq. 1: centroid motion
    plus rotation times the block radius) into ``u_acc``, ``u_geo``, ``u_mig``, and check the
    state.

    Returns ``(bad, u_mig_max)``: the row of the first block with a non-finite position or
    speed, a speed above ``speed_limit``, or a free block whose motion bound in this one step
    exceeds ``max_step`` (-1 if none), and the largest ``u_mig`` of the free (not ``fixed``)
    blocks (0 if none).

    ``max_step``: the motion per step the contact search can follow. The search runs after
    the step in which a block's ``u_acc`` passes CTOL/2 (pdem.resolve.REMAP_FRACTION), so a
    pair not yet in contact can overlap by at most the step's motion before its contact exists;
    a block moving more in one step can land inside or beyond a thin block unseen (tunnelling,
    tests/extremes/test_extreme_impact.py). The stepper passes ``state.max_step``
    (pdem.state.max_step_motion); the default (infinite) checks nothing.
    """
    bad = -1
    u_max = 0.0
    for i in range(dx.shape[0]):
        moved = math.sqrt(dx[i, 0] * dx[i, 0] + dx[i, 1] * dx[i, 1] + dx[i, 2] * dx[i, 2]) + \
            math.sqrt(dtheta[i, 0] * dtheta[i, 0] + dtheta[i, 1] * dtheta[i, 1]
                      + dtheta[i, 2] * dtheta[i, 2]) * radius[i]
        u_acc[i] += moved
        u_geo[i] += moved
        um = u_mig[i] + moved
        u_mig[i] = um
        if fixed[i] == 0 and um > u_max:
            u_max = um
        if bad < 0:
            speed = math.sqrt(v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
            if not (math.isfinite(speed) and math.isfinite(x[i, 0]) and math.isfinite(x[i, 1])
                    and math.isfinite(x[i, 2])) or speed > speed_limit \
                    or (fixed[i] == 0 and moved > max_step):
                bad = i
    return bad, u_max


def new_stats() -> np.ndarray:
    """A zeroed ``out_stats`` array for :func:`integrate`."""
    return np.zeros(N_STATS)


# Adaptive global damping (Cundall 1982), eq. (77).
ADAPTIVE_MIN_FACTOR = 1.01
ADAPTIVE_MAX_FACTOR = 1.10


def adaptive_alpha_update(
    alpha: float,
    power_damping_sum: float,
    dEk_sum: float,
    target_ratio: float = 0.5,
    alpha_min: float = 1e-9,
    alpha_max: float = math.inf,
    dt: float | None = None,
) -> float:
    """One servo update of the global viscous constant alpha towards R = target (eq. 77).

    ``R = sum P / sum |dEk/dt|`` from ``out_stats[STAT_DAMP_POWER]`` and
    ``out_stats[STAT_DEK]`` (summed over ranks, and preferably over the steps since the last
    update -- call this every few, e.g. 10, steps).  If R is below the target there is too
    little damping and alpha is multiplied by a factor f, otherwise divided by f, with
    ``f = clip((target / R) ** 0.1, 1.01, 1.10)`` (or its inverse): a gentle multiplicative
    servo whose step grows with the log of the mismatch, so it is scale-free (alpha has units
    1/s and cannot be bounded a priori) and can't overshoot by more than 10 % per update.

    ``sum |dEk/dt|`` uses per-block magnitudes so that oscillating blocks whose energy rates
    cancel in a signed sum still register; for a single harmonic mode of frequency w0 the
    servo then settles near ``alpha = 2 target w0 / pi`` (damping ratio ~ target/pi).

    The result is clamped to ``[alpha_min, alpha_max]`` and, if ``dt`` is given, to
    ``alpha <= 1/dt`` (keeps ``D1 = 1 - alpha dt/2 >= 1/2``, far from the D1 < 0 regime that
    reverses velocities).  With no kinetic-energy change (at rest) alpha is returned unchanged
    (apart from the clamp).
    """
    hi = alpha_max
    if dt is not None and dt > 0.0:
        hi = min(hi, 1.0 / dt)
    a = max(alpha, alpha_min)
    if dEk_sum > 0.0 and math.isfinite(dEk_sum):
        r = power_damping_sum / dEk_sum
        if r < target_ratio:
            f = (target_ratio / r) ** 0.1 if r > 0.0 else ADAPTIVE_MAX_FACTOR
            a *= min(max(f, ADAPTIVE_MIN_FACTOR), ADAPTIVE_MAX_FACTOR)
        elif r > target_ratio:
            f = (r / target_ratio) ** 0.1
            a /= min(max(f, ADAPTIVE_MIN_FACTOR), ADAPTIVE_MAX_FACTOR)
    return float(min(max(a, alpha_min), hi))
