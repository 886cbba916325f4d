"""Physical kinetic energy and momenta of the block set (for reporting and tests).

Velocities are taken as stored (``v``, ``L`` at ``t + dt/2`` after a step).  ``L`` is the
*inertial* angular momentum (scaled inertia when mass scaling is on); the physical angular
velocity is ``w = R (s I)^-1 R^T L`` and the physical values below use the true mass and
inertia.  With ``mass_scale = 1`` everything is the plain mechanical quantity.
"""

from __future__ import annotations

import numpy as np

from pdem.dynamics.rotation import rotate_inv_s
from pdem.jit import kernel


@kernel
def kinetic_energy(mass, inertia, q, v, L, mass_scale, scalar_inertia):
    """Total (translational, rotational) kinetic energy; rotational from L and inertia at q.

    Rotational: ``1/2 sum_k I_k wb_k^2`` with body components ``wb = R^T L / (s I_k)``.
    ``scalar_inertia`` uses the mean principal moment, as the integrator does.
    """
    et = 0.0
    er = 0.0
    for i in range(mass.shape[0]):
        s = mass_scale[i]
        et += 0.5 * mass[i] * (v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
        i1 = inertia[i, 0]
        i2 = inertia[i, 1]
        i3 = inertia[i, 2]
        if scalar_inertia:
            if not (i1 == i2 and i2 == i3):
                i1 = (i1 + i2 + i3) / 3.0
            i2 = i1
            i3 = i1
        bx, by, bz = rotate_inv_s(q[i, 0], q[i, 1], q[i, 2], q[i, 3], L[i, 0], L[i, 1], L[i, 2])
        s2 = s * s
        er += 0.5 * (bx * bx / i1 + by * by / i2 + bz * bz / i3) / s2
    return et, er


@kernel
def angular_momentum(mass, x, v, L, mass_scale):
    """Total physical angular momentum about the origin: sum m x × v + L / s."""
    out = np.zeros(3)
    for i in range(mass.shape[0]):
        m = mass[i]
        s = mass_scale[i]
        out[0] += m * (x[i, 1] * v[i, 2] - x[i, 2] * v[i, 1]) + L[i, 0] / s
        out[1] += m * (x[i, 2] * v[i, 0] - x[i, 0] * v[i, 2]) + L[i, 1] / s
        out[2] += m * (x[i, 0] * v[i, 1] - x[i, 1] * v[i, 0]) + L[i, 2] / s
    return out


@kernel
def linear_momentum(mass, v):
    """Total linear momentum sum m v."""
    out = np.zeros(3)
    for i in range(mass.shape[0]):
        for k in range(3):
            out[k] += mass[i] * v[i, k]
    return out


def kinetic_per_block(b, rows) -> np.ndarray:
    """Kinetic energy of blocks ``rows`` of a block store, as integrated: translation with the
    inertial mass and rotation w . L / 2, both at t - dt/2."""
    v, w, L = b.v[rows], b.w[rows], b.L[rows]
    return 0.5 * b.mass[rows] * b.mscale[rows] * np.einsum("ij,ij->i", v, v) \
        + 0.5 * np.einsum("ij,ij->i", w, L)
