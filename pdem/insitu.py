"""In-situ stress (``insitu:``): every joint starts carrying the forces of a given stress field
across its plane, so a confined model starts in equilibrium (3DEC's ``block insitu``).

The stress at a point is ``sigma(z) = stress + gradient (z - reference_z)`` (Voigt order xx,
yy, zz, xy, yz, zx; compression negative, as in 3DEC). A sub-contact with area A on the
common plane of unit normal n (from block A to block B) carries the force A exerts on B,
``-sigma n A``: normal force ``fn = -(n . sigma n) A`` (compression positive, pdem's sign) and
shear force on B ``fs = -(sigma n - (n . sigma n) n) A``. The normal spring's compression is
set to ``fn / (kn A)`` so that the force law's total form gives the same force; the shear
displacement to ``|fs| / (ks A)``. A joint law clips what its strength cannot carry at the
first step. The energy budget starts from these springs (their energy is the start's).

Only face-to-face contacts are joints of the rock mass; edge and vertex contacts (blocks that
touch along an edge where joints meet) start unloaded: a constant stress over each block's
closed surface of faces is then in equilibrium exactly.
"""

from __future__ import annotations

import numpy as np

from .contact.common_plane import FACE_FACE
from .jit import kernel


def stress_tensor(voigt) -> np.ndarray:
    sxx, syy, szz, sxy, syz, szx = (float(v) for v in voigt)
    return np.array([[sxx, sxy, szx], [sxy, syy, syz], [szx, syz, szz]])


@kernel
def _initialise(ia, normal, ctype, sc_start, x, R, pa, area, un, dil, fs, us, kn, ks, joint,
                s0, grad, z0):
    for c in range(ia.shape[0]):
        if ctype[c] != FACE_FACE:
            continue
        a = ia[c]
        n = normal[c]
        j = joint[c]
        for s in range(sc_start[c], sc_start[c + 1]):
            z = x[a, 2]
            for m in range(3):
                z += R[a, 2, m] * pa[s, m]
            sig = s0 + grad * (z - z0)
            t = np.zeros(3)
            for i in range(3):
                for m in range(3):
                    t[i] += sig[i, m] * n[m]
            sn = t[0] * n[0] + t[1] * n[1] + t[2] * n[2]
            A = area[s]
            if A <= 0.0:
                continue
            fn = -sn * A
            if fn > 0.0:
                un[s] = fn / (kn[j] * A) - dil[s]
            shear = 0.0
            for i in range(3):
                fs[s, i] = -(t[i] - sn * n[i]) * A
                shear += fs[s, i] ** 2
            mag = np.sqrt(shear) / (ks[j] * A)
            for i in range(3):
                us[s, i] = fs[s, i] / (ks[j] * A) if shear > 0.0 else 0.0
            if mag == 0.0:
                for i in range(3):
                    us[s, i] = 0.0


def zone_stresses(grids, ins) -> None:
    """Every held grid's zone stresses from the in-situ field at the zone centroids (zone
    stresses are tension positive, as the field)."""
    s0, grad = np.asarray(ins.stress, float), np.asarray(ins.gradient, float)
    for body in grids.bodies:
        z = body.nodes[body.tets, 2].mean(axis=1)
        body.stress[:] = s0[None] + np.outer(z - float(ins.reference_z), grad)


def initialise(state) -> None:
    """Set every contact's sub-contact forces from the scene's in-situ stress (this rank's
    contacts; collective only through nothing: each rank does its own), and the zoned
    blocks' zone stresses (3DEC's ``zone initialize-stresses``): with boundary stresses
    equal to the field on its exposed faces, a zoned rock mass starts in equilibrium."""
    ins = state.scene.insitu
    if state.grids is not None:
        zone_stresses(state.grids, ins)
    c = state.contacts
    b = state.blocks
    if c.n == 0:
        return
    sub = c.sub
    _initialise(c.ia, c.normal, c.ctype, c.sc_start, b.x, b.R, sub["sc_pa"], sub["sc_area"],
                sub["sc_un"], sub["sc_dil"], sub["sc_fs"], sub["sc_us"], state.joints.kn,
                state.joints.ks, c.joint, stress_tensor(ins.stress),
                stress_tensor(ins.gradient), float(ins.reference_z))
    # a joint pressed by the stress is closed by its elastic closure, not found apart: its gap
    # is minus its largest closure (pdem.contact.staleness re-detects contacts found apart as
    # soon as they press, which would throw the closure away)
    pressed = np.diff(c.sc_start) > 0
    if pressed.any():
        closure = np.maximum.reduceat(sub["sc_un"] + sub["sc_dil"], c.sc_start[:-1][pressed])
        c.gap[pressed] = np.minimum(c.gap[pressed], -np.maximum(closure, 0.0))
