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


@kernel
def nmd_strain_into(tets, vol, rate, nodal, ev_bar):
    """Replace every zone's volumetric strain rate ``ev`` by its nodal average (eqs. 68-71),
    in place: per zone, the mean over its 4 nodes of the volume-weighted nodal mean of
    ``ev``. ``nodal`` (n_nodes, >= 2) and ``ev_bar`` (n_zones,): scratch the caller owns
    (the grid step's: a small grid's step allocated its own, ~1,000 allocations a step in a
    rock mass of zoned blocks)."""
    for z in range(tets.shape[0]):
        ev_bar[z] = (rate[z, 0] + rate[z, 1] + rate[z, 2]) / 3.0
    volume_average(tets, vol, ev_bar, nodal, ev_bar)
    for z in range(tets.shape[0]):
        d = ev_bar[z] - (rate[z, 0] + rate[z, 1] + rate[z, 2]) / 3.0
        rate[z, 0] += d
        rate[z, 1] += d
        rate[z, 2] += d


@kernel
def nmd_stress_into(tets, vol, sigma_p, stress, nodal, bar):
    """Substitute the nodal average of ``sigma_p`` (as :func:`nmd_strain_into` averages)
    for each zone's own (eq. 76), in place; ``nodal``, ``bar``: the caller's scratch."""
    volume_average(tets, vol, sigma_p, nodal, bar)
    for z in range(tets.shape[0]):
        d = sigma_p[z] - bar[z]
        stress[z, 0] += d
        stress[z, 1] += d
        stress[z, 2] += d


@inline_kernel
def volume_average(tets, vol, value, nodal, out):
    """Per zone, the mean over its 4 nodes of the volume-weighted nodal mean of the zones'
    ``value`` (eqs. 69-71), into ``out`` (``value`` itself may be ``out``: it is read whole
    before ``out`` is written); ``nodal`` (n_nodes, >= 2): scratch."""
    for n in range(nodal.shape[0]):
        nodal[n, 0] = 0.0
        nodal[n, 1] = 0.0
    for z in range(tets.shape[0]):
        for a in range(4):
            nodal[tets[z, a], 0] += value[z] * vol[z]
            nodal[tets[z, a], 1] += vol[z]
    for z in range(tets.shape[0]):
        acc = 0.0
        for a in range(4):
            n = tets[z, a]
            acc += nodal[n, 0] / nodal[n, 1]
        out[z] = 0.25 * acc


@kernel
def nmd_strain(tets, vol, rate, n_nodes):
    """:func:`nmd_strain_into` with scratch of its own."""
    nmd_strain_into(tets, vol, rate, np.empty((n_nodes, 2)), np.empty(tets.shape[0]))


@kernel
def nmd_stress(tets, vol, sigma_p, stress, n_nodes):
    """:func:`nmd_stress_into` with scratch of its own."""
    nmd_stress_into(tets, vol, sigma_p, stress, np.empty((n_nodes, 2)),
                    np.empty(tets.shape[0]))
