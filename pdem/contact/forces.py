"""Per-step sub-contact force update and assembly on the blocks (eqs. 15, 20-32)."""

from __future__ import annotations

import math

from ..jit import kernel
from .joint import coulomb_slip


@kernel
def rotation_matrices(q, out):
    """Rotation matrix of each unit quaternion (w, x, y, z)."""
    for b in range(q.shape[0]):
        w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        out[b, 0, 0] = 1 - 2 * (y * y + z * z)
        out[b, 0, 1] = 2 * (x * y - w * z)
        out[b, 0, 2] = 2 * (x * z + w * y)
        out[b, 1, 0] = 2 * (x * y + w * z)
        out[b, 1, 1] = 1 - 2 * (x * x + z * z)
        out[b, 1, 2] = 2 * (y * z - w * x)
        out[b, 2, 0] = 2 * (x * z - w * y)
        out[b, 2, 1] = 2 * (y * z + w * x)
        out[b, 2, 2] = 1 - 2 * (x * x + y * y)


@kernel
def contact_forces(dt, x, R, v, w, dtheta, force, moment,
                   c_ia, c_ib, c_joint, c_normal, sc_start, sc_pa, sc_area,
                   sc_un, sc_fn, sc_fs, sc_us, sc_dil, sc_state,
                   kn, ks, tan_phi, tan_psi, cohesion, tension, us_lim):
    """Advance every sub-contact by one step and add the contact forces to the blocks.

    The relative displacement increment at each sub-contact is ``V dt`` with ``V`` the velocity
    of B relative to A there (eq. 15, 20), split into normal and shear parts (eqs. 21-22). The
    common-plane normal turns with the mean incremental rotation of the two blocks, and the
    existing shear force is turned with it (eq. 23). Forces follow the joint law and are summed
    on both blocks (eqs. 28-32) in contact order, which is the canonical key order, so the sum
    does not depend on how contacts were distributed over ranks.

    Sign convention: ``n`` points from A to B; the force on B is ``fn n + fs`` (``fn`` > 0 in
    compression) and the force on A is its opposite. (Eq. 28 writes the action with the
    opposite sign and correspondingly flips eq. 29/31.)
    """
    nc = c_ia.shape[0]
    for c in range(nc):
        a = c_ia[c]
        b = c_ib[c]
        j = c_joint[c]
        # turn the plane with the blocks (mean incremental rotation)
        nx, ny, nz = c_normal[c, 0], c_normal[c, 1], c_normal[c, 2]
        tx = 0.5 * (dtheta[a, 0] + dtheta[b, 0])
        ty = 0.5 * (dtheta[a, 1] + dtheta[b, 1])
        tz = 0.5 * (dtheta[a, 2] + dtheta[b, 2])
        mx = nx + (ty * nz - tz * ny)
        my = ny + (tz * nx - tx * nz)
        mz = nz + (tx * ny - ty * nx)
        inv = 1.0 / math.sqrt(mx * mx + my * my + mz * mz)
        nx, ny, nz = mx * inv, my * inv, mz * inv
        c_normal[c, 0], c_normal[c, 1], c_normal[c, 2] = nx, ny, nz
        s0 = sc_start[c]
        s1 = sc_start[c + 1]
        if s1 == s0:
            continue
        # Per-contact constants, hoisted into locals (the compiler cannot prove the sub-contact
        # stores do not alias the block arrays, so it would reload them per sub-contact).
        r00, r01, r02 = R[a, 0, 0], R[a, 0, 1], R[a, 0, 2]
        r10, r11, r12 = R[a, 1, 0], R[a, 1, 1], R[a, 1, 2]
        r20, r21, r22 = R[a, 2, 0], R[a, 2, 1], R[a, 2, 2]
        # r_b = r_a + d with d = x_a - x_b
        ddx = x[a, 0] - x[b, 0]
        ddy = x[a, 1] - x[b, 1]
        ddz = x[a, 2] - x[b, 2]
        wax, way, waz = w[a, 0], w[a, 1], w[a, 2]
        wbx, wby, wbz = w[b, 0], w[b, 1], w[b, 2]
        # eq. 15: V = v_b + w_b x r_b - v_a - w_a x r_a = V0 + (w_b - w_a) x r_a
        v0x = v[b, 0] - v[a, 0] + (wby * ddz - wbz * ddy)
        v0y = v[b, 1] - v[a, 1] + (wbz * ddx - wbx * ddz)
        v0z = v[b, 2] - v[a, 2] + (wbx * ddy - wby * ddx)
        dwx = wbx - wax
        dwy = wby - way
        dwz = wbz - waz
        kn_j = kn[j]
        ks_j = ks[j]
        tphi = tan_phi[j]
        tpsi = tan_psi[j]
        coh = cohesion[j]
        ten = tension[j]
        ulim = us_lim[j]
        fbx = 0.0
        fby = 0.0
        fbz = 0.0
        max_ = 0.0
        may = 0.0
        maz = 0.0
        mbx = 0.0
        mby = 0.0
        mbz = 0.0
        for s in range(s0, s1):
            # sub-contact relative to A's centroid (stored in A's body frame)
            p0, p1, p2 = sc_pa[s, 0], sc_pa[s, 1], sc_pa[s, 2]
            rax = r00 * p0 + r01 * p1 + r02 * p2
            ray = r10 * p0 + r11 * p1 + r12 * p2
            raz = r20 * p0 + r21 * p1 + r22 * p2
            # eq. 15: velocity of B relative to A at the sub-contact
            vx = v0x + (dwy * raz - dwz * ray)
            vy = v0y + (dwz * rax - dwx * raz)
            vz = v0z + (dwx * ray - dwy * rax)
            dun = (vx * nx + vy * ny + vz * nz) * dt  # eqs. 20-21
            dsx = vx * dt - dun * nx  # eq. 22
            dsy = vy * dt - dun * ny
            dsz = vz * dt - dun * nz
            un = sc_un[s] - dun
            sc_un[s] = un
            # eq. 23: keep the shear force in the (turned) plane, magnitude preserved
            fx, fy, fz = sc_fs[s, 0], sc_fs[s, 1], sc_fs[s, 2]
            fdn = fx * nx + fy * ny + fz * nz
            if fdn != 0.0:
                mag0 = fx * fx + fy * fy + fz * fz
                fx -= fdn * nx
                fy -= fdn * ny
                fz -= fdn * nz
                mag1 = fx * fx + fy * fy + fz * fz
                if mag1 > 0.0:
                    sc = math.sqrt(mag0 / mag1)
                    fx *= sc
                    fy *= sc
                    fz *= sc
            area = sc_area[s]
            kss = ks_j * area
            ux = sc_us[s, 0] + dsx
            uy = sc_us[s, 1] + dsy
            uz = sc_us[s, 2] + dsz
            sc_us[s, 0], sc_us[s, 1], sc_us[s, 2] = ux, uy, uz
            fn, dil, st, fx, fy, fz = coulomb_slip(
                un, sc_dil[s], fx - kss * dsx, fy - kss * dsy, fz - kss * dsz,  # eq. 25, 27
                dsx, dsy, dsz, area, kn_j, tphi, tpsi, coh, ten, ulim, ux, uy, uz, sc_state[s])
            sc_fn[s] = fn
            sc_dil[s] = dil
            sc_state[s] = st
            sc_fs[s, 0], sc_fs[s, 1], sc_fs[s, 2] = fx, fy, fz
            # force on B (eq. 28 with our sign), moments about each centroid (eqs. 30, 32):
            # m_b = r_b x f = r_a x f + d x f, summed per contact; m_a = -(r_a x f)
            fx += fn * nx
            fy += fn * ny
            fz += fn * nz
            fbx += fx
            fby += fy
            fbz += fz
            max_ += ray * fz - raz * fy
            may += raz * fx - rax * fz
            maz += rax * fy - ray * fx
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
