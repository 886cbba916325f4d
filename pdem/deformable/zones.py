"""Constant-strain tetrahedral zones: kernels over flat arrays (reference eqs. 53-59).

Array layouts shared by every kernel of :mod:`pdem.deformable`:

- ``nodes (n, 3)``, ``vel (n, 3)``, ``force (n, 3)``: gridpoint positions, velocities, forces.
- ``tets (m, 4) int64``: positively oriented node ids (see :mod:`.mesh`).
- ``grad (m, 4, 3)``: shape-function gradients dN_a/dx_j of each zone at the current positions.
- ``vol (m,)``: zone volumes at the current positions.
- symmetric tensors as ``(m, 6)`` rows ``xx, yy, zz, xy, yz, zx``; stresses are tension-positive
  (the FLAC/3DEC sign convention; compression is negative).

For a linear tet, ``dN_a/dx = -A_a n_a / (3 V)`` with ``A_a n_a`` the outward area vector of
the face opposite node ``a``; so the gridpoint force ``f_a = -V sigma . grad N_a`` is
``sigma . n_a A_a / 3``: the contour integral of eq. 55 (each face's traction shared equally by
its three nodes). Summed over a boundary gridpoint's zones this is ``-sigma . n A / 3`` of its
boundary triangles: the internal force that balances the surface traction there.
"""

from __future__ import annotations

import numpy as np

from ..jit import inline_kernel, kernel


@inline_kernel
def _tet_gradients(x, tets, z, off, grad):
    """Fill ``grad[z] (4, 3)`` with dN_a/dx of tet ``z`` (gridpoints ``tets[z] + off``) at
    positions ``x``; return its volume."""
    i0, i1 = np.uint64(tets[z, 0] + off), np.uint64(tets[z, 1] + off)
    i2, i3 = np.uint64(tets[z, 2] + off), np.uint64(tets[z, 3] + off)
    ax, ay, az = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1], x[i1, 2] - x[i0, 2]
    bx, by, bz = x[i2, 0] - x[i0, 0], x[i2, 1] - x[i0, 1], x[i2, 2] - x[i0, 2]
    cx, cy, cz = x[i3, 0] - x[i0, 0], x[i3, 1] - x[i0, 1], x[i3, 2] - x[i0, 2]
    # rows of the inverse Jacobian: b x c, c x a, a x b over det = 6 V
    bc = (by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx)
    ca = (cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax)
    ab = (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx)
    det = ax * bc[0] + ay * bc[1] + az * bc[2]
    inv = 1.0 / det
    for j in range(3):
        grad[z, 1, j] = bc[j] * inv
        grad[z, 2, j] = ca[j] * inv
        grad[z, 3, j] = ab[j] * inv
        grad[z, 0, j] = -(grad[z, 1, j] + grad[z, 2, j] + grad[z, 3, j])
    return det / 6.0


# Each kernel below has a ``_in`` form over the zones ``za <= z < ze`` of flat arrays whose
# tets hold gridpoint numbers counted from ``off`` (a grid of pdem.deformable.store.GridStore,
# stepped without slicing its arrays: pdem.deformable.motion.step_grids) and a plain form
# over a whole grid (``za, ze, off = 0, m, 0``): the same arithmetic, so the same bits.
# Indices are unsigned (np.uint64): numba wraps a negative signed index around (a compare
# and select at every access, which also keeps LLVM from vectorizing the loop) unless LLVM
# proves it non-negative, which it cannot for a range from a start it does not know or for
# a gridpoint number read from ``tets``.


@kernel
def zone_geometry_in(nodes, tets, grad, vol, za, ze, off):
    """:func:`zone_geometry` of the zones ``za <= z < ze`` (gridpoints ``tets + off``)."""
    vmin = np.inf
    for z in range(np.uint64(za), np.uint64(ze)):
        vol[z] = _tet_gradients(nodes, tets, z, off, grad)
        vmin = min(vmin, vol[z])
    return vmin


@kernel
def zone_geometry(nodes, tets, grad, vol):
    """Shape-function gradients and volumes of every zone at the current positions.

    Returns the smallest volume (<= 0 means a zone inverted: the caller must stop).
    """
    return zone_geometry_in(nodes, tets, grad, vol, 0, tets.shape[0], 0)


@kernel
def strain_rates_in(vel, tets, grad, rate, spin, za, ze, off):
    """:func:`strain_rates` of the zones ``za <= z < ze`` (gridpoints ``tets + off``)."""
    for z in range(np.uint64(za), np.uint64(ze)):
        lxx = lyy = lzz = lxy = lyx = lyz = lzy = lzx = lxz = 0.0
        for a in range(4):
            n = np.uint64(tets[z, a] + off)
            gx, gy, gz = grad[z, a, 0], grad[z, a, 1], grad[z, a, 2]
            vx, vy, vz = vel[n, 0], vel[n, 1], vel[n, 2]
            lxx += vx * gx
            lyy += vy * gy
            lzz += vz * gz
            lxy += vx * gy
            lyx += vy * gx
            lyz += vy * gz
            lzy += vz * gy
            lzx += vz * gx
            lxz += vx * gz
        rate[z, 0] = lxx
        rate[z, 1] = lyy
        rate[z, 2] = lzz
        rate[z, 3] = 0.5 * (lxy + lyx)
        rate[z, 4] = 0.5 * (lyz + lzy)
        rate[z, 5] = 0.5 * (lzx + lxz)
        spin[z, 0] = 0.5 * (lxy - lyx)
        spin[z, 1] = 0.5 * (lyz - lzy)
        spin[z, 2] = 0.5 * (lzx - lxz)


@kernel
def strain_rates(vel, tets, grad, rate, spin):
    """Strain rate ``rate (m, 6)`` and spin ``spin (m, 3)`` (W_xy, W_yz, W_zx) per zone (eq. 58).

    Exact for a linear velocity field (the patch test): ``L_ij = sum_a v_ai dN_a/dx_j``.
    """
    strain_rates_in(vel, tets, grad, rate, spin, 0, tets.shape[0], 0)


@kernel
def add_zone_forces_in(tets, grad, vol, stress, force, za, ze, off):
    """:func:`add_zone_forces` of the zones ``za <= z < ze`` (gridpoints ``tets + off``)."""
    for z in range(np.uint64(za), np.uint64(ze)):
        sxx, syy, szz = stress[z, 0], stress[z, 1], stress[z, 2]
        sxy, syz, szx = stress[z, 3], stress[z, 4], stress[z, 5]
        v = vol[z]
        for a in range(4):
            n = np.uint64(tets[z, a] + off)
            gx, gy, gz = grad[z, a, 0], grad[z, a, 1], grad[z, a, 2]
            force[n, 0] -= v * (sxx * gx + sxy * gy + szx * gz)
            force[n, 1] -= v * (sxy * gx + syy * gy + syz * gz)
            force[n, 2] -= v * (szx * gx + syz * gy + szz * gz)


@kernel
def add_viscous_forces_in(vel, tets, grad, vol, beta, lam, shear, force, za, ze, off):
    """Add the forces of Rayleigh damping's stiffness-proportional term of the zones
    ``za <= z < ze`` (gridpoints ``tets + off``): the viscous stress ``beta D : eps_dot``
    (``D`` the elastic stiffness, Lame ``lam`` and ``shear``; ``eps_dot`` the strain rate of
    ``vel`` on the geometry ``grad``), as :func:`add_zone_forces_in` adds a zone's stress. It
    is not kept in the zone's stress: it damps, it is not held."""
    for z in range(np.uint64(za), np.uint64(ze)):
        exx = eyy = ezz = exy = eyz = ezx = 0.0
        for a in range(4):
            n = np.uint64(tets[z, a] + off)
            gx, gy, gz = grad[z, a, 0], grad[z, a, 1], grad[z, a, 2]
            vx, vy, vz = vel[n, 0], vel[n, 1], vel[n, 2]
            exx += vx * gx
            eyy += vy * gy
            ezz += vz * gz
            exy += vx * gy + vy * gx
            eyz += vy * gz + vz * gy
            ezx += vz * gx + vx * gz
        bl = beta * lam * (exx + eyy + ezz)
        b2 = 2.0 * beta * shear
        sxx, syy, szz = bl + b2 * exx, bl + b2 * eyy, bl + b2 * ezz
        bs = beta * shear  # (2 G times the tensor shear rates, half the sums above)
        sxy, syz, szx = bs * exy, bs * eyz, bs * ezx
        v = vol[z]
        for a in range(4):
            n = np.uint64(tets[z, a] + off)
            gx, gy, gz = grad[z, a, 0], grad[z, a, 1], grad[z, a, 2]
            force[n, 0] -= v * (sxx * gx + sxy * gy + szx * gz)
            force[n, 1] -= v * (sxy * gx + syy * gy + syz * gz)
            force[n, 2] -= v * (szx * gx + syz * gy + szz * gz)


@kernel
def add_zone_forces(tets, grad, vol, stress, force):
    """Add ``f_a = -V sigma . dN_a/dx`` of every zone to its gridpoints (eq. 55)."""
    add_zone_forces_in(tets, grad, vol, stress, force, 0, tets.shape[0], 0)


@kernel
def lumped_mass(n_nodes, tets, vol, density):
    """Gridpoint mass: a quarter of the mass of every zone around it (eq. 56 for tets)."""
    mass = np.zeros(n_nodes)
    for z in range(tets.shape[0]):
        q = 0.25 * density * vol[z]
        for a in range(4):
            mass[tets[z, a]] += q
    return mass


@kernel
def gravity_forces(mass, g):
    """``F = m_g g`` per gridpoint (eq. 56), ``g (3,)``."""
    out = np.empty((mass.shape[0], 3))
    for n in range(mass.shape[0]):
        for i in range(3):
            out[n, i] = mass[n] * g[i]
    return out


@kernel
def rotate_stress_in(stress, spin, dt, za, ze):
    """Jaumann correction of every zone's stress: ``sigma += (W sigma - sigma W) dt``.

    ``W`` is the spin of eq. 58 (``W_ij = (v_i,j - v_j,i) / 2``), so a rigid rotation carries
    the stress with the material instead of straining it (the large-strain update of the
    reference: positions move every step, stresses turn with the zone); of the zones
    ``za <= z < ze``.
    """
    for z in range(np.uint64(za), np.uint64(ze)):
        wxy, wyz, wzx = spin[z, 0], spin[z, 1], spin[z, 2]
        sxx, syy, szz = stress[z, 0], stress[z, 1], stress[z, 2]
        sxy, syz, szx = stress[z, 3], stress[z, 4], stress[z, 5]
        # (W s - s W)_ij with W = [[0, wxy, -wzx], [-wxy, 0, wyz], [wzx, -wyz, 0]]
        dxx = 2.0 * (wxy * sxy - wzx * szx)
        dyy = 2.0 * (wyz * syz - wxy * sxy)
        dzz = 2.0 * (wzx * szx - wyz * syz)
        dxy = wxy * (syy - sxx) - wzx * syz + wyz * szx
        dyz = wyz * (szz - syy) - wxy * szx + wzx * sxy
        dzx = wzx * (sxx - szz) - wyz * sxy + wxy * syz
        stress[z, 0] += dxx * dt
        stress[z, 1] += dyy * dt
        stress[z, 2] += dzz * dt
        stress[z, 3] += dxy * dt
        stress[z, 4] += dyz * dt
        stress[z, 5] += dzx * dt


@kernel
def rotate_stress(stress, spin, dt):
    """Jaumann correction of every zone's stress (:func:`rotate_stress_in`)."""
    rotate_stress_in(stress, spin, dt, 0, stress.shape[0])


@kernel
def surface_load(nodes, surface, traction):
    """Gridpoint forces of a uniform traction ``(3,)`` on the triangles ``surface (k, 3)``:
    each triangle's ``t A`` shared equally by its three nodes (linear velocity on faces)."""
    out = np.zeros_like(nodes)
    for k in range(surface.shape[0]):
        a, b, c = surface[k, 0], surface[k, 1], surface[k, 2]
        ux, uy, uz = nodes[b, 0] - nodes[a, 0], nodes[b, 1] - nodes[a, 1], nodes[b, 2] - nodes[a, 2]
        wx, wy, wz = nodes[c, 0] - nodes[a, 0], nodes[c, 1] - nodes[a, 1], nodes[c, 2] - nodes[a, 2]
        area = 0.5 * np.sqrt((uy * wz - uz * wy) ** 2 + (uz * wx - ux * wz) ** 2
                             + (ux * wy - uy * wx) ** 2)
        for i in range(3):
            f = traction[i] * area / 3.0
            out[a, i] += f
            out[b, i] += f
            out[c, i] += f
    return out
