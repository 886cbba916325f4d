"""The body seam of the contact loop for zoned blocks, and their per-step piece geometry.

A sub-contact on a zoned block lies on one of its surface triangles; the block's motion there
is the barycentric interpolation of the triangle's three gridpoint velocities (not
``v + w x r``), and the sub-contact's force goes to those gridpoints with the same weights (a
sub-contact at a gridpoint gives it all). :func:`locate` finds the triangle and weights of
every sub-contact after a contact update (the points then stay fixed in their contact's frame
until the next update, as for rigid blocks); :func:`contact_forces_grid` is
:func:`pdem.contact.forces.contact_forces` with that seam. Contacts between two rigid blocks
take the rigid seam's exact arithmetic, but a scene without zoned blocks never calls this
kernel (the stepper keeps the rigid one), so rigid scenes pay nothing.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from ..contact.forces import carry_shear, turn_normal
from ..contact.laws import SLIPPING, apply_law, joint_dissipation
from ..contact.rigid import (
    add_point_force,
    apply_pair,
    book_dissipation,
    pair_motion,
    point_motion,
)
from ..jit import force_kernel, inline_kernel, kernel

# dindex (rows,): zoned-block index of each block row, -1 for rigid; vel, force (N, 3): the
# flat gridpoint velocities and contact forces; sc_node (S, 2, 3) gridpoints of sub-contact s
# on side A (0) and B (1), sc_w (S, 2, 3) their weights (unused on a rigid side); kc (N,)
# each gridpoint's Gershgorin contact stiffness from the step's sub-contacts, kjoint the
# stiffest joint's max(kn, ks) (Pa/m) it is counted with (GridStore.step's partial scaling)
Grid = namedtuple("Grid", "dindex vel force sc_node sc_w kc kjoint")


@inline_kernel
def closest_on_triangle(px, py, pz, a, b, c):
    """Barycentric weights (wa, wb, wc) of the point of triangle abc closest to p, and the
    squared distance (Ericson, Real-Time Collision Detection 5.1.5)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    if d1 <= 0.0 and d2 <= 0.0:
        wa, wb, wc = 1.0, 0.0, 0.0
    elif d3 >= 0.0 and d4 <= d3:
        wa, wb, wc = 0.0, 1.0, 0.0
    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        wa, wb, wc = 1.0 - t, t, 0.0
    elif d6 >= 0.0 and d5 <= d6:
        wa, wb, wc = 0.0, 0.0, 1.0
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        wa, wb, wc = 1.0 - t, 0.0, t
    elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        wa, wb, wc = 0.0, 1.0 - t, t
    else:
        den = 1.0 / (va + vb + vc)
        wb = vb * den
        wc = vc * den
        wa = 1.0 - wb - wc
    qx = wa * a[0] + wb * b[0] + wc * c[0] - px
    qy = wa * a[1] + wb * b[1] + wc * c[1] - py
    qz = wa * a[2] + wb * b[2] + wc * c[2] - pz
    return wa, wb, wc, qx * qx + qy * qy + qz * qz


@kernel
def locate(ia, ib, ka, kb, sc_start, pa, x, R, face_start, fvert_start, face_verts, nodes,
           vnode, dindex, todo, sc_node, sc_w):
    """Triangle and barycentric weights of every sub-contact of the contacts ``todo`` on
    each zoned side: the surface triangle of that side's piece nearest the sub-contact point
    (world ``x_a + R_a pa``). ``vnode`` maps vertex rows to gridpoints, ``nodes`` the
    gridpoint positions."""
    for c in range(ia.shape[0]):
        a, b = ia[c], ib[c]
        if todo[c] == 0 or (dindex[a] < 0 and dindex[b] < 0):
            continue
        for s in range(sc_start[c], sc_start[c + 1]):
            p0, p1, p2 = pa[s, 0], pa[s, 1], pa[s, 2]
            px = x[a, 0] + R[a, 0, 0] * p0 + R[a, 0, 1] * p1 + R[a, 0, 2] * p2
            py = x[a, 1] + R[a, 1, 0] * p0 + R[a, 1, 1] * p1 + R[a, 1, 2] * p2
            pz = x[a, 2] + R[a, 2, 0] * p0 + R[a, 2, 1] * p1 + R[a, 2, 2] * p2
            for side in range(2):
                k = ka[c] if side == 0 else kb[c]
                if dindex[a if side == 0 else b] < 0:
                    continue
                best = np.inf
                for f in range(face_start[k], face_start[k + 1]):
                    j = fvert_start[f]
                    n0 = vnode[face_verts[j]]
                    n1 = vnode[face_verts[j + 1]]
                    n2 = vnode[face_verts[j + 2]]
                    wa, wb, wc, d2 = closest_on_triangle(px, py, pz, nodes[n0], nodes[n1],
                                                          nodes[n2])
                    if d2 < best:
                        best = d2
                        sc_node[s, side, 0], sc_node[s, side, 1], sc_node[s, side, 2] = n0, n1, n2
                        sc_w[s, side, 0], sc_w[s, side, 1], sc_w[s, side, 2] = wa, wb, wc


@inline_kernel
def _grid_velocity(grid, s, side):
    n, w, v = grid.sc_node, grid.sc_w, grid.vel
    vx = vy = vz = 0.0
    for i in range(3):
        g = n[s, side, i]
        vx += w[s, side, i] * v[g, 0]
        vy += w[s, side, i] * v[g, 1]
        vz += w[s, side, i] * v[g, 2]
    return vx, vy, vz


@inline_kernel
def _grid_force(grid, s, side, fx, fy, fz, k2):
    """The force on a zoned side's gridpoints, and their share ``w k2`` of the spring's
    Gershgorin row: a spring K between two weighted points couples every gridpoint of both
    (weights >= 0, summing to 1 a side), so gridpoint i's row holds ``K w_i (1 + 1)``: ``k2``
    is 2 K. On the triangle side this can exceed the gridpoint's own area share (a finer or
    larger neighbour landing on a sliver's small triangles): the build's estimate misses it."""
    n, w, f, kc = grid.sc_node, grid.sc_w, grid.force, grid.kc
    for i in range(3):
        g = n[s, side, i]
        f[g, 0] += w[s, side, i] * fx
        f[g, 1] += w[s, side, i] * fy
        f[g, 2] += w[s, side, i] * fz
        kc[g] += w[s, side, i] * k2


@force_kernel  # a call, not inlined: numba's IR inlining of the inlined joint law inside it warns
def _sub_update(dt, subs, joints, slot, j, s, vx, vy, vz, nx, ny, nz):
    """One sub-contact's joint update from the relative velocity (as in contact_forces):
    returns the force on B and the energy the joint dissipated."""
    dun = (vx * nx + vy * ny + vz * nz) * dt
    dsx = vx * dt - dun * nx
    dsy = vy * dt - dun * ny
    dsz = vz * dt - dun * nz
    un0 = subs.un[s]
    un = un0 - dun
    subs.un[s] = un
    fx, fy, fz = carry_shear(subs.fs[s, 0], subs.fs[s, 1], subs.fs[s, 2], nx, ny, nz)
    ux = subs.us[s, 0] + dsx
    uy = subs.us[s, 1] + dsy
    uz = subs.us[s, 2] + dsz
    subs.us[s, 0], subs.us[s, 1], subs.us[s, 2] = ux, uy, uz
    area = subs.area[s]
    gx, gy, gz = fx, fy, fz
    dil0 = subs.dil[s]
    st0 = subs.state[s]
    fn, dil, st, fx, fy, fz = apply_law(joints.laws, slot, j, s, subs.hist, un, dil0, fx, fy, fz,
                                        dsx, dsy, dsz, area, ux, uy, uz, st0)
    subs.dil[s] = dil
    subs.state[s] = st
    subs.fs[s, 0], subs.fs[s, 1], subs.fs[s, 2] = fx, fy, fz
    dissipated = 0.0
    if (st & SLIPPING) or st != st0 or dil != dil0:
        dissipated = joint_dissipation(joints.laws, slot, j, s, subs.hist, dun, dsx, dsy, dsz,
                                       area, un0, dil0, gx, gy, gz, st0, un, dil, fn, fx, fy, fz,
                                       st)
    return fx + fn * nx, fy + fn * ny, fz + fn * nz, dissipated


@force_kernel
def contact_forces_grid(dt, bodies, pairs, subs, joints, grid):
    """:func:`pdem.contact.forces.contact_forces` for a scene with zoned blocks (no held
    inactive contacts: ``solve.inactive`` is refused with zones). A zoned side's velocity and
    force are its triangle's gridpoints' (module doc); its ``dtheta`` is zero, so the plane
    normal turns with the rigid side only."""
    for c in range(pairs.ia.shape[0]):
        a = pairs.ia[c]
        b = pairs.ib[c]
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
        da = grid.dindex[a]
        db = grid.dindex[b]
        acc = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        dissipated = 0.0
        if da < 0 and db < 0:  # the rigid seam, as contact_forces
            for s in range(s0, s1):
                rax, ray, raz, vx, vy, vz = point_motion(rel, subs.pa[s, 0], subs.pa[s, 1],
                                                         subs.pa[s, 2])
                fx, fy, fz, dis = _sub_update(dt, subs, joints, slot, j, s, vx, vy, vz, nx, ny,
                                              nz)
                dissipated += dis
                acc = add_point_force(acc, rax, ray, raz, fx, fy, fz)
            apply_pair(bodies, a, b, rel, acc, dissipated)
            continue
        ra = rel[0]
        ddx, ddy, ddz = rel[1]
        v, w = bodies.v, bodies.w
        # rigid-side sums: force and moment on A about x_a, on B about x_b
        fa = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        fb = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        for s in range(s0, s1):
            p0, p1, p2 = subs.pa[s, 0], subs.pa[s, 1], subs.pa[s, 2]
            rax = ra[0] * p0 + ra[1] * p1 + ra[2] * p2
            ray = ra[3] * p0 + ra[4] * p1 + ra[5] * p2
            raz = ra[6] * p0 + ra[7] * p1 + ra[8] * p2
            rbx, rby, rbz = rax + ddx, ray + ddy, raz + ddz
            if da >= 0:
                vax, vay, vaz = _grid_velocity(grid, s, 0)
            else:
                vax = v[a, 0] + (w[a, 1] * raz - w[a, 2] * ray)
                vay = v[a, 1] + (w[a, 2] * rax - w[a, 0] * raz)
                vaz = v[a, 2] + (w[a, 0] * ray - w[a, 1] * rax)
            if db >= 0:
                vbx, vby, vbz = _grid_velocity(grid, s, 1)
            else:
                vbx = v[b, 0] + (w[b, 1] * rbz - w[b, 2] * rby)
                vby = v[b, 1] + (w[b, 2] * rbx - w[b, 0] * rbz)
                vbz = v[b, 2] + (w[b, 0] * rby - w[b, 1] * rbx)
            fx, fy, fz, dis = _sub_update(dt, subs, joints, slot, j, s, vbx - vax, vby - vay,
                                          vbz - vaz, nx, ny, nz)
            dissipated += dis
            k2 = 2.0 * grid.kjoint * subs.area[s]
            if db >= 0:
                _grid_force(grid, s, 1, fx, fy, fz, k2)
            else:
                fb = add_point_force(fb, rbx, rby, rbz, fx, fy, fz)
            if da >= 0:
                _grid_force(grid, s, 0, -fx, -fy, -fz, k2)
            else:
                fa = add_point_force(fa, rax, ray, raz, -fx, -fy, -fz)
        for i in range(3):
            bodies.force[a, i] += fa[i]
            bodies.moment[a, i] += fa[3 + i]
            bodies.force[b, i] += fb[i]
            bodies.moment[b, i] += fb[3 + i]
        book_dissipation(bodies, a, b, dissipated)


@kernel
def refresh_pieces(rows, node_start, surf_start, surf, nodes, vel, gmass, x, v, dx, radius,
                   piece_start, vert_start, verts_local, face_start, fvert_start, face_verts,
                   normals_local, offsets_local, edge_start, edges, edir_start, edirs_local):
    """After a grid step: each zoned block's row from its gridpoints (``x`` the mass-weighted
    centroid, ``v`` the mean velocity, ``dx`` the largest gridpoint motion of the step as a
    vector, so that eq. 1's motion bound covers the deforming surface) and its piece geometry
    in the identity frame (vertices, triangle planes, edge directions), and its radius."""
    for d in range(rows.shape[0]):
        r = rows[d]
        a, e = node_start[d], node_start[d + 1]
        m = 0.0
        cx = cy = cz = vx = vy = vz = 0.0
        for n in range(a, e):
            g = gmass[n]
            m += g
            cx += g * nodes[n, 0]
            cy += g * nodes[n, 1]
            cz += g * nodes[n, 2]
            vx += g * vel[n, 0]
            vy += g * vel[n, 1]
            vz += g * vel[n, 2]
        cx /= m
        cy /= m
        cz /= m
        k = piece_start[r]
        v0 = vert_start[k]
        # the largest gridpoint motion: old surface vertex + old x vs new
        big = 0.0
        bx = by = bz = 0.0
        rad = 0.0
        for i in range(surf_start[d + 1] - surf_start[d]):
            n = a + surf[surf_start[d] + i]
            ox = verts_local[v0 + i, 0] + x[r, 0]
            oy = verts_local[v0 + i, 1] + x[r, 1]
            oz = verts_local[v0 + i, 2] + x[r, 2]
            mx, my, mz = nodes[n, 0] - ox, nodes[n, 1] - oy, nodes[n, 2] - oz
            mm = mx * mx + my * my + mz * mz
            if mm > big:
                big = mm
                bx, by, bz = mx, my, mz
            lx, ly, lz = nodes[n, 0] - cx, nodes[n, 1] - cy, nodes[n, 2] - cz
            verts_local[v0 + i, 0], verts_local[v0 + i, 1], verts_local[v0 + i, 2] = lx, ly, lz
            rad = max(rad, math.sqrt(lx * lx + ly * ly + lz * lz))
        x[r, 0], x[r, 1], x[r, 2] = cx, cy, cz
        v[r, 0], v[r, 1], v[r, 2] = vx / m, vy / m, vz / m
        dx[r, 0], dx[r, 1], dx[r, 2] = bx, by, bz
        radius[r] = rad
        for f in range(face_start[k], face_start[k + 1]):
            j = fvert_start[f]
            p, q, t = face_verts[j], face_verts[j + 1], face_verts[j + 2]
            ux = verts_local[q, 0] - verts_local[p, 0]
            uy = verts_local[q, 1] - verts_local[p, 1]
            uz = verts_local[q, 2] - verts_local[p, 2]
            wx = verts_local[t, 0] - verts_local[p, 0]
            wy = verts_local[t, 1] - verts_local[p, 1]
            wz = verts_local[t, 2] - verts_local[p, 2]
            nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
            inv = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
            nx, ny, nz = nx * inv, ny * inv, nz * inv
            normals_local[f, 0], normals_local[f, 1], normals_local[f, 2] = nx, ny, nz
            offsets_local[f] = (nx * (verts_local[p, 0] + verts_local[q, 0] + verts_local[t, 0])
                                + ny * (verts_local[p, 1] + verts_local[q, 1] + verts_local[t, 1])
                                + nz * (verts_local[p, 2] + verts_local[q, 2] + verts_local[t, 2])
                                ) / 3.0
        # the edge directions: of the piece's first edges (pdem.deformable.zoning)
        t0 = edir_start[k]
        for i in range(edir_start[k + 1] - t0):
            p, q = edges[edge_start[k] + i, 0], edges[edge_start[k] + i, 1]
            ux = verts_local[q, 0] - verts_local[p, 0]
            uy = verts_local[q, 1] - verts_local[p, 1]
            uz = verts_local[q, 2] - verts_local[p, 2]
            inv = 1.0 / math.sqrt(ux * ux + uy * uy + uz * uz)
            edirs_local[t0 + i, 0], edirs_local[t0 + i, 1], edirs_local[t0 + i, 2] = \
                ux * inv, uy * inv, uz * inv
