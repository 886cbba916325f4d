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
the best so far are mostly rejected after two or four dot products (any vertex pair gives an
upper bound of the gap for any normal: the best plane's support vertices and the last
rejection's witness are tried first, on the candidate before its normalisation, see
:func:`_consider`). The planes are the same bits as with plain support scans. Pass *unique*
edge directions (one per set of parallel edges; a box has three) to keep ``eA eB`` small.
"""

from __future__ import annotations

import math

import numpy as np

from pdem.contact.common_plane import finish_plane, initial_plane, support_gap
from pdem.jit import inline_kernel, kernel

_INF = np.inf
_MAX_TIES = 4
_MAX_ROUNDS = 32


@inline_kernel
def _gap_above(va, vb, m0, m1, m2, ia, ib, wa, wb, best):
    """:func:`support_gap` with a second rejection witness, the pair ``(wa, wb)``.

    Returns ``(ok, max_A m.V, min_B m.V, argmax_A, argmin_B)``; on failure the last two are a
    witness pair (a vertex pair whose separation along ``m`` is ``<= best``). ``ok`` and, when
    ``ok``, every other value are the same bits as :func:`support_gap`'s, whatever the hints:
    any vertex pair bounds the computed gap from above (rounding is monotone, and each dot
    product is the same expression as in the full scan), so a pair that proves the gap
    ``<= best`` decides ``ok``, and a gap above ``best`` is only returned after full scans,
    which keep the lowest index of each extreme.
    """
    ubb = vb[ib, 0] * m0 + vb[ib, 1] * m1 + vb[ib, 2] * m2
    uba = va[ia, 0] * m0 + va[ia, 1] * m1 + va[ia, 2] * m2
    if ubb - uba <= best:
        return False, 0.0, 0.0, ia, ib
    wbb = vb[wb, 0] * m0 + vb[wb, 1] * m1 + vb[wb, 2] * m2
    wba = va[wa, 0] * m0 + va[wa, 1] * m1 + va[wa, 2] * m2
    if wbb - wba <= best:
        return False, 0.0, 0.0, wa, wb
    jb = ib
    if wbb < ubb:  # the lower of the two B values bounds min_B best
        ubb = wbb
        jb = wb
    maxa = -_INF
    ka = 0
    for i in range(va.shape[0]):
        d = va[i, 0] * m0 + va[i, 1] * m1 + va[i, 2] * m2
        if d > maxa:
            maxa = d
            ka = i
    if ubb - maxa <= best:
        return False, 0.0, 0.0, ka, jb
    minb = _INF
    kb = 0
    for j in range(vb.shape[0]):
        d = vb[j, 0] * m0 + vb[j, 1] * m1 + vb[j, 2] * m2
        if d < minb:
            minb = d
            kb = j
    if minb - maxa <= best:
        return False, 0.0, 0.0, ka, kb
    return True, maxa, minb, ka, kb


@inline_kernel
def _consider(va, vb, m0, m1, m2, st, margin):
    """Evaluate candidate ``m`` (any length, normalised here) against the state ``st`` =
    (n0, n1, n2, best gap, max_A, min_B, ia, ib, wa, wb); returns (improved, new state).

    ``(ia, ib)`` are the best normal's support vertices, ``(wa, wb)`` the witness of the last
    rejection: consecutive candidates are alike (the same vertex pair projected off each edge
    direction), so it often rejects the next one after two dot products. Whether a candidate
    improves, and the new best, do not depend on these hints (:func:`_gap_above`).

    Pre-test before the normalisation (three divisions in the latency chain of every
    candidate; most are rejected by one of the two pairs): a pair with
    ``m.V_b - m.V_a <= |m| (best - margin)`` for the unnormalised ``m`` proves that the full
    test on the normalised ``m`` rejects the candidate. The two computations differ by
    rounding only, bounded by a few tens of ``2^-53 size`` (``size`` the largest
    ``|x| + |y| + |z|`` of a vertex; ``|best| <= 2 size``), and ``margin = 1e-12 size`` exceeds
    that by more than two orders of magnitude; whatever the pre-test lets through takes the
    full test. So the result is the same bits as without it (tested against the plain
    algorithm in tests/unit/test_fcp_bits.py).
    """
    s = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    if not (s > 0.0):
        return False, st
    if s > 1e-100:  # (far from underflow, where the rounding bound holds)
        thr = s * (st[3] - margin)
        ia, ib, wa, wb = st[6], st[7], st[8], st[9]
        g = (vb[ib, 0] * m0 + vb[ib, 1] * m1 + vb[ib, 2] * m2) - \
            (va[ia, 0] * m0 + va[ia, 1] * m1 + va[ia, 2] * m2)
        if g <= thr:
            return False, st
        g = (vb[wb, 0] * m0 + vb[wb, 1] * m1 + vb[wb, 2] * m2) - \
            (va[wa, 0] * m0 + va[wa, 1] * m1 + va[wa, 2] * m2)
        if g <= thr:
            return False, st
    m0 /= s
    m1 /= s
    m2 /= s
    ok, mxa, mnb, ka, kb = _gap_above(va, vb, m0, m1, m2, st[6], st[7], st[8], st[9], st[3])
    if ok:
        return True, (m0, m1, m2, mnb - mxa, mxa, mnb, ka, kb, st[8], st[9])
    return False, (st[0], st[1], st[2], st[3], st[4], st[5], st[6], st[7], ka, kb)


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
    n0, n1, n2, c = initial_plane(ca, cb, n_in, p_in, warm)
    ok, mxa, mnb, ka, kb = support_gap(va, vb, n0, n1, n2, 0, 0, -_INF)
    # (n0, n1, n2, best gap, max_A, min_B, ia, ib, wa, wb): see _consider
    state = (n0, n1, n2, mnb - mxa, mxa, mnb, ka, kb, ka, kb)
    iters = 1
    early = state[3] > ctol
    size = 0.0  # the largest |x| + |y| + |z| of a vertex: the rounding scale (see _consider)
    for i in range(va.shape[0]):
        size = max(size, abs(va[i, 0]) + abs(va[i, 1]) + abs(va[i, 2]))
    for j in range(vb.shape[0]):
        size = max(size, abs(vb[j, 0]) + abs(vb[j, 1]) + abs(vb[j, 2]))
    margin = 1e-12 * size

    # face normals of A (B beyond A's face) and of B (reversed)
    if not early:
        for f in range(fa_normals.shape[0]):
            _, state = _consider(va, vb, fa_normals[f, 0], fa_normals[f, 1], fa_normals[f, 2],
                                 state, margin)
            iters += 1
            if state[3] > ctol:
                early = True
                break
    if not early:
        for f in range(fb_normals.shape[0]):
            _, state = _consider(va, vb, -fb_normals[f, 0], -fb_normals[f, 1], -fb_normals[f, 2],
                                 state, margin)
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
                _, state = _consider(va, vb, m0, m1, m2, state, margin)
                _, state = _consider(va, vb, -m0, -m1, -m2, state, margin)
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
                    ok, state = _consider(va, vb, d0, d1, d2, state, margin)  # type a
                    if ok:
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
                        ok, state = _consider(va, vb, d0 - t * e0, d1 - t * e1, d2 - t * e2,
                                              state, margin)
                        if ok:
                            improved = True
                        iters += 1
                    if state[3] > ctol:
                        break
                if state[3] > ctol:
                    break
            if not improved or state[3] > ctol:
                break

    n, p, gap, da, db = finish_plane(
        va, vb, state[0], state[1], state[2], c, state[4], state[5], state[6], state[7]
    )
    return n, p, gap, da, db, iters
