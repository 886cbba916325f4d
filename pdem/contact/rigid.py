"""The body seam of the contact loop, for rigid blocks.

The contact loop asks three things of the two bodies of a contact: the relative motion at a
point (eq. 15), to sum a force at a point, and to apply the summed action to the bodies (eqs.
28-32). Those are here and nowhere else; a deformable body provides the same three with
gridpoint interpolation. Sub-contact points are stored relative to A's centroid in A's body
frame.
"""

from __future__ import annotations

from collections import namedtuple

from ..jit import inline_kernel

# The block arrays the contact loop reads (pose, velocities, rotation increment, fixed flag)
# and writes (force and moment sums, the energy accumulators).
Bodies = namedtuple("Bodies", "x R v w dtheta force moment fixed work")

# columns of ``work`` (pdem.dynamics.motion.WORK_*): what damping took out (the contacts'
# Rayleigh dashpots, pdem.contact.forces.dashpot), joint dissipation, and the energy a
# contact's force update created (a step in which its joint gave back more than it took in)
WORK_DAMPING = 3
WORK_JOINT = 5
WORK_JOINT_MADE = 6
WORK_GEOMETRY = 7
WORK_REMOVED = 8


@inline_kernel
def pair_motion(bodies, a, b):
    """Per-contact constants of the motion of B relative to A: A's rotation (9), the centroid
    offset d = x_a - x_b (3), V0 = v_b - v_a + w_b x d (3) and w_b - w_a (3)."""
    x, R, v, w = bodies.x, bodies.R, bodies.v, bodies.w
    ra = (R[a, 0, 0], R[a, 0, 1], R[a, 0, 2], R[a, 1, 0], R[a, 1, 1], R[a, 1, 2],
          R[a, 2, 0], R[a, 2, 1], R[a, 2, 2])
    ddx = x[a, 0] - x[b, 0]
    ddy = x[a, 1] - x[b, 1]
    ddz = x[a, 2] - x[b, 2]
    wbx, wby, wbz = w[b, 0], w[b, 1], w[b, 2]
    # eq. 15: V = v_b + w_b x r_b - v_a - w_a x r_a = V0 + (w_b - w_a) x r_a, r_b = r_a + d
    v0 = (v[b, 0] - v[a, 0] + (wby * ddz - wbz * ddy),
          v[b, 1] - v[a, 1] + (wbz * ddx - wbx * ddz),
          v[b, 2] - v[a, 2] + (wbx * ddy - wby * ddx))
    dw = (wbx - w[a, 0], wby - w[a, 1], wbz - w[a, 2])
    return ra, (ddx, ddy, ddz), v0, dw


@inline_kernel
def point_motion(rel, p0, p1, p2):
    """Arm r_a (world) of the body-frame point p of A, and the velocity of B relative to A
    there (eq. 15)."""
    ra, _, v0, dw = rel
    rax = ra[0] * p0 + ra[1] * p1 + ra[2] * p2
    ray = ra[3] * p0 + ra[4] * p1 + ra[5] * p2
    raz = ra[6] * p0 + ra[7] * p1 + ra[8] * p2
    vx = v0[0] + (dw[1] * raz - dw[2] * ray)
    vy = v0[1] + (dw[2] * rax - dw[0] * raz)
    vz = v0[2] + (dw[0] * ray - dw[1] * rax)
    return rax, ray, raz, vx, vy, vz


@inline_kernel
def add_point_force(acc, rax, ray, raz, fx, fy, fz):
    """Sum a force on B at arm r_a: (force, moment about A's centroid)."""
    return (acc[0] + fx, acc[1] + fy, acc[2] + fz,
            acc[3] + (ray * fz - raz * fy),
            acc[4] + (raz * fx - rax * fz),
            acc[5] + (rax * fy - ray * fx))


@inline_kernel
def energy_shares(bodies, a, b):
    """How a contact's energies are booked on its two blocks: half each, or all on the free
    one when the other is fixed. Summing the owned rows then counts each contact once on any
    rank count (every owner of a free block computes all its contacts)."""
    if bodies.fixed[a]:
        return 0.0, 1.0
    if bodies.fixed[b]:
        return 1.0, 0.0
    return 0.5, 0.5


@inline_kernel
def book_dissipation(bodies, a, b, dissipated):
    """The energy a contact's joint dissipated this step, on its blocks' ``work`` by
    :func:`energy_shares`, and in ``WORK_JOINT_MADE`` what it created (negative dissipation)."""
    wa, wb = energy_shares(bodies, a, b)
    bodies.work[a, WORK_JOINT] += wa * dissipated
    bodies.work[b, WORK_JOINT] += wb * dissipated
    made = max(-dissipated, 0.0)
    bodies.work[a, WORK_JOINT_MADE] += wa * made
    bodies.work[b, WORK_JOINT_MADE] += wb * made


@inline_kernel
def apply_pair(bodies, a, b, rel, acc, dissipated):
    """Force and moment sums of one contact onto both blocks (eqs. 28-32): the force on A is
    the opposite of B's; B's moment about its centroid is r_a x f + d x f. The energy the joint
    dissipated this step is booked on the blocks by :func:`energy_shares`."""
    force, moment = bodies.force, bodies.moment
    book_dissipation(bodies, a, b, dissipated)
    ddx, ddy, ddz = rel[1]
    fbx, fby, fbz, max_, may, maz = acc
    mbx = max_ + (ddy * fbz - ddz * fby)
    mby = may + (ddz * fbx - ddx * fbz)
    mbz = maz + (ddx * fby - ddy * fbx)
    force[a, 0] -= fbx
    force[a, 1] -= fby
    force[a, 2] -= fbz
    force[b, 0] += fbx
    force[b, 1] += fby
    force[b, 2] += fbz
    moment[a, 0] -= max_
    moment[a, 1] -= may
    moment[a, 2] -= maz
    moment[b, 0] += mbx
    moment[b, 1] += mby
    moment[b, 2] += mbz
