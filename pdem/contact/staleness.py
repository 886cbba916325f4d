"""When a resting contact's geometry is stale: which contacts a periodic update re-detects.

A contact's common plane and sub-contacts are a function of where block B is relative to block
A, nothing else (both are rigid). So a contact is re-detected when B has moved relative to A,
in A's frame, by more than ``contact.refresh_tolerance`` x CTOL since its last geometry update:
its reference is the relative pose at that update (``rel_x``: B's centroid in A's body frame,
``rel_q``: B's orientation relative to A's), and the measure is the bound on how far any point
of B moved in A's frame, ``|Δ rel_x| + Δθ r_B`` (Δθ the angle of the relative rotation since
then, r_B B's radius). Blocks that move together (a settling stack, a sliding wedge's rigid
part, the whole model swaying) keep their contacts; the sum of the two blocks' own motion,
which the update read before, counted every oscillation of a resting stack and re-detected
most of its contacts every few updates (bench/cube_stack.py, docs/validation.md).

One event a small relative motion can matter for: two blocks found touching or apart (gap
>= 0) have a plane that is one of several equally good ones when they are flush (the shared
edge of diagonal neighbours in a stack lies in a horizontal and in a vertical face plane
alike). The right one is known only once they press together, so a contact whose last update
found gap >= 0 is re-detected as soon as B has moved relative to A and one of its sub-contacts
overlaps by more than ``TOUCH_SHARE`` of the refresh tolerance (a 4³ stack settled with a stale
horizontal plane on its diagonal edges carried 2.5 % of its weight through them; fidelity case
``settled``). Joints given the in-situ stress (pdem.insitu) start pressed by their elastic
closure with no overlap in the geometry: their gap is set to minus that closure, so they are not
taken for contacts found apart (tests/verification/test_insitu.py).

Zoned blocks deform, and their pose says nothing of it: scenes with zoned blocks keep the
two blocks' accumulated motion (``u_geo``, pdem.stepper).
"""

from __future__ import annotations

import math

from ..jit import access, inline_kernel, kernel

# the share of the refresh tolerance a sub-contact of a contact found apart may overlap by
# before the contact is re-detected (see the module doc)
TOUCH_SHARE = 0.01


@inline_kernel
def _relative_pose(x, q, R, a, b):
    """B's centroid in A's body frame and q_a* q_b."""
    dx = x[b, 0] - x[a, 0]
    dy = x[b, 1] - x[a, 1]
    dz = x[b, 2] - x[a, 2]
    px = R[a, 0, 0] * dx + R[a, 1, 0] * dy + R[a, 2, 0] * dz
    py = R[a, 0, 1] * dx + R[a, 1, 1] * dy + R[a, 2, 1] * dz
    pz = R[a, 0, 2] * dx + R[a, 1, 2] * dy + R[a, 2, 2] * dz
    aw, ax, ay, az = q[a, 0], -q[a, 1], -q[a, 2], -q[a, 3]
    bw, bx, by, bz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    rw = aw * bw - ax * bx - ay * by - az * bz
    rx = aw * bx + ax * bw + ay * bz - az * by
    ry = aw * by - ax * bz + ay * bw + az * bx
    rz = aw * bz + ax * by - ay * bx + az * bw
    return px, py, pz, rw, rx, ry, rz


@inline_kernel
def _angle(half):
    """``2 asin(half)``: the angle of a rotation whose quaternion has a vector part of length
    ``half``. Resting contacts turn by far less than 1e-3 rad between updates, where the series
    ``2h (1 + h²/6 + 3h⁴/40)`` is exact to rounding (the next term, 5h⁶/112, is below 1e-19):
    asin was a third of this loop."""
    if half < 1e-3:
        h2 = half * half
        return 2.0 * half * (1.0 + h2 * (1.0 / 6.0 + h2 * 0.075))
    return 2.0 * math.asin(half)


@kernel
def mark_fresh(x, q, R, ia, ib, rel_x, rel_q, which):
    """Record the relative pose of the contacts with ``which[c] != 0`` (just updated)."""
    for c in range(ia.shape[0]):
        if which[c] == 0:
            continue
        px, py, pz, rw, rx, ry, rz = _relative_pose(x, q, R, ia[c], ib[c])
        rel_x[c, 0], rel_x[c, 1], rel_x[c, 2] = px, py, pz
        rel_q[c, 0], rel_q[c, 1], rel_q[c, 2], rel_q[c, 3] = rw, rx, ry, rz


@access(reads="x q R radius ia ib rel_x rel_q gap warm sc_un", writes="moved")
@kernel
def stale_contacts(x, q, R, radius, ia, ib, rel_x, rel_q, gap, warm, sc_start, sc_un,
                   tolerance, moved, todo):
    """Mark in ``todo`` (uint8) the contacts a periodic update must re-detect, write each
    contact's relative motion since its last update to ``moved`` (m); returns how many.

    New contacts (``warm == 0``), those whose reference pose is unknown (a checkpoint written
    before it was kept: ``rel_q`` zero), those whose B moved more than ``tolerance`` (m) in A's
    frame, and those found apart at their last update (``gap >= 0``) that moved and have a
    sub-contact now overlapping, both by more than ``TOUCH_SHARE * tolerance``."""
    touch = TOUCH_SHARE * tolerance
    n = 0
    for c in range(ia.shape[0]):
        a = ia[c]
        b = ib[c]
        px, py, pz, rw, rx, ry, rz = _relative_pose(x, q, R, a, b)
        ex = px - rel_x[c, 0]
        ey = py - rel_x[c, 1]
        ez = pz - rel_x[c, 2]
        # the rotation since then, rel_q* r: its vector part is sin(angle / 2) times the axis
        sw, sx, sy, sz = rel_q[c, 0], -rel_q[c, 1], -rel_q[c, 2], -rel_q[c, 3]
        known = sw * sw + sx * sx + sy * sy + sz * sz > 0.5
        vx = sw * rx + sx * rw + sy * rz - sz * ry
        vy = sw * ry - sx * rz + sy * rw + sz * rx
        vz = sw * rz + sx * ry - sy * rx + sz * rw
        half = min(math.sqrt(vx * vx + vy * vy + vz * vz), 1.0)
        m = math.sqrt(ex * ex + ey * ey + ez * ez) + _angle(half) * radius[b]
        moved[c] = m
        stale = warm[c] == 0 or not known or m > tolerance
        if not stale and gap[c] >= 0.0 and m > touch:
            for s in range(sc_start[c], sc_start[c + 1]):
                if sc_un[s] > touch:
                    stale = True
                    break
        todo[c] = 1 if stale else 0
        n += 1 if stale else 0
    return n
