"""Structural elements of rock reinforcement (docs/reinforcement.md): cables and rock bolts as
chains of nodes, 3DEC's formulation.

A node ``i`` has a lumped mass ``m_i`` (the steel of its tributary length) and three
translational degrees of freedom; it lies in a host (a rigid block or a zoned block's
tetrahedron) whose material point that coincided with it at installation is its *anchor*
(``ax``, ``av``: position and velocity, gathered from the hosts' owners every step).

* **Segment** ``s`` between nodes ``a`` and ``b``: an axial spring ``EA/L0`` on the strain
  ``eps = L/L0 - 1``, elastic-perfectly plastic, ``F = EA (eps - eps_p)`` within
  ``[-yield_compression, yield_tension]`` (0: no limit), ``eps_p`` its plastic strain. A
  rock bolt's segment breaks for good when ``eps`` exceeds its failure strain.
* **Grout** at node ``i`` (tributary length ``l``): along the element's axis ``t`` a spring
  ``k_g l`` on the node's slip relative to its anchor, ``F_a = -k_g l (r.t - slip)``, capped at
  the grout strength ``s_g l`` (the excess becomes plastic slip); across it the grout holds
  the node to its anchor with ``k_g l`` and no limit (bending-free, the element stays in its
  hole). The host takes the opposite force at the anchor.
* **Dowel** (a rock bolt's segment whose nodes lie in two different blocks: it crosses a
  joint): a shear spring ``k_s`` on the relative displacement of its nodes across the
  segment's axis, capped at its shear strength.
* An **anchored** end (``anchors``) is held to its host without slip: the node moves with its
  anchor and hands the whole force of its segment to the host.

All forces are totals of the state (the plastic offsets are the history), so computing them
twice at one state gives the same bits. Nodes move by central differences with the blocks'
damping (:func:`pdem.dynamics.damping.damped_momentum`, translation only).
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import inline_kernel, kernel
from .damping import damped_momentum

# energy accumulators (``work`` columns of the elements)
CW_GRAVITY = 0  # work of gravity on the nodes
CW_YIELD = 1  # dissipated by the axial springs' plastic flow (and by breaking)
CW_SLIP = 2  # dissipated by the grout's slip and the dowels' plastic shear
CW_DAMPING = 3  # dissipated by the nodes' damping
CW_WIDTH = 4


@inline_kernel
def _unit(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return x / n, y / n, z / n, n


@kernel
def move_nodes(d, dt, gx, gy, gz, x, v, force, last, mass, imass, slaved, anchored, ax, av,
               work):
    """Central-difference step of every node: ``v`` to t + dt/2 from the force at t (springs
    ``force`` plus gravity, damped as the blocks are: ``d`` the damping kernel's constants,
    ``last`` the previous step's total force for combined damping), then ``x`` to t + dt. A
    slaved node (an anchored end) takes its anchor's position and velocity instead."""
    z3 = (0.0, 0.0, 0.0)
    for i in range(x.shape[0]):
        if slaved[i] != 0 and anchored[i] != 0:
            for k in range(3):
                v[i, k] = av[i, k]
                x[i, k] = ax[i, k]
            continue
        m = mass[i]
        ft = (force[i, 0] + m * gx, force[i, 1] + m * gy, force[i, 2] + m * gz)
        v0 = (v[i, 0], v[i, 1], v[i, 2])
        pf = (last[i, 0], last[i, 1], last[i, 2])
        vn, _, fd, _ = damped_momentum(d, imass[i], dt, v0, z3, z3, ft, z3, pf, z3)
        for k in range(3):
            vb = 0.5 * (v0[k] + vn[k])
            work[CW_GRAVITY] += m * (gx, gy, gz)[k] * vb * dt
            work[CW_DAMPING] += fd[k] * vb * dt
            v[i, k] = vn[k]
            x[i, k] += vn[k] * dt
            last[i, k] = ft[k]


@inline_kernel
def _axis_at(i, x, node_seg, seg_a, seg_b):
    """The element's axis at node ``i``: the mean direction of its (one or two) segments."""
    tx, ty, tz = 0.0, 0.0, 0.0
    for j in range(2):
        s = node_seg[i, j]
        if s < 0:
            continue
        a, b = seg_a[s], seg_b[s]
        ux, uy, uz, _ = _unit(x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2])
        tx += ux
        ty += uy
        tz += uz
    ux, uy, uz, _ = _unit(tx, ty, tz)
    return ux, uy, uz


@kernel
def element_forces(x, ax, anchored, slaved, node_seg, kg, sg, slip, seg_a, seg_b, L0, EA,
                   y_t, y_c, eps_p, fail, broken, ks, cap, d0, dp, force, reaction, axial,
                   shear, grout, work):
    """The elements' forces at the state ``x`` (nodes) and ``ax`` (anchors): ``force`` on the
    nodes, ``reaction`` on each node's host at its anchor, ``axial`` (N, tension positive)
    and ``shear`` (the dowel's, N) per segment; the plastic offsets (``eps_p``, ``slip``,
    ``dp``) and ``broken`` flags updated, what their flow dissipated booked in ``work``.
    Returns the elastic energy the elements hold."""
    stored = 0.0
    for i in range(x.shape[0]):
        grout[i] = 0.0
        for k in range(3):
            force[i, k] = 0.0
            reaction[i, k] = 0.0
    for s in range(seg_a.shape[0]):
        a, b = seg_a[s], seg_b[s]
        held = shear[s]  # (the dowel's force of the last evaluation: lost if it breaks now)
        axial[s] = 0.0
        shear[s] = 0.0
        if broken[s] != 0:
            continue
        dx, dy, dz = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
        ex, ey, ez, length = _unit(dx, dy, dz)
        eps = length / L0[s] - 1.0
        if fail[s] > 0.0 and eps > fail[s]:  # the bolt breaks: its springs' energy is lost
            broken[s] = 1
            f = EA[s] * (eps - eps_p[s])
            work[CW_YIELD] += 0.5 * f * f / EA[s] * L0[s]
            if ks[s] > 0.0:
                work[CW_SLIP] += 0.5 * held * held / ks[s]
            continue
        f = EA[s] * (eps - eps_p[s])
        if y_t[s] > 0.0 and f > y_t[s]:
            work[CW_YIELD] += y_t[s] * L0[s] * (f - y_t[s]) / EA[s]
            f = y_t[s]
            eps_p[s] = eps - f / EA[s]
        elif y_c[s] > 0.0 and f < -y_c[s]:
            work[CW_YIELD] += y_c[s] * L0[s] * (-y_c[s] - f) / EA[s]
            f = -y_c[s]
            eps_p[s] = eps - f / EA[s]
        stored += 0.5 * f * f / EA[s] * L0[s]
        axial[s] = f
        force[a, 0] += f * ex
        force[a, 1] += f * ey
        force[a, 2] += f * ez
        force[b, 0] -= f * ex
        force[b, 1] -= f * ey
        force[b, 2] -= f * ez
        if ks[s] > 0.0:  # a dowel across a joint: the shear of b relative to a
            rx, ry, rz = dx - d0[s, 0], dy - d0[s, 1], dz - d0[s, 2]
            ra = rx * ex + ry * ey + rz * ez
            lx, ly, lz = rx - ra * ex, ry - ra * ey, rz - ra * ez
            fx = ks[s] * (lx - dp[s, 0])
            fy = ks[s] * (ly - dp[s, 1])
            fz = ks[s] * (lz - dp[s, 2])
            fm = math.sqrt(fx * fx + fy * fy + fz * fz)
            if cap[s] > 0.0 and fm > cap[s]:
                c = cap[s] / fm
                work[CW_SLIP] += cap[s] * (fm - cap[s]) / ks[s]
                fx, fy, fz = fx * c, fy * c, fz * c
                dp[s, 0] = lx - fx / ks[s]
                dp[s, 1] = ly - fy / ks[s]
                dp[s, 2] = lz - fz / ks[s]
                fm = cap[s]
            stored += 0.5 * fm * fm / ks[s]
            shear[s] = fm
            force[a, 0] += fx
            force[a, 1] += fy
            force[a, 2] += fz
            force[b, 0] -= fx
            force[b, 1] -= fy
            force[b, 2] -= fz
    for i in range(x.shape[0]):
        if anchored[i] == 0:
            continue
        if slaved[i] != 0:  # held to its host: the host takes the whole force
            for k in range(3):
                reaction[i, k] = force[i, k]
                force[i, k] = 0.0
            continue
        if kg[i] == 0.0:
            continue
        tx, ty, tz = _axis_at(i, x, node_seg, seg_a, seg_b)
        rx, ry, rz = x[i, 0] - ax[i, 0], x[i, 1] - ax[i, 1], x[i, 2] - ax[i, 2]
        ra = rx * tx + ry * ty + rz * tz
        fa = 0.0
        if sg[i] > 0.0:
            fa = -kg[i] * (ra - slip[i])
            if abs(fa) > sg[i]:
                over = abs(fa) - sg[i]
                fa = sg[i] if fa > 0.0 else -sg[i]
                work[CW_SLIP] += sg[i] * over / kg[i]
                slip[i] = ra + fa / kg[i]
            stored += 0.5 * fa * fa / kg[i]
            grout[i] = fa
        else:
            slip[i] = ra  # unbonded along the axis: it slides freely
        lx, ly, lz = rx - ra * tx, ry - ra * ty, rz - ra * tz
        stored += 0.5 * kg[i] * (lx * lx + ly * ly + lz * lz)
        gx = fa * tx - kg[i] * lx
        gy = fa * ty - kg[i] * ly
        gz = fa * tz - kg[i] * lz
        force[i, 0] += gx
        force[i, 1] += gy
        force[i, 2] += gz
        reaction[i, 0] = -gx
        reaction[i, 1] = -gy
        reaction[i, 2] = -gz
    return stored


@kernel
def rigid_anchors(rows, local, x, R, v, w, ax, av):
    """Anchors in rigid blocks (``rows``: their rows here, -1 where not held here): the world
    position ``x + R p`` and velocity ``v + w x (R p)`` of each body-frame point ``p``."""
    for i in range(rows.shape[0]):
        r = rows[i]
        if r < 0:
            continue
        px, py, pz = local[i, 0], local[i, 1], local[i, 2]
        qx = R[r, 0, 0] * px + R[r, 0, 1] * py + R[r, 0, 2] * pz
        qy = R[r, 1, 0] * px + R[r, 1, 1] * py + R[r, 1, 2] * pz
        qz = R[r, 2, 0] * px + R[r, 2, 1] * py + R[r, 2, 2] * pz
        # (+ 0.0: a -0.0 becomes +0.0, so that the ranks' sum of anchors is every rank's bits)
        ax[i, 0] = x[r, 0] + qx + 0.0
        ax[i, 1] = x[r, 1] + qy + 0.0
        ax[i, 2] = x[r, 2] + qz + 0.0
        av[i, 0] = v[r, 0] + (w[r, 1] * qz - w[r, 2] * qy) + 0.0
        av[i, 1] = v[r, 1] + (w[r, 2] * qx - w[r, 0] * qz) + 0.0
        av[i, 2] = v[r, 2] + (w[r, 0] * qy - w[r, 1] * qx) + 0.0


@kernel
def rigid_reactions(rows, ax, reaction, x, force, moment):
    """The hosts' reactions onto the rigid blocks of ``rows`` (-1: not owned here), node by
    node in order: the force at the anchor and its moment about the centroid."""
    for i in range(rows.shape[0]):
        r = rows[i]
        if r < 0:
            continue
        fx, fy, fz = reaction[i, 0], reaction[i, 1], reaction[i, 2]
        px, py, pz = ax[i, 0] - x[r, 0], ax[i, 1] - x[r, 1], ax[i, 2] - x[r, 2]
        force[r, 0] += fx
        force[r, 1] += fy
        force[r, 2] += fz
        moment[r, 0] += py * fz - pz * fy
        moment[r, 1] += pz * fx - px * fz
        moment[r, 2] += px * fy - py * fx


@kernel
def zoned_anchors(base, tet_nodes, tet_w, nodes, vel, ax, av):
    """Anchors in zoned blocks (``base``: the first gridpoint of the host's grid here, -1
    where not owned here): the host tetrahedron's gridpoints interpolated."""
    for i in range(base.shape[0]):
        g0 = base[i]
        if g0 < 0:
            continue
        for k in range(3):
            px, pv = 0.0, 0.0
            for j in range(4):
                g = g0 + tet_nodes[i, j]
                px += tet_w[i, j] * nodes[g, k]
                pv += tet_w[i, j] * vel[g, k]
            ax[i, k] = px + 0.0
            av[i, k] = pv + 0.0


@kernel
def zoned_reactions(base, tet_nodes, tet_w, reaction, kg, force, kc):
    """The hosts' reactions onto the gridpoints of owned zoned hosts, by the anchors'
    weights, node by node in order, with the grout's stiffness into their contact stiffness
    (the gridpoints' masses for the next step: pdem.deformable.store)."""
    for i in range(base.shape[0]):
        g0 = base[i]
        if g0 < 0:
            continue
        for j in range(4):
            g = g0 + tet_nodes[i, j]
            w = tet_w[i, j]
            for k in range(3):
                force[g, k] += w * reaction[i, k]
            kc[g] += w * kg[i]


@kernel
def kinetic(v, imass, slaved, anchored) -> float:
    """Kinetic energy of the nodes that move by their own forces (at t - dt/2)."""
    e = 0.0
    for i in range(v.shape[0]):
        if slaved[i] != 0 and anchored[i] != 0:
            continue
        e += 0.5 * imass[i] * (v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
    return e


def node_stiffness(n_nodes: int, seg_a, seg_b, L0, EA, ks, kg) -> np.ndarray:
    """Each node's stiffness for its stable step: its segments' ``EA/L0`` (and dowels'
    ``k_s``) and its grout's ``k_g l`` (along and across: the larger counts once)."""
    k = np.array(kg, float).copy()
    axial = EA / L0 + ks
    np.add.at(k, seg_a, axial)
    np.add.at(k, seg_b, axial)
    return k
