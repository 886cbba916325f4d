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

from ..contact.forces import (
    book_on_blocks,
    carry_shear,
    dashpot,
    dashpot_constants,
    has_dashpots,
    turn_normal,
)
from ..contact.laws import OPEN, SLIPPING, apply_law, joint_dissipation, law_stays_open
from ..contact.rigid import (
    WORK_DAMPING,
    add_point_force,
    apply_pair,
    book_dissipation,
    pair_motion,
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


@force_kernel
def contact_forces_grid(dt, bodies, pairs, subs, joints, grid):
    """:func:`pdem.contact.forces.contact_forces` for a scene with zoned blocks (no held
    inactive contacts: ``solve.inactive`` is refused with zones). A zoned side's velocity is
    the barycentric sum of its triangle's gridpoint velocities and its force goes to those
    gridpoints with the same weights (module doc); its ``dtheta`` is zero, so the plane normal
    turns with the rigid side only. A contact of two rigid blocks takes the rigid kernel's
    arithmetic (``point_motion``, one force and moment sum, ``apply_pair``).

    Every sub-contact also adds to ``grid.kc`` its spring's share of the Gershgorin row of
    each gridpoint of a zoned side: a spring ``K = kjoint A`` between two weighted points
    (weights >= 0, summing to 1 a side) couples every gridpoint of both, so gridpoint i's row
    holds ``K w_i (1 + 1)``, ``w_i k2`` with ``k2 = 2 K`` (GridStore.step's partial density
    scaling). On the triangle side this can exceed the gridpoint's own area share (a finer or
    larger neighbour landing on a sliver's small triangles): the build's estimate misses it.

    Written as one loop over plain arrays taken from the records once, above the loops:
    numba counts the references of an array bound to a variable (an atomic increment and
    decrement), and a helper called or inlined per sub-contact with the records binds each
    of their arrays anew, which took ~60 % of this loop on a rock mass of 1,000 zoned cubes
    (bench/zoned_rock_mass.py). As in the rigid kernel, a sub-contact that is separated and
    stays so skips its law (zero forces, the same state: the force sums and the dissipation
    unchanged, the sums never being -0) but still adds its ``kc``; dilation and state are
    stored only when changed. Rayleigh's dashpots (``joints.dash``) act as in the rigid
    kernel, on the relative velocity of the two sides' interpolated points, their force
    spread as the joint's is (the grids' step already allows for ``beta`` with the joint
    springs in its bound)."""
    ia, ib, normal, sc_start, joint, frozen = (pairs.ia, pairs.ib, pairs.normal, pairs.sc_start,
                                               pairs.joint, pairs.frozen)
    pa, sarea, sun, sfs, sus, sdil, sstate, hist = subs
    laws, jslot, jrow = joints.laws, joints.slot, joints.row
    dindex, vel, gforce, sc_node, sc_w, kc = (grid.dindex, grid.vel, grid.force, grid.sc_node,
                                              grid.sc_w, grid.kc)
    k2j = 2.0 * grid.kjoint
    dash = joints.dash
    damped = has_dashpots(dash)
    v, w, force, moment = bodies.v, bodies.w, bodies.force, bodies.moment
    for c in range(ia.shape[0]):
        a = np.uint64(ia[c])
        b = np.uint64(ib[c])
        frozen[c] = 0
        nx, ny, nz = turn_normal(normal, bodies.dtheta, c, a, b)
        s0 = sc_start[c]
        s1 = sc_start[c + 1]
        if s1 == s0:
            continue
        rel = pair_motion(bodies, a, b)
        slot = jslot[joint[c]]
        j = jrow[joint[c]]
        da = dindex[a]
        db = dindex[b]
        rigid = da < 0 and db < 0
        ra = rel[0]
        ddx, ddy, ddz = rel[1]
        v0x, v0y, v0z = rel[2]
        dwx, dwy, dwz = rel[3]
        rbx = rby = rbz = 0.0
        # force and moment sums: on B about x_b, or (two rigid blocks) about x_a as the rigid
        # kernel's; on a rigid A about x_a
        fa = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        fb = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        dissipated = 0.0
        damped_out = 0.0
        cn, cs = dashpot_constants(dash, joint[c])
        # unsigned: no negative-index wrap on the sub-contact and gridpoint reads
        for s in range(np.uint64(s0), np.uint64(s1)):
            p0, p1, p2 = pa[s, 0], pa[s, 1], pa[s, 2]
            rax = ra[0] * p0 + ra[1] * p1 + ra[2] * p2
            ray = ra[3] * p0 + ra[4] * p1 + ra[5] * p2
            raz = ra[6] * p0 + ra[7] * p1 + ra[8] * p2
            if rigid:  # eq. 15, as point_motion
                vx = v0x + (dwy * raz - dwz * ray)
                vy = v0y + (dwz * rax - dwx * raz)
                vz = v0z + (dwx * ray - dwy * rax)
            else:
                rbx, rby, rbz = rax + ddx, ray + ddy, raz + ddz
                vax = vay = vaz = 0.0
                if da >= 0:
                    for i in range(3):
                        g = np.uint64(sc_node[s, 0, i])
                        vax += sc_w[s, 0, i] * vel[g, 0]
                        vay += sc_w[s, 0, i] * vel[g, 1]
                        vaz += sc_w[s, 0, i] * vel[g, 2]
                else:
                    vax = v[a, 0] + (w[a, 1] * raz - w[a, 2] * ray)
                    vay = v[a, 1] + (w[a, 2] * rax - w[a, 0] * raz)
                    vaz = v[a, 2] + (w[a, 0] * ray - w[a, 1] * rax)
                vbx = vby = vbz = 0.0
                if db >= 0:
                    for i in range(3):
                        g = np.uint64(sc_node[s, 1, i])
                        vbx += sc_w[s, 1, i] * vel[g, 0]
                        vby += sc_w[s, 1, i] * vel[g, 1]
                        vbz += sc_w[s, 1, i] * vel[g, 2]
                else:
                    vbx = v[b, 0] + (w[b, 1] * rbz - w[b, 2] * rby)
                    vby = v[b, 1] + (w[b, 2] * rbx - w[b, 0] * rbz)
                    vbz = v[b, 2] + (w[b, 0] * rby - w[b, 1] * rbx)
                vx, vy, vz = vbx - vax, vby - vay, vbz - vaz
            # the joint update (as contact_forces'): eqs. 20-22, the law, eq. 23
            dun = (vx * nx + vy * ny + vz * nz) * dt
            dsx = vx * dt - dun * nx
            dsy = vy * dt - dun * ny
            dsz = vz * dt - dun * nz
            un0 = sun[s]
            un = un0 - dun
            sun[s] = un
            ux = sus[s, 0] + dsx
            uy = sus[s, 1] + dsy
            uz = sus[s, 2] + dsz
            sus[s, 0], sus[s, 1], sus[s, 2] = ux, uy, uz
            area = sarea[s]
            k2 = k2j * area
            dil0 = sdil[s]
            st0 = sstate[s]
            if st0 & OPEN and law_stays_open(laws, slot, j, s, hist, un, dil0, area, st0):
                sfs[s, 0], sfs[s, 1], sfs[s, 2] = 0.0, 0.0, 0.0
                if db >= 0:
                    for i in range(3):
                        kc[np.uint64(sc_node[s, 1, i])] += sc_w[s, 1, i] * k2
                if da >= 0:
                    for i in range(3):
                        kc[np.uint64(sc_node[s, 0, i])] += sc_w[s, 0, i] * k2
                continue
            fx, fy, fz = carry_shear(sfs[s, 0], sfs[s, 1], sfs[s, 2], nx, ny, nz)
            gx, gy, gz = fx, fy, fz
            fn, dil, st, fx, fy, fz = apply_law(laws, slot, j, s, hist, un, dil0, fx, fy, fz,
                                                dsx, dsy, dsz, area, ux, uy, uz, st0)
            if dil != dil0:
                sdil[s] = dil
            if st != st0:
                sstate[s] = st
            sfs[s, 0], sfs[s, 1], sfs[s, 2] = fx, fy, fz
            if (st & SLIPPING) or st != st0 or dil != dil0:
                dissipated += joint_dissipation(laws, slot, j, s, hist, dun, dsx, dsy, dsz,
                                                area, un0, dil0, gx, gy, gz, st0, un, dil, fn,
                                                fx, fy, fz, st)
            # the force on B (eq. 28 with our sign), on A its opposite
            fx, fy, fz = fx + fn * nx, fy + fn * ny, fz + fn * nz
            if damped and not st & OPEN:
                dx, dy, dz, de = dashpot(cn, cs, area, vx, vy, vz, nx, ny, nz, dt)
                fx += dx
                fy += dy
                fz += dz
                damped_out += de
            if rigid:
                fb = add_point_force(fb, rax, ray, raz, fx, fy, fz)
                continue
            if db >= 0:
                for i in range(3):
                    g = np.uint64(sc_node[s, 1, i])
                    wi = sc_w[s, 1, i]
                    gforce[g, 0] += wi * fx
                    gforce[g, 1] += wi * fy
                    gforce[g, 2] += wi * fz
                    kc[g] += wi * k2
            else:
                fb = add_point_force(fb, rbx, rby, rbz, fx, fy, fz)
            if da >= 0:
                for i in range(3):
                    g = np.uint64(sc_node[s, 0, i])
                    wi = sc_w[s, 0, i]
                    gforce[g, 0] += wi * -fx
                    gforce[g, 1] += wi * -fy
                    gforce[g, 2] += wi * -fz
                    kc[g] += wi * k2
            else:
                fa = add_point_force(fa, rax, ray, raz, -fx, -fy, -fz)
        if damped:
            book_on_blocks(bodies, a, b, damped_out, WORK_DAMPING)
        if rigid:
            apply_pair(bodies, a, b, rel, fb, dissipated)
            continue
        for i in range(3):
            force[a, i] += fa[i]
            moment[a, i] += fa[3 + i]
            force[b, i] += fb[i]
            moment[b, i] += fb[3 + i]
        book_dissipation(bodies, a, b, dissipated)


@kernel
def refresh_pieces(rows, node_start, surf_start, surf, nodes, vel, gmass, x, v, dx, radius,
                   piece_start, vert_start, verts_local, dtheta, w, L):
    """After a grid step: each zoned block's row from its gridpoints (``x`` the mass-weighted
    centroid, ``v`` the mean velocity, ``dx`` the largest gridpoint motion of the step as a
    vector, so that eq. 1's motion bound covers the deforming surface; no rotation: ``dtheta``,
    ``w``, ``L`` zero), its piece's vertices in the identity frame and its radius. The piece's
    planes follow from the vertices when they are read (:func:`piece_planes`). The stepper
    and the compiled loop of steps (pdem.cycle) both call it
    (:meth:`~pdem.deformable.store.GridStore.sync_args`)."""
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
        for i in range(3):
            dtheta[r, i] = 0.0
            w[r, i] = 0.0
            L[r, i] = 0.0
        radius[r] = rad


@kernel
def piece_planes(rows, piece_start, verts_local, face_start, fvert_start, face_verts,
                 normals_local, offsets_local, edge_start, edges, edir_start, edirs_local):
    """The zoned blocks' (block ``rows``) piece planes from their vertices: the triangles'
    unit normals and offsets, and the directions of the piece's first edges
    (pdem.deformable.zoning)."""
    for d in range(rows.shape[0]):
        k = piece_start[rows[d]]
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
        t0 = edir_start[k]
        for i in range(edir_start[k + 1] - t0):
            p, q = edges[edge_start[k] + i, 0], edges[edge_start[k] + i, 1]
            ux = verts_local[q, 0] - verts_local[p, 0]
            uy = verts_local[q, 1] - verts_local[p, 1]
            uz = verts_local[q, 2] - verts_local[p, 2]
            inv = 1.0 / math.sqrt(ux * ux + uy * uy + uz * uz)
            edirs_local[t0 + i, 0], edirs_local[t0 + i, 1], edirs_local[t0 + i, 2] = \
                ux * inv, uy * inv, uz * inv
