"""Critical timestep (eqs. 84-88) and mass scaling for static solves (eq. 89).

Block stiffness
---------------
``stiffnesses[i]`` is the contact stiffness acting on block i: the sum over its sub-contacts
of ``max(kn, ks) * area`` (3DEC's joint term of eq. 85 takes the larger of the normal and
shear stiffness times the area).  :func:`block_stiffness` accumulates it from per-sub-contact
values.

Translational bound (eq. 87, as 3DEC states it)
    ``dt_b = frac * 2 * sqrt(M_min / K_max)`` with ``M_min`` the smallest (inertial) block
    mass and ``K_max`` the largest block stiffness, each over the free blocks.  This is more
    conservative than ``min_i sqrt(m_i / K_i)``; ``frac`` (typically 0.1) covers a block being
    squeezed by several neighbours.

Rotational bound (pdem addition, when ``inertias`` and ``radii`` are given)
    The rotational stiffness of block i is at most ``K_i r_i^2`` (all of its contact stiffness
    at its bounding radius), so ``dt_r = frac * 2 * min_i sqrt(I_min,i / (K_i r_i^2))``, with
    ``I_min,i`` the block's smallest principal moment.  For a cube ``I/r^2 = 2m/9``, so this
    bound is about half the per-block translational one -- it matters for slender blocks and
    is cheap insurance against rotational instability in the scalar-inertia-free integrator.

    ``dt = min(dt_b, dt_r)`` (eq. 88 without the deformable-zone term).  Returns ``inf`` if no
    free block has contact stiffness.
"""

from __future__ import annotations

import numpy as np


def block_stiffness(n: int, ia, ib, k_area) -> np.ndarray:
    """Sum per-sub-contact stiffness ``k_area`` (= max(kn, ks) * area) onto both blocks.

    ``ia``, ``ib`` are the block rows of each entry (same length as ``k_area``); a negative
    row is ignored.  Deterministic (np.bincount sums in input order).
    """
    ia = np.asarray(ia, dtype=np.int64)
    ib = np.asarray(ib, dtype=np.int64)
    k = np.asarray(k_area, dtype=np.float64)
    out = np.zeros(n)
    for rows in (ia, ib):
        ok = rows >= 0
        out += np.bincount(rows[ok], weights=k[ok], minlength=n)
    return out


def _free(n: int, fixed) -> np.ndarray:
    if fixed is None:
        return np.ones(n, dtype=bool)
    return ~np.asarray(fixed, dtype=bool)


def auto_timestep(
    masses,
    stiffnesses,
    frac: float = 0.1,
    inertias=None,
    radii=None,
    fixed=None,
    mass_scale=None,
) -> float:
    """Critical timestep per eq. (87) plus the rotational bound (module docstring).

    masses (n,), stiffnesses (n,) block contact stiffness sums, inertias (n, 3) principal
    moments, radii (n,) bounding radii, fixed (n,) flags of blocks to ignore, mass_scale (n,)
    inertial scale factors (multiply masses and inertias).
    """
    return timestep_from_extremes(frac, timestep_extremes(masses, stiffnesses, inertias, radii,
                                                          fixed, mass_scale))


def timestep_extremes(masses, stiffnesses, inertias=None, radii=None, fixed=None,
                      mass_scale=None) -> np.ndarray:
    """What :func:`auto_timestep` takes of the blocks, as maxima: ``(K_max, -M_min,
    -min I_min / (K r^2))`` over the free blocks (-inf where there is none). Maxima are exact
    in any order, so the blocks may be split over ranks (the element-wise maximum of the
    ranks' arrays is the whole's)."""
    m = np.asarray(masses, dtype=np.float64)
    k = np.asarray(stiffnesses, dtype=np.float64)
    n = len(m)
    ms = np.ones(n) if mass_scale is None else np.asarray(mass_scale, dtype=np.float64)
    free = _free(n, fixed)
    out = np.array([k[free].max(initial=-np.inf), -(m * ms)[free].min(initial=np.inf), -np.inf])
    if inertias is not None and radii is not None:
        i_min = np.asarray(inertias, dtype=np.float64).min(axis=1, initial=np.inf) * ms
        r = np.asarray(radii, dtype=np.float64)
        kr = k * r * r
        sel = free & (kr > 0.0)
        out[2] = -(i_min[sel] / kr[sel]).min(initial=np.inf)
    return out


def timestep_from_extremes(frac: float, extremes) -> float:
    """:func:`auto_timestep` from :func:`timestep_extremes` (of every block)."""
    k_max, m_min, rot_min = float(extremes[0]), -float(extremes[1]), -float(extremes[2])
    if not k_max > 0.0:  # no free block, or none with stiffness
        return np.inf
    dt = frac * 2.0 * np.sqrt(m_min / k_max)
    if rot_min < np.inf:
        dt = min(dt, frac * 2.0 * float(np.sqrt(rot_min)))
    return float(dt)


def mass_scale_factors(
    masses,
    stiffnesses,
    dt_target: float,
    frac: float = 0.1,
    inertias=None,
    radii=None,
    uniform: bool = False,
) -> np.ndarray:
    """Inertial mass-scale factors so every block is stable at ``dt_target`` (eq. 89).

    Per block, the critical step ``frac * 2 * sqrt(s m / K)`` reaches ``dt_target`` for
    ``s_t = K dt^2 / (4 frac^2 m)``; with inertias/radii the rotational bound likewise needs
    ``s_r = K r^2 dt^2 / (4 frac^2 I_min)`` (mass and inertia share one factor).

    ``uniform=False`` (default): ``s = max(1, s_t, s_r)`` -- only blocks too light for
    ``dt_target`` are made heavier, so the physics of the rest is untouched.
    ``uniform=True``: ``s = max(s_t, s_r)`` even when < 1, i.e. 3DEC's static-solve scaling
    where every block gets the same critical step (and so the same natural frequency, which is
    what makes damped relaxation converge fastest).  Blocks without stiffness get 1.

    The per-block estimate uses the block's own K and mass; pass a frac that allows for
    neighbours (0.1 as in eq. 87 is safe).  Apply with ``BlockStore.mscale``; gravity keeps the
    true mass (see :mod:`pdem.dynamics.motion`).
    """
    m = np.asarray(masses, dtype=np.float64)
    k = np.asarray(stiffnesses, dtype=np.float64)
    c = dt_target * dt_target / (4.0 * frac * frac)
    s = k * c / m
    if inertias is not None and radii is not None:
        i_min = np.asarray(inertias, dtype=np.float64).min(axis=1)
        r = np.asarray(radii, dtype=np.float64)
        s = np.maximum(s, k * r * r * c / i_min)
    if uniform:
        return np.where(k > 0.0, s, 1.0)
    return np.maximum(s, 1.0)


def critical_steps(masses, stiffnesses, frac: float = 0.1, inertias=None, radii=None,
                   mass_scale=None) -> np.ndarray:
    """Each block's own critical step ``frac * 2 * min(sqrt(s m / K), sqrt(s I_min / (K r^2)))``
    (the per-block form of eq. 87 and of the rotational bound; ``inf`` where K = 0).

    This is the criterion partial mass scaling (:func:`mass_scale_factors`) makes every block
    meet: a contact of stiffness k between blocks i and j oscillates at
    ``w^2 = k (1/m_i + 1/m_j) <= K_i/m_i + K_j/m_j``, so when both blocks meet it,
    ``w dt <= sqrt(8) frac`` (0.28 at frac = 0.1), far below the central-difference limit 2.
    """
    m = np.asarray(masses, dtype=np.float64)
    k = np.asarray(stiffnesses, dtype=np.float64)
    ms = np.ones(len(m)) if mass_scale is None else np.asarray(mass_scale, dtype=np.float64)
    out = np.full(len(m), np.inf)
    sel = k > 0.0
    out[sel] = np.sqrt(m[sel] * ms[sel] / k[sel])
    return frac * 2.0 * _rotational(out, k, ms, inertias, radii)


def _rotational(step, k, ms, inertias, radii) -> np.ndarray:
    """``step`` (per block, in place) lowered to each block's rotational bound
    ``sqrt(I_min / (K r^2))`` where it has one (module docstring)."""
    if inertias is None or radii is None:
        return step
    i_min = np.asarray(inertias, dtype=np.float64).min(axis=1) * ms
    r = np.asarray(radii, dtype=np.float64)
    kr = k * r * r
    rot = kr > 0.0
    step[rot] = np.minimum(step[rot], np.sqrt(i_min[rot] / kr[rot]))
    return step


def limiting_block(masses, stiffnesses, frac: float = 0.1, inertias=None, radii=None,
                   fixed=None, mass_scale=None, k_max: float | None = None):
    """The free block that sets :func:`auto_timestep`'s step (-1 if none): the lightest block
    when eq. 87 (its mass against the stiffest block's K) governs, else the block with the
    smallest rotational bound. ``k_max``: the stiffest free block's K of every block (when
    these are some of them); then returns ``(its step measure, row)`` of the first such row
    here, or None, for the caller to compare over all."""
    m = np.asarray(masses, dtype=np.float64)
    k = np.asarray(stiffnesses, dtype=np.float64)
    n = len(m)
    ms = np.ones(n) if mass_scale is None else np.asarray(mass_scale, dtype=np.float64)
    free = np.nonzero(_free(n, fixed))[0]
    part = k_max is not None
    if not part:
        k_max = k[free].max() if len(free) else 0.0
    if not len(free) or not k_max > 0.0:
        return None if part else -1
    step = _rotational(np.sqrt(m * ms / k_max), k, ms, inertias, radii)
    best = int(np.argmin(step[free]))
    return (float(step[free][best]), int(free[best])) if part else int(free[best])
