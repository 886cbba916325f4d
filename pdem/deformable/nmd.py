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

from ..jit import kernel


@kernel
def _zone_average_of_nodes(tets, vol, zone_value, n_nodes):
    """Per zone: the mean over its 4 nodes of the volume-weighted nodal mean of ``zone_value``."""
    num = np.zeros(n_nodes)
    den = np.zeros(n_nodes)
    for z in range(tets.shape[0]):
        for a in range(4):
            num[tets[z, a]] += zone_value[z] * vol[z]
            den[tets[z, a]] += vol[z]
    out = np.empty(tets.shape[0])
    for z in range(tets.shape[0]):
        acc = 0.0
        for a in range(4):
            n = tets[z, a]
            acc += num[n] / den[n]
        out[z] = 0.25 * acc
    return out


@kernel
def nmd_strain(tets, vol, rate, n_nodes):
    """Replace every zone's volumetric strain rate by its nodal average (eqs. 68-71), in place."""
    ev = np.empty(tets.shape[0])
    for z in range(tets.shape[0]):
        ev[z] = (rate[z, 0] + rate[z, 1] + rate[z, 2]) / 3.0
    ev_bar = _zone_average_of_nodes(tets, vol, ev, n_nodes)
    for z in range(tets.shape[0]):
        d = ev_bar[z] - ev[z]
        rate[z, 0] += d
        rate[z, 1] += d
        rate[z, 2] += d


@kernel
def nmd_stress(tets, vol, sigma_p, stress, n_nodes):
    """Substitute the nodal average of ``sigma_p`` for each zone's own (eq. 76), in place."""
    bar = _zone_average_of_nodes(tets, vol, sigma_p, n_nodes)
    for z in range(tets.shape[0]):
        d = sigma_p[z] - bar[z]
        stress[z, 0] += d
        stress[z, 1] += d
        stress[z, 2] += d
