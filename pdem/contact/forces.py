"""Per-step sub-contact force update and assembly on the blocks (eqs. 15, 20-32)."""

from __future__ import annotations

import math

import numpy as np

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
    dus = np.empty(3)
    fs = np.empty(3)
    us = np.empty(3)
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
        fbx = 0.0
        fby = 0.0
        fbz = 0.0
        max_ = 0.0
        may = 0.0
        maz = 0.0
        mbx = 0.0
        mby = 0.0
        mbz = 0.0
        for s in range(sc_start[c], sc_start[c + 1]):
            # world position of the sub-contact (stored in A's body frame)
            px = x[a, 0] + R[a, 0, 0] * sc_pa[s, 0] + R[a, 0, 1] * sc_pa[s, 1] + R[a, 0, 2] * sc_pa[s, 2]
            py = x[a, 1] + R[a, 1, 0] * sc_pa[s, 0] + R[a, 1, 1] * sc_pa[s, 1] + R[a, 1, 2] * sc_pa[s, 2]
            pz = x[a, 2] + R[a, 2, 0] * sc_pa[s, 0] + R[a, 2, 1] * sc_pa[s, 1] + R[a, 2, 2] * sc_pa[s, 2]
            rax, ray, raz = px - x[a, 0], py - x[a, 1], pz - x[a, 2]
            rbx, rby, rbz = px - x[b, 0], py - x[b, 1], pz - x[b, 2]
            # eq. 15: velocity of B relative to A at the sub-contact
            vx = (v[b, 0] + w[b, 1] * rbz - w[b, 2] * rby) - (v[a, 0] + w[a, 1] * raz - w[a, 2] * ray)
            vy = (v[b, 1] + w[b, 2] * rbx - w[b, 0] * rbz) - (v[a, 1] + w[a, 2] * rax - w[a, 0] * raz)
            vz = (v[b, 2] + w[b, 0] * rby - w[b, 1] * rbx) - (v[a, 2] + w[a, 0] * ray - w[a, 1] * rax)
            dun = (vx * nx + vy * ny + vz * nz) * dt  # eqs. 20-21
            dus[0] = vx * dt - dun * nx  # eq. 22
            dus[1] = vy * dt - dun * ny
            dus[2] = vz * dt - dun * nz
            sc_un[s] -= dun
            # eq. 23: keep the shear force in the (turned) plane, magnitude preserved
            fs[0], fs[1], fs[2] = sc_fs[s, 0], sc_fs[s, 1], sc_fs[s, 2]
            mag0 = math.sqrt(fs[0] * fs[0] + fs[1] * fs[1] + fs[2] * fs[2])
            if mag0 > 0.0:
                fdn = fs[0] * nx + fs[1] * ny + fs[2] * nz
                fs[0] -= fdn * nx
                fs[1] -= fdn * ny
                fs[2] -= fdn * nz
                mag1 = math.sqrt(fs[0] * fs[0] + fs[1] * fs[1] + fs[2] * fs[2])
                if mag1 > 0.0:
                    fs[0] *= mag0 / mag1
                    fs[1] *= mag0 / mag1
                    fs[2] *= mag0 / mag1
            area = sc_area[s]
            kss = ks[j] * area
            fs[0] -= kss * dus[0]  # eq. 25, 27
            fs[1] -= kss * dus[1]
            fs[2] -= kss * dus[2]
            us[0] = sc_us[s, 0] + dus[0]
            us[1] = sc_us[s, 1] + dus[1]
            us[2] = sc_us[s, 2] + dus[2]
            sc_us[s, 0], sc_us[s, 1], sc_us[s, 2] = us[0], us[1], us[2]
            fn, dil, st = coulomb_slip(sc_un[s], sc_dil[s], fs, dus, area, kn[j], ks[j],
                                       tan_phi[j], tan_psi[j], cohesion[j], tension[j],
                                       us_lim[j], us, sc_state[s])
            sc_fn[s] = fn
            sc_dil[s] = dil
            sc_state[s] = st
            sc_fs[s, 0], sc_fs[s, 1], sc_fs[s, 2] = fs[0], fs[1], fs[2]
            # force on B (eq. 28 with our sign), moments about each centroid (eqs. 30, 32)
            fx = fn * nx + fs[0]
            fy = fn * ny + fs[1]
            fz = fn * nz + fs[2]
            fbx += fx
            fby += fy
            fbz += fz
            mbx += rby * fz - rbz * fy
            mby += rbz * fx - rbx * fz
            mbz += rbx * fy - rby * fx
            max_ -= ray * fz - raz * fy
            may -= raz * fx - rax * fz
            maz -= rax * fy - ray * fx
        force[a, 0] -= fbx
        force[a, 1] -= fby
        force[a, 2] -= fbz
        force[b, 0] += fbx
        force[b, 1] += fby
        force[b, 2] += fbz
        moment[a, 0] += max_
        moment[a, 1] += may
        moment[a, 2] += maz
        moment[b, 0] += mbx
        moment[b, 1] += mby
        moment[b, 2] += mbz
