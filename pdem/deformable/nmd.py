"""Nodal mixed discretization (NMD, reference eqs. 68-76) over a tetrahedral grid.

Constant-strain tets lock volumetrically: a mesh of n gridpoints has ~5-6 n tets, each one
volumetric constraint when the material is (nearly) incompressible or flows plastically at
constant volume, against 3 n degrees of freedom. NMD keeps each zone's deviatoric strain rate
but replaces its volumetric part by the average of nodal values, each node's value being the
volume-weighted mean of its zones (eqs. 69-71); the plastic volumetric stress correction
``sigma_p = K de_v^p`` returned by the constitutive model is averaged the same way
(eqs. 74-76). For a uniform field both averages return the zone's own value (the patch test
still passes); the kernels are pure over the flat arrays of :mod:`.zones`.
"""

from __future__ import annotations

import numpy as np

from ..jit import inline_kernel, kernel


@inline_kernel
def _clear_sums(nodal, a, e):
    """Zero the gridpoint sums of :func:`_nodal_sums` of the gridpoints ``a <= n < e``."""
    for n in range(np.uint64(a), np.uint64(e)):  # (unsigned: pdem.deformable.zones)
        nodal[n, 0] = 0.0
        nodal[n, 1] = 0.0


@inline_kernel
def _nodal_sums(tets, z, off, value, v, nodal):
    """Add zone ``z``'s ``value * V`` and ``V`` to its gridpoints' sums (``nodal[:, 0]``,
    ``nodal[:, 1]``; gridpoints ``tets[z] + off``)."""
    for a in range(4):
        n = np.uint64(tets[z, a] + off)
        nodal[n, 0] += value * v
        nodal[n, 1] += v


@inline_kernel
def _zone_mean(tets, z, off, nodal):
    """The mean over zone ``z``'s 4 gridpoints of their volume-weighted means
    ``nodal[:, 0] / nodal[:, 1]`` (eqs. 69-71)."""
    acc = 0.0
    for a in range(4):
        n = np.uint64(tets[z, a] + off)
        acc += nodal[n, 0] / nodal[n, 1]
    return 0.25 * acc


@kernel
def nmd_strain_in(tets, vol, rate, nodal, za, ze, a, e):
    """Replace the volumetric strain rate ``ev`` of every zone ``za <= z < ze`` (gridpoints
    ``tets + a``, which are ``a <= n < e``) by its nodal average (eqs. 68-71), in place: per
    zone, the mean over its 4 gridpoints of the volume-weighted nodal mean of ``ev``.
    ``nodal`` (>= e, >= 2): scratch the caller owns (the grid step's: a small grid's step
    allocating its own made ~1,000 allocations a step in a rock mass of zoned blocks); each
    zone's ``ev`` is made where it is used, read whole before any rate is changed."""
    _clear_sums(nodal, a, e)
    for z in range(np.uint64(za), np.uint64(ze)):
        _nodal_sums(tets, z, a, (rate[z, 0] + rate[z, 1] + rate[z, 2]) / 3.0, vol[z], nodal)
    for z in range(np.uint64(za), np.uint64(ze)):
        d = _zone_mean(tets, z, a, nodal) - (rate[z, 0] + rate[z, 1] + rate[z, 2]) / 3.0
        rate[z, 0] += d
        rate[z, 1] += d
        rate[z, 2] += d


@kernel
def nmd_stress_in(tets, vol, sigma_p, stress, nodal, za, ze, a, e):
    """Substitute the nodal average of ``sigma_p`` (as :func:`nmd_strain_in` averages) for
    each zone's own (eq. 76), in place, for the zones ``za <= z < ze`` (gridpoints as
    :func:`nmd_strain_in`'s); ``nodal``: the caller's scratch."""
    _clear_sums(nodal, a, e)
    for z in range(np.uint64(za), np.uint64(ze)):
        _nodal_sums(tets, z, a, sigma_p[z], vol[z], nodal)
    for z in range(np.uint64(za), np.uint64(ze)):
        d = sigma_p[z] - _zone_mean(tets, z, a, nodal)
        stress[z, 0] += d
        stress[z, 1] += d
        stress[z, 2] += d


@kernel
def nmd_strain(tets, vol, rate, n_nodes):
    """:func:`nmd_strain_in` of a whole grid, with scratch of its own."""
    nmd_strain_in(tets, vol, rate, np.empty((n_nodes, 2)), 0, tets.shape[0], 0, n_nodes)


@kernel
def nmd_stress(tets, vol, sigma_p, stress, n_nodes):
    """:func:`nmd_stress_in` of a whole grid, with scratch of its own."""
    nmd_stress_in(tets, vol, sigma_p, stress, np.empty((n_nodes, 2)), 0, tets.shape[0], 0,
                  n_nodes)
