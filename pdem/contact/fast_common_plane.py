"""Fast common plane (FCP) of Nezami et al., as used in explicit 3D-DDA (DDA section 3).

Instead of hill climbing, the common-plane normal is chosen among a finite candidate set:

- the previous normal (warm start) or the centroid-to-centroid direction (cold start);
- the outward face normals of A and the reversed outward face normals of B;
- both signs of the cross products of every edge direction of A with every edge direction of B;
- for separated blocks, iterated from the nearest vertices of the best plane so far
  (FCP types a and d): the direction between the two nearest vertices and its components
  perpendicular to each edge direction of A and of B.

The face normals and edge crosses are the facet normals of the Minkowski difference, so for
touching or overlapping blocks the candidate maximising the gap is the exact optimum
(separating-axis theorem): the common plane minimising the penetration of the most deeply
buried vertex. For separated blocks the optimum is the direction between the closest points;
it is a face normal (vertex/edge/face against face), an edge cross (edge-edge), a type-d
(vertex-edge) or a type-a (vertex-vertex) candidate, found by the iteration above.

Return values follow :mod:`pdem.contact.common_plane` exactly (``n`` from A to B, ``gap``
positive when separated, ``p`` per eqs. (8)/(9)), so the two are interchangeable.

Cost: ``(fA + fB + 2 eA eB) (vA + vB)`` dot products at worst; candidates that cannot beat
the best so far are rejected after two dot products (the best plane's support vertices give
an upper bound of the gap for any normal). Pass *unique* edge directions (one per set of
parallel edges; a box has three) to keep ``eA eB`` small.
"""

from __future__ import annotations

import math

import numpy as np

from pdem.contact.common_plane import finish_plane, initial_plane, support_gap
from pdem.jit import kernel

_INF = np.inf
_MAX_TIES = 4
_MAX_ROUNDS = 32


@kernel
def _consider(va, vb, m0, m1, m2, state):
    """Evaluate unit-normalised candidate ``m``; update ``state`` if it improves the gap.

    ``state`` (8,) float array: n0, n1, n2, best gap, max_A, min_B, ia, ib.
    """
    s = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    if not (s > 0.0):
        return False
    m0 /= s
    m1 /= s
    m2 /= s
    ia = int(state[6])
    ib = int(state[7])
    ok, mxa, mnb, ka, kb = support_gap(va, vb, m0, m1, m2, ia, ib, state[3])
    if ok:
        state[0] = m0
        state[1] = m1
        state[2] = m2
        state[3] = mnb - mxa
        state[4] = mxa
        state[5] = mnb
        state[6] = ka
        state[7] = kb
    return ok


@kernel
def fast_common_plane(va, vb, ca, cb, fa_normals, fb_normals, ea, eb, n_in, p_in, warm, ctol):
    """Common plane by exhaustive candidate normals (FCP).

    Parameters
    ----------
    va, vb : (na, 3), (nb, 3) world vertex coordinates.
    ca, cb : (3,) centroids.
    fa_normals, fb_normals : (fA, 3), (fB, 3) unit outward face normals (world frame).
    ea, eb : (eA, 3), (eB, 3) edge direction vectors (any length, preferably unique).
    n_in, p_in : (3,) previous normal and reference point, used when ``warm``.
    warm : bool.
    ctol : float, stop as soon as a candidate's gap exceeds it.

    Returns ``(n, p, gap, d_a, d_b, iters)`` like ``common_plane``; ``iters`` is the number
    of candidate normals examined.
    """
    state = np.empty(8)
    n0, n1, n2, c = initial_plane(ca, cb, n_in, p_in, warm)
    ok, mxa, mnb, ka, kb = support_gap(va, vb, n0, n1, n2, 0, 0, -_INF)
    state[0] = n0
    state[1] = n1
    state[2] = n2
    state[3] = mnb - mxa
    state[4] = mxa
    state[5] = mnb
    state[6] = ka
    state[7] = kb
    iters = 1
    early = state[3] > ctol

    # face normals of A (B beyond A's face) and of B (reversed)
    if not early:
        for f in range(fa_normals.shape[0]):
            _consider(va, vb, fa_normals[f, 0], fa_normals[f, 1], fa_normals[f, 2], state)
            iters += 1
            if state[3] > ctol:
                early = True
                break
    if not early:
        for f in range(fb_normals.shape[0]):
            _consider(va, vb, -fb_normals[f, 0], -fb_normals[f, 1], -fb_normals[f, 2], state)
            iters += 1
            if state[3] > ctol:
                early = True
                break
    # edge-edge cross products, both signs
    if not early:
        for i in range(ea.shape[0]):
            a0, a1, a2 = ea[i, 0], ea[i, 1], ea[i, 2]
            aa = a0 * a0 + a1 * a1 + a2 * a2
            for j in range(eb.shape[0]):
                b0, b1, b2 = eb[j, 0], eb[j, 1], eb[j, 2]
                m0 = a1 * b2 - a2 * b1
                m1 = a2 * b0 - a0 * b2
                m2 = a0 * b1 - a1 * b0
                mm = m0 * m0 + m1 * m1 + m2 * m2
                if mm <= 1e-24 * aa * (b0 * b0 + b1 * b1 + b2 * b2):
                    continue  # parallel edges: no plane defined
                _consider(va, vb, m0, m1, m2, state)
                _consider(va, vb, -m0, -m1, -m2, state)
                iters += 2
                if state[3] > ctol:
                    early = True
                    break
            if early:
                break

    # separated blocks: FCP types a and d from the nearest vertices, iterated
    if not early and state[3] > 0.0:
        scale = 0.0
        for i in range(va.shape[0]):
            for k in range(3):
                scale = max(scale, abs(va[i, k] - ca[k]))
        for j in range(vb.shape[0]):
            for k in range(3):
                scale = max(scale, abs(vb[j, k] - cb[k]))
        tie = 1e-9 * scale
        tia = np.empty(_MAX_TIES, np.int64)
        tib = np.empty(_MAX_TIES, np.int64)
        for _round in range(_MAX_ROUNDS):
            improved = False
            n0, n1, n2 = state[0], state[1], state[2]
            # nearest vertices of the current best plane (up to _MAX_TIES each)
            nta = 0
            for i in range(va.shape[0]):
                d = va[i, 0] * n0 + va[i, 1] * n1 + va[i, 2] * n2
                if d >= state[4] - tie and nta < _MAX_TIES:
                    tia[nta] = i
                    nta += 1
            ntb = 0
            for j in range(vb.shape[0]):
                d = vb[j, 0] * n0 + vb[j, 1] * n1 + vb[j, 2] * n2
                if d <= state[5] + tie and ntb < _MAX_TIES:
                    tib[ntb] = j
                    ntb += 1
            for ti in range(nta):
                i = tia[ti]
                for tj in range(ntb):
                    j = tib[tj]
                    d0 = vb[j, 0] - va[i, 0]
                    d1 = vb[j, 1] - va[i, 1]
                    d2 = vb[j, 2] - va[i, 2]
                    if _consider(va, vb, d0, d1, d2, state):  # type a
                        improved = True
                    iters += 1
                    for e in range(ea.shape[0] + eb.shape[0]):  # type d
                        if e < ea.shape[0]:
                            e0, e1, e2 = ea[e, 0], ea[e, 1], ea[e, 2]
                        else:
                            r = e - ea.shape[0]
                            e0, e1, e2 = eb[r, 0], eb[r, 1], eb[r, 2]
                        ee = e0 * e0 + e1 * e1 + e2 * e2
                        if ee <= 0.0:
                            continue
                        t = (d0 * e0 + d1 * e1 + d2 * e2) / ee
                        if _consider(va, vb, d0 - t * e0, d1 - t * e1, d2 - t * e2, state):
                            improved = True
                        iters += 1
                    if state[3] > ctol:
                        break
                if state[3] > ctol:
                    break
            if not improved or state[3] > ctol:
                break

    n, p, gap, da, db = finish_plane(
        va, vb, state[0], state[1], state[2], c, state[4], state[5], int(state[6]), int(state[7])
    )
    return n, p, gap, da, db, iters
