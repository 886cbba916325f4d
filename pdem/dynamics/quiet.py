"""Quiet (viscous) faces and wave input on rigid blocks (docs/dynamics.md, "Quiet boundaries
and wave input"): Lysmer and Kuhlemeyer's dashpots on a rigid block's exposed faces.

A face of area ``A`` and unit outward normal ``n`` (world) whose centroid sits at ``r`` from
the block's centroid resists the velocity of that point, ``u = v + w x r``, with the force
``f = -C u``, ``C = A (a n n^T + b (I - n n^T))``, ``a = rho Cp`` and ``b = rho Cs`` (the
directions not chosen are zero), and the moment ``r x f``. On the block's six velocities
``U = (v, w)`` the face's force and moment are ``-D U`` with the symmetric (positive
semi-definite) 6 x 6 matrix

    D = [[C, -C [r]x], [[r]x C, -[r]x C [r]x]]      ([r]x: the cross-product matrix of r)

summed over the block's faces (:func:`block_dashpots`).

Centred, not explicit. A rigid boundary block is usually a slab under its quiet face, so
``c dt / m = Cp dt / h`` (its thickness ``h``) at a step set by its joints' stiffness is of
order one (a 1 m slab of rock, Cp 5 km/s, dt 1e-4 s: 0.5): an explicit dashpot (at the
velocities of t - dt/2) would be unstable from 2 on and inaccurate well before. So the
dashpot acts at the step's mean velocity, as on the zoned blocks' gridpoints:
:func:`centred_dashpots` solves the block's momentum balance of the step,

    M ((1 + a') U+ - (1 - a') U-) = dt F - dt D (U- + U+) / 2,   a' = alpha dt / 2,

(``M = diag(m, m, m, I)`` inertial, ``I`` the world inertia at the pose at t, ``alpha`` the
viscous or Rayleigh mass-proportional constant, 0 for other modes; the rotational row is in
the angular momentum the integrator keeps), for ``U+`` (a 6 x 6 system per quiet block) and
hands the integrator the force and moment ``-D (U- + U+) / 2`` as boundary loads: it then
makes ``U+`` to round-off (translation; the rotation to the change of the inertia over half
a step, O(|w| dt)). Stable for a dashpot of any strength, and the timestep is not changed.
Local and combined damping scale their force with the unbalanced force, the dashpot's
included, which the solve does not anticipate: stable while ``alpha`` times the largest
``dt lambda(M^-1 D)`` stays below one (:func:`dashpot_rate` gives ``lambda``;
pdem.rigid_faces stops a step beyond it).

What the dashpots absorb, ``-(F_q . v_mean + M_q . w_mean) dt`` with the velocities the
integrator made (:func:`absorbed`), is booked exactly: moved from the applied work (where
the integrator books every boundary load) to the ``quiet_absorbed`` column.

Wave input: the traction ``2 (a (v.n) n + b (v - (v.n) n))`` of a history's particle
velocity ``v`` on each face (:func:`wave_loads`), a boundary load like a stress.
"""

from __future__ import annotations

import math

import numpy as np


def impedances(density: float, young: float, poisson: float) -> tuple[float, float]:
    """``(rho Cp, rho Cs)`` of an elastic material: ``sqrt(rho (K + 4G/3))``,
    ``sqrt(rho G)`` with ``K = E / (3 (1 - 2 nu))``, ``G = E / (2 (1 + nu))``."""
    bulk = young / (3.0 * (1.0 - 2.0 * poisson))
    shear = young / (2.0 * (1.0 + poisson))
    return math.sqrt(density * (bulk + 4.0 * shear / 3.0)), math.sqrt(density * shear)


def _cross_matrices(r: np.ndarray) -> np.ndarray:
    """``[r]x`` (k, 3, 3) of vectors ``r`` (k, 3): ``[r]x u = r x u``."""
    z = np.zeros(len(r))
    return np.stack([np.stack([z, -r[:, 2], r[:, 1]], -1),
                     np.stack([r[:, 2], z, -r[:, 0]], -1),
                     np.stack([-r[:, 1], r[:, 0], z], -1)], 1)


def _matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Stacked 3 x 3 products by explicit sums (the same bits however many are stacked)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    for i in range(3):
        for j in range(3):
            out[:, i, j] = a[:, i, 0] * b[:, 0, j] + a[:, i, 1] * b[:, 1, j] \
                + a[:, i, 2] * b[:, 2, j]
    return out


def matvec(d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Stacked products ``d u`` (k, 6) by explicit sums in column order."""
    out = d[:, :, 0] * u[:, None, 0]
    for j in range(1, d.shape[2]):
        out = out + d[:, :, j] * u[:, None, j]
    return out


def face_dashpots(area, coef, n, r) -> np.ndarray:
    """The faces' 6 x 6 matrices ``D`` (k, 6, 6) (module docstring): ``area`` (k,),
    ``coef`` (k, 2) the normal and shear impedances per area (zero where not chosen), unit
    normals ``n`` and centroid arms ``r`` (k, 3) in one frame."""
    a = area * coef[:, 0]
    b = area * coef[:, 1]
    c = np.empty((len(area), 3, 3))
    for i in range(3):
        for j in range(3):
            c[:, i, j] = (a - b) * n[:, i] * n[:, j] + (b if i == j else 0.0)
    x = _cross_matrices(r)
    cx = _matmul(c, x)
    d = np.empty((len(area), 6, 6))
    d[:, :3, :3] = c
    d[:, :3, 3:] = -cx
    d[:, 3:, :3] = _matmul(x, c)
    d[:, 3:, 3:] = -_matmul(x, cx)
    return d


def block_dashpots(index, k: int, area, coef, n, r) -> np.ndarray:
    """The blocks' ``D`` (k, 6, 6): the faces' (:func:`face_dashpots`) summed onto block
    ``index`` of each face, in the faces' order (the same bits on any rank count)."""
    out = np.zeros((k, 6, 6))
    np.add.at(out, index, face_dashpots(area, coef, n, r))
    return out


def dashpot_rate(d_body: np.ndarray, mass: float, inertia) -> float:
    """The largest ``lambda`` of ``M^-1 D`` (1/s) of a block (body frame: its principal
    moments ``inertia``, its faces' ``D`` summed in the body frame): what ``dt lambda`` of
    its momentum one step's dashpot takes at most."""
    s = 1.0 / np.sqrt(np.array([mass, mass, mass, *inertia], float))
    return float(np.linalg.eigvalsh(d_body * s[:, None] * s[None, :]).max())


def centred_dashpots(d, mass, inertia_world, u0, l0, force, moment, dt: float, a: float,
                     held) -> np.ndarray:
    """The dashpots' force and moment (k, 6) that make the integrator's step centred
    (module docstring): ``d`` (k, 6, 6) the blocks' matrices, ``mass`` (k,) inertial,
    ``inertia_world`` (k, 3, 3) inertial, ``u0`` (k, 6) the velocities and ``l0`` (k, 3) the
    angular momenta at t - dt/2, ``force``/``moment`` (k, 3) every other load at t (gravity
    in), ``a = alpha dt / 2`` of the viscous forms (0 otherwise), ``held`` (k, 3) the
    prescribed translation components (they keep their velocity)."""
    k = len(mass)
    m = np.zeros((k, 6, 6))
    for i in range(3):
        m[:, i, i] = mass
    m[:, 3:, 3:] = inertia_world
    du = matvec(d, u0)
    lhs = (1.0 + a) * m + 0.5 * dt * d
    rhs = np.empty((k, 6))
    rhs[:, :3] = (1.0 - a) * mass[:, None] * u0[:, :3] + dt * force - 0.5 * dt * du[:, :3]
    rhs[:, 3:] = (1.0 - a) * l0 + dt * moment - 0.5 * dt * du[:, 3:]
    for i in range(3):  # a prescribed component: U+ = U-
        on = held[:, i]
        lhs[on, i, :] = 0.0
        lhs[on, i, i] = 1.0
        rhs[on, i] = u0[on, i]
    u1 = np.linalg.solve(lhs, rhs[:, :, None])[:, :, 0]
    return -0.5 * matvec(d, u0 + u1)


def absorbed(load: np.ndarray, u0: np.ndarray, u1: np.ndarray, free: np.ndarray,
             dt: float) -> np.ndarray:
    """What the dashpots' ``load`` (k, 6) took out over the step (k,), with the integrator's
    mean velocities (``u0``, ``u1`` (k, 6) at t -/+ dt/2): only its free translation
    components (``free`` (k, 3), 1.0 or 0.0) count, as the integrator books them."""
    vb = 0.5 * (u0[:, :3] + u1[:, :3]) * free
    wb = 0.5 * (u0[:, 3:] + u1[:, 3:])
    return -(load[:, 0] * vb[:, 0] + load[:, 1] * vb[:, 1] + load[:, 2] * vb[:, 2]
             + load[:, 3] * wb[:, 0] + load[:, 4] * wb[:, 1] + load[:, 5] * wb[:, 2]) * dt


def wave_loads(area, coef, n, v) -> np.ndarray:
    """The forces (k, 3) a wave of particle velocity ``v`` (k, 3) puts in through faces
    ``area`` (k,), ``coef`` (k, 2) (rho Cp, rho Cs), unit normals ``n`` (k, 3): ``2 A (rho
    Cp (v.n) n + rho Cs (v - (v.n) n))``."""
    vn = (v[:, 0] * n[:, 0] + v[:, 1] * n[:, 1] + v[:, 2] * n[:, 2])[:, None]
    return 2.0 * area[:, None] * (coef[:, :1] * vn * n + coef[:, 1:] * (v - vn * n))
