"""Cundall's common plane (3DEC formulation, eqs. (5)-(10)) and contact typing (Table 1).

Conventions shared by :func:`common_plane` and
:func:`pdem.contact.fast_common_plane.fast_common_plane`:

- ``n`` is the unit normal of the common plane, pointing from block A to block B.
- ``gap = min_B n.V - max_A n.V``: positive for a gap, negative for an overlap (then ``-gap``
  is the depth of the most deeply buried vertex measured along ``n``).
- ``p`` is the reference point of the plane. Separated blocks (``gap > 0``): midway between
  the nearest vertices, eq. (9). Touching/overlapping blocks: the starting point (``p_in``
  on a warm start, the centroid midpoint (5) on a cold start) translated along ``n`` by
  eq. (8), so the plane lies midway between the two blocks' extreme vertices.
- ``d_a = max_A n.(V - p)`` and ``d_b = min_B n.(V - p)`` relative to the returned ``p``;
  after translation ``d_a = -gap/2`` and ``d_b = gap/2`` up to rounding.

The plane is chosen to maximise the gap (minimise the overlap of the most deeply buried
vertex). The objective does not depend on ``p``, only on ``n``.

pdem refinement beyond 3DEC ("feature snap"): the hill climb stops within about ``k_min``
(0.01 degree) of the optimum, so a block resting on a face would see a spurious normal tilt.
After the climb the vertices of each block within a narrow band of the plane are examined;
if three or more of them are coplanar (a face), the normal is replaced by that face's exact
normal; if each block has exactly two (an edge), by the normalised cross product of the two
edges; a single vertex against an edge or vertex gives the exact closest-feature direction.
A snapped normal is accepted only if its gap is not smaller than the hill climb's (minus
``snap_tol``), so the snap can only improve the objective. ``snap_tol <= 0`` disables it.

pdem refinement beyond 3DEC ("ridge steps", ``ridge=True``): the objective is a minimum of
linear functions of ``n``, and the four-direction hill climb stalls on its narrow ridges, in
measurements up to 20-30 degrees from the optimum for separated random polyhedra (26 of 60
random pairs wrong by more than k_min without this). A level ``k`` is therefore left only after
both axis sets (0 and 45 degrees) failed AND (a) the FCP-style candidate normals built from the
vertices within ``2 k R`` of the supports (vertex-vertex direction, vertex-edge perpendicular,
edge-edge cross, face normal) and (b) a line search along the ridges through ``n`` (tangent
``n x e`` for each near-active edge ``e``) found no improvement. Every accepted move strictly
increases the gap. For separated blocks (unimodal objective) this reaches the optimum; for
overlapping blocks the objective is multimodal and the search may end at a local optimum
(the fast common plane is global).
"""

from __future__ import annotations

import math

import numpy as np

from pdem.jit import kernel

# Contact type codes (Table 1). Symmetric pairs (vertex-face / face-vertex) share a code.
NONE = 0
VERTEX_VERTEX = 1
VERTEX_EDGE = 2
VERTEX_FACE = 3
EDGE_EDGE = 4
EDGE_FACE = 5
FACE_FACE = 6

CONTACT_TYPE_NAMES = {
    NONE: "none",
    VERTEX_VERTEX: "vertex-vertex",
    VERTEX_EDGE: "vertex-edge",
    VERTEX_FACE: "vertex-face",
    EDGE_EDGE: "edge-edge",
    EDGE_FACE: "edge-face",
    FACE_FACE: "face-face",
}

K_MAX_DEFAULT = math.tan(math.radians(5.0))
K_MIN_DEFAULT = math.tan(math.radians(0.01))

_INF = np.inf


@kernel
def support_gap(va, vb, n0, n1, n2, ia, ib, best):
    """Support values of A and B along ``n`` with pruning.

    Returns ``(ok, max_A n.V, min_B n.V, argmax_A, argmin_B)``. ``ok`` is False (and the other
    values meaningless) as soon as the gap ``min_B - max_A`` is proven ``<= best``; any vertex
    pair bounds the gap from above, so the pair ``(ia, ib)`` (the support vertices of the best
    normal so far) is tested first. Ties go to the lowest vertex index. On failure ``argmax_A,
    argmin_B`` hold a witness: a vertex pair whose separation along ``n`` is ``<= best``.
    """
    ubb = vb[ib, 0] * n0 + vb[ib, 1] * n1 + vb[ib, 2] * n2
    uba = va[ia, 0] * n0 + va[ia, 1] * n1 + va[ia, 2] * n2
    if ubb - uba <= best:
        return False, 0.0, 0.0, ia, ib
    maxa = -_INF
    ka = 0
    for i in range(va.shape[0]):
        d = va[i, 0] * n0 + va[i, 1] * n1 + va[i, 2] * n2
        if d > maxa:
            maxa = d
            ka = i
            if ubb - maxa <= best:
                return False, 0.0, 0.0, ka, ib
    minb = _INF
    kb = 0
    for j in range(vb.shape[0]):
        d = vb[j, 0] * n0 + vb[j, 1] * n1 + vb[j, 2] * n2
        if d < minb:
            minb = d
            kb = j
            if minb - maxa <= best:
                return False, 0.0, 0.0, ka, kb
    return True, maxa, minb, ka, kb


@kernel
def _perp_axes(n0, n1, n2):
    """Two unit vectors p, q with (p, q, n) right-handed and orthonormal (deterministic)."""
    a0 = abs(n0)
    a1 = abs(n1)
    a2 = abs(n2)
    # helper axis: the coordinate axis least aligned with n
    if a0 <= a1 and a0 <= a2:
        e0, e1, e2 = 1.0, 0.0, 0.0
    elif a1 <= a2:
        e0, e1, e2 = 0.0, 1.0, 0.0
    else:
        e0, e1, e2 = 0.0, 0.0, 1.0
    d = e0 * n0 + e1 * n1 + e2 * n2
    p0 = e0 - d * n0
    p1 = e1 - d * n1
    p2 = e2 - d * n2
    s = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    p0 /= s
    p1 /= s
    p2 /= s
    q0 = n1 * p2 - n2 * p1
    q1 = n2 * p0 - n0 * p2
    q2 = n0 * p1 - n1 * p0
    return p0, p1, p2, q0, q1, q2


@kernel
def _radius(v, c):
    r2 = 0.0
    for i in range(v.shape[0]):
        d0 = v[i, 0] - c[0]
        d1 = v[i, 1] - c[1]
        d2 = v[i, 2] - c[2]
        r = d0 * d0 + d1 * d1 + d2 * d2
        if r > r2:
            r2 = r
    return math.sqrt(r2)


@kernel
def _band_fit(v, n0, n1, n2, ref, sgn, band, snap_tol):
    """Touching vertices of one block and, if >= 3 of them are coplanar, their plane normal.

    A vertex touches when ``sgn * (n.V - ref) >= -band`` (``sgn=+1`` for A, whose support
    is the maximum, ``-1`` for B). Returns ``(count, i0, i1, f0, f1, f2, planar)``: ``i0``,
    ``i1`` the two most distant touching vertices, ``f`` the unit normal through the three
    most spread touching vertices, oriented with ``sgn * f.n > 0``, ``planar`` True when every
    touching vertex lies within ``snap_tol`` of that plane.
    """
    cnt = 0
    i0 = -1
    for i in range(v.shape[0]):
        d = v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2
        if sgn * (d - ref) >= -band:
            cnt += 1
            if i0 < 0:
                i0 = i
    if cnt < 2:
        return cnt, i0, i0, 0.0, 0.0, 0.0, False
    # farthest touching vertex from i0
    i1 = i0
    best = -1.0
    for i in range(v.shape[0]):
        d = v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2
        if sgn * (d - ref) >= -band:
            e0 = v[i, 0] - v[i0, 0]
            e1 = v[i, 1] - v[i0, 1]
            e2 = v[i, 2] - v[i0, 2]
            r = e0 * e0 + e1 * e1 + e2 * e2
            if r > best:
                best = r
                i1 = i
    if cnt < 3:
        return cnt, i0, i1, 0.0, 0.0, 0.0, False
    a0 = v[i1, 0] - v[i0, 0]
    a1 = v[i1, 1] - v[i0, 1]
    a2 = v[i1, 2] - v[i0, 2]
    best = -1.0
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    for i in range(v.shape[0]):
        d = v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2
        if sgn * (d - ref) >= -band:
            b0 = v[i, 0] - v[i0, 0]
            b1 = v[i, 1] - v[i0, 1]
            b2 = v[i, 2] - v[i0, 2]
            c0 = a1 * b2 - a2 * b1
            c1 = a2 * b0 - a0 * b2
            c2 = a0 * b1 - a1 * b0
            r = c0 * c0 + c1 * c1 + c2 * c2
            if r > best:
                best = r
                f0, f1, f2 = c0, c1, c2
    s = math.sqrt(best)
    if s <= 1e-14 * (a0 * a0 + a1 * a1 + a2 * a2):  # collinear touching vertices
        return cnt, i0, i1, 0.0, 0.0, 0.0, False
    if sgn * (f0 * n0 + f1 * n1 + f2 * n2) < 0.0:
        s = -s
    f0 /= s
    f1 /= s
    f2 /= s
    for i in range(v.shape[0]):
        d = v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2
        if sgn * (d - ref) >= -band:
            off = f0 * (v[i, 0] - v[i0, 0]) + f1 * (v[i, 1] - v[i0, 1]) + f2 * (v[i, 2] - v[i0, 2])
            if abs(off) > snap_tol:
                return cnt, i0, i1, f0, f1, f2, False
    return cnt, i0, i1, f0, f1, f2, True


@kernel
def _try_normal(va, vb, m0, m1, m2, n0, n1, n2, cos_max, ia, ib, floor):
    """Gap of unit candidate ``m`` if within the snap cone of ``n`` and gap > ``floor``."""
    s = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    if not (s > 0.0):
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, ia, ib
    m0 /= s
    m1 /= s
    m2 /= s
    if m0 * n0 + m1 * n1 + m2 * n2 < cos_max:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, ia, ib
    ok, mxa, mnb, ka, kb = support_gap(va, vb, m0, m1, m2, ia, ib, floor)
    return ok, m0, m1, m2, mxa, mnb, ka, kb


@kernel
def _snap(va, vb, ca, cb, n0, n1, n2, maxa, minb, ia, ib, k_min, snap_tol):
    """Feature snap (pdem refinement, see module docstring). Returns the new state."""
    band_a = 4.0 * k_min * _radius(va, ca) + snap_tol
    band_b = 4.0 * k_min * _radius(vb, cb) + snap_tol
    # allowed angle between snapped and climbed normal: a few k_min
    ang = 8.0 * k_min
    cos_max = math.cos(ang)
    floor = (minb - maxa) - snap_tol
    ca_, a0, a1, fa0, fa1, fa2, pa = _band_fit(va, n0, n1, n2, maxa, 1.0, band_a, snap_tol)
    cb_, b0, b1, fb0, fb1, fb2, pb = _band_fit(vb, n0, n1, n2, minb, -1.0, band_b, snap_tol)
    r0, r1, r2, rmaxa, rminb, ria, rib = n0, n1, n2, maxa, minb, ia, ib
    done = False
    # faces: block with more touching vertices first, ties -> A
    for t in range(2):
        if done:
            break
        use_a = (t == 0) == (ca_ >= cb_)
        if use_a and pa:
            ok, m0, m1, m2, mxa, mnb, ka, kb = _try_normal(
                va, vb, fa0, fa1, fa2, n0, n1, n2, cos_max, ia, ib, floor
            )
        elif (not use_a) and pb:
            ok, m0, m1, m2, mxa, mnb, ka, kb = _try_normal(
                va, vb, -fb0, -fb1, -fb2, n0, n1, n2, cos_max, ia, ib, floor
            )
        else:
            ok = False
        if ok:
            r0, r1, r2, rmaxa, rminb, ria, rib = m0, m1, m2, mxa, mnb, ka, kb
            done = True
    if done or ca_ >= 3 or cb_ >= 3:
        return r0, r1, r2, rmaxa, rminb, ria, rib
    if ca_ == 2 and cb_ == 2:
        # edge-edge: normal along the cross product of the two edges
        e0 = va[a1, 0] - va[a0, 0]
        e1 = va[a1, 1] - va[a0, 1]
        e2 = va[a1, 2] - va[a0, 2]
        g0 = vb[b1, 0] - vb[b0, 0]
        g1 = vb[b1, 1] - vb[b0, 1]
        g2 = vb[b1, 2] - vb[b0, 2]
        m0 = e1 * g2 - e2 * g1
        m1 = e2 * g0 - e0 * g2
        m2 = e0 * g1 - e1 * g0
        if m0 * n0 + m1 * n1 + m2 * n2 < 0.0:
            m0, m1, m2 = -m0, -m1, -m2
        ok, m0, m1, m2, mxa, mnb, ka, kb = _try_normal(va, vb, m0, m1, m2, n0, n1, n2, cos_max, ia, ib, floor)
        if ok:
            return m0, m1, m2, mxa, mnb, ka, kb
    elif ca_ + cb_ == 3 or (ca_ == 1 and cb_ == 1):
        # vertex-edge / vertex-vertex: direction from the nearest point of the A feature
        # to the nearest point of the B feature (exact for separated blocks)
        d0 = vb[b0, 0] - va[a0, 0]
        d1 = vb[b0, 1] - va[a0, 1]
        d2 = vb[b0, 2] - va[a0, 2]
        e0 = 0.0
        e1 = 0.0
        e2 = 0.0
        if ca_ == 2:
            e0 = va[a1, 0] - va[a0, 0]
            e1 = va[a1, 1] - va[a0, 1]
            e2 = va[a1, 2] - va[a0, 2]
        elif cb_ == 2:
            e0 = vb[b1, 0] - vb[b0, 0]
            e1 = vb[b1, 1] - vb[b0, 1]
            e2 = vb[b1, 2] - vb[b0, 2]
        ee = e0 * e0 + e1 * e1 + e2 * e2
        if ee > 0.0:
            t = (d0 * e0 + d1 * e1 + d2 * e2) / ee
            d0 -= t * e0
            d1 -= t * e1
            d2 -= t * e2
        ok, m0, m1, m2, mxa, mnb, ka, kb = _try_normal(va, vb, d0, d1, d2, n0, n1, n2, cos_max, ia, ib, floor)
        if ok:
            return m0, m1, m2, mxa, mnb, ka, kb
    return r0, r1, r2, rmaxa, rminb, ria, rib


_NEAR = 4


@kernel
def _near_set(v, n0, n1, n2, ref, sgn, band, out):
    """Up to ``_NEAR`` vertices with ``sgn * (n.V - ref) >= -band``, nearest to the plane first."""
    cnt = 0
    val = np.empty(_NEAR)
    for i in range(v.shape[0]):
        d = sgn * (v[i, 0] * n0 + v[i, 1] * n1 + v[i, 2] * n2 - ref)
        if d < -band:
            continue
        if cnt == _NEAR and d <= val[cnt - 1]:
            continue
        pos = min(cnt, _NEAR - 1)
        while pos > 0 and val[pos - 1] < d:
            if pos < _NEAR:
                val[pos] = val[pos - 1]
                out[pos] = out[pos - 1]
            pos -= 1
        val[pos] = d
        out[pos] = i
        if cnt < _NEAR:
            cnt += 1
    return cnt


@kernel
def _features(cnt, out):
    """Vertices, vertex pairs and vertex triples of ``cnt`` near vertices, as index triples."""
    m = 0
    for i in range(cnt):
        out[m, 0] = i
        out[m, 1] = i
        out[m, 2] = i
        m += 1
    for i in range(cnt):
        for j in range(i + 1, cnt):
            out[m, 0] = i
            out[m, 1] = j
            out[m, 2] = j
            m += 1
    for i in range(cnt):
        for j in range(i + 1, cnt):
            for k in range(j + 1, cnt):
                out[m, 0] = i
                out[m, 1] = j
                out[m, 2] = k
                m += 1
    return m


@kernel
def _ridge_step(va, vb, n0, n1, n2, maxa, minb, ia, ib, band_a, band_b):
    """Escape a ridge of the piecewise-linear objective (pdem refinement beyond 3DEC).

    ``gap(n) = min over vertex pairs of n.(V_b - V_a)`` is a minimum of linear functions; along
    its ridges none of the eight hill-climbing directions may improve although the maximum is
    far. The vertices of A and B within ``band`` of their supports are the features that can
    become active; the normals they define (FCP types a, b, c, d: vertex-vertex direction,
    vertex-edge perpendicular, face normal, edge-edge cross product) are tried exactly and the
    best improving one is returned.
    """
    sa = np.empty(_NEAR, np.int64)
    sb = np.empty(_NEAR, np.int64)
    na = _near_set(va, n0, n1, n2, maxa, 1.0, band_a, sa)
    nb = _near_set(vb, n0, n1, n2, minb, -1.0, band_b, sb)
    # features: vertex (i, i, i), edge (i, j, j), face (i, j, k); at most 14 per block
    fa_ = np.empty((14, 3), np.int64)
    fb_ = np.empty((14, 3), np.int64)
    nfa = _features(na, fa_)
    nfb = _features(nb, fb_)
    found = False
    best = minb - maxa
    r0, r1, r2, rmaxa, rminb, ria, rib = n0, n1, n2, maxa, minb, ia, ib
    for fa in range(nfa):
        i = fa_[fa, 0]
        j = fa_[fa, 1]
        k = fa_[fa, 2]
        dima = 0 if i == j else (1 if j == k else 2)
        for fb in range(nfb):
            a = fb_[fb, 0]
            b = fb_[fb, 1]
            c = fb_[fb, 2]
            dimb = 0 if a == b else (1 if b == c else 2)
            # face-vertex, edge-edge, edge-vertex, vertex-vertex only; a face needs no partner
            if dima + dimb > 2 or (dima == 2 and fb > 0) or (dimb == 2 and fa > 0):
                continue
            pa0 = va[sa[i], 0]
            pa1 = va[sa[i], 1]
            pa2 = va[sa[i], 2]
            pb0 = vb[sb[a], 0]
            pb1 = vb[sb[a], 1]
            pb2 = vb[sb[a], 2]
            if dima == 2:
                u0 = va[sa[j], 0] - pa0
                u1 = va[sa[j], 1] - pa1
                u2 = va[sa[j], 2] - pa2
                w0 = va[sa[k], 0] - pa0
                w1 = va[sa[k], 1] - pa1
                w2 = va[sa[k], 2] - pa2
                m0 = u1 * w2 - u2 * w1
                m1 = u2 * w0 - u0 * w2
                m2 = u0 * w1 - u1 * w0
            elif dimb == 2:
                u0 = vb[sb[b], 0] - pb0
                u1 = vb[sb[b], 1] - pb1
                u2 = vb[sb[b], 2] - pb2
                w0 = vb[sb[c], 0] - pb0
                w1 = vb[sb[c], 1] - pb1
                w2 = vb[sb[c], 2] - pb2
                m0 = u1 * w2 - u2 * w1
                m1 = u2 * w0 - u0 * w2
                m2 = u0 * w1 - u1 * w0
            elif dima == 1 and dimb == 1:
                u0 = va[sa[j], 0] - pa0
                u1 = va[sa[j], 1] - pa1
                u2 = va[sa[j], 2] - pa2
                w0 = vb[sb[b], 0] - pb0
                w1 = vb[sb[b], 1] - pb1
                w2 = vb[sb[b], 2] - pb2
                m0 = u1 * w2 - u2 * w1
                m1 = u2 * w0 - u0 * w2
                m2 = u0 * w1 - u1 * w0
            else:
                m0 = pb0 - pa0
                m1 = pb1 - pa1
                m2 = pb2 - pa2
                if dima == 1 or dimb == 1:
                    if dima == 1:
                        u0 = va[sa[j], 0] - pa0
                        u1 = va[sa[j], 1] - pa1
                        u2 = va[sa[j], 2] - pa2
                    else:
                        u0 = vb[sb[b], 0] - pb0
                        u1 = vb[sb[b], 1] - pb1
                        u2 = vb[sb[b], 2] - pb2
                    uu = u0 * u0 + u1 * u1 + u2 * u2
                    if uu <= 0.0:
                        continue
                    t = (m0 * u0 + m1 * u1 + m2 * u2) / uu
                    m0 -= t * u0
                    m1 -= t * u1
                    m2 -= t * u2
            if m0 * n0 + m1 * n1 + m2 * n2 < 0.0:
                m0, m1, m2 = -m0, -m1, -m2
            mm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            if not (mm > 0.0):
                continue
            m0 /= mm
            m1 /= mm
            m2 /= mm
            ok, mxa, mnb, ka, kb = support_gap(va, vb, m0, m1, m2, ria, rib, best)
            if ok:
                found = True
                best = mnb - mxa
                r0, r1, r2, rmaxa, rminb, ria, rib = m0, m1, m2, mxa, mnb, ka, kb
    return found, r0, r1, r2, rmaxa, rminb, ria, rib


@kernel
def _ridge_walk(va, vb, n0, n1, n2, maxa, minb, ia, ib, band_a, band_b, k):
    """Line search along the ridges through ``n`` (pdem refinement beyond 3DEC).

    Two near-active vertices of one block (an edge with direction ``e``) make the objective
    non-smooth across the great circle ``n.e = const``; moving along its tangent ``n x e``
    keeps both constraints balanced. Each tangent (both senses) is searched with steps
    ``k, 2k, 4k, ...`` while the gap improves. Returns the best improving normal, if any, and
    the accepted step.
    """
    sa = np.empty(_NEAR, np.int64)
    sb = np.empty(_NEAR, np.int64)
    na = _near_set(va, n0, n1, n2, maxa, 1.0, band_a, sa)
    nb = _near_set(vb, n0, n1, n2, minb, -1.0, band_b, sb)
    best = minb - maxa
    found = False
    step = k
    r0, r1, r2, rmaxa, rminb, ria, rib = n0, n1, n2, maxa, minb, ia, ib
    for blk in range(2):
        cnt = na if blk == 0 else nb
        for i in range(cnt):
            for j in range(i + 1, cnt):
                if blk == 0:
                    e0 = va[sa[j], 0] - va[sa[i], 0]
                    e1 = va[sa[j], 1] - va[sa[i], 1]
                    e2 = va[sa[j], 2] - va[sa[i], 2]
                else:
                    e0 = vb[sb[j], 0] - vb[sb[i], 0]
                    e1 = vb[sb[j], 1] - vb[sb[i], 1]
                    e2 = vb[sb[j], 2] - vb[sb[i], 2]
                t0 = n1 * e2 - n2 * e1
                t1 = n2 * e0 - n0 * e2
                t2 = n0 * e1 - n1 * e0
                tt = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
                if not (tt > 0.0):
                    continue
                t0 /= tt
                t1 /= tt
                t2 /= tt
                for sgn in (1.0, -1.0):
                    h = k
                    while h < 1.0:
                        m0 = n0 + sgn * h * t0
                        m1 = n1 + sgn * h * t1
                        m2 = n2 + sgn * h * t2
                        z = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
                        m0 /= z
                        m1 /= z
                        m2 /= z
                        ok, mxa, mnb, ka, kb = support_gap(va, vb, m0, m1, m2, ria, rib, best)
                        if not ok:
                            break
                        found = True
                        best = mnb - mxa
                        step = h
                        r0, r1, r2, rmaxa, rminb, ria, rib = m0, m1, m2, mxa, mnb, ka, kb
                        h *= 2.0
    return found, r0, r1, r2, rmaxa, rminb, ria, rib, step


@kernel
def finish_plane(va, vb, n0, n1, n2, c, maxa, minb, ia, ib):
    """Translate the plane (eq. (8)) or place it between the nearest vertices (eq. (9))."""
    n = np.empty(3)
    n[0] = n0
    n[1] = n1
    n[2] = n2
    gap = minb - maxa
    p = np.empty(3)
    if gap > 0.0:
        for k in range(3):
            p[k] = 0.5 * (va[ia, k] + vb[ib, k])
    else:
        nc = n0 * c[0] + n1 * c[1] + n2 * c[2]
        shift = 0.5 * ((maxa - nc) + (minb - nc))
        for k in range(3):
            p[k] = c[k] + shift * n[k]
    np_ = n0 * p[0] + n1 * p[1] + n2 * p[2]
    return n, p, gap, maxa - np_, minb - np_


@kernel
def initial_plane(ca, cb, n_in, p_in, warm):
    """Starting plane: an existing contact's (warm start), else eq. (5) -- midway between the
    centroids, normal from A's centroid to B's. Returns (n0, n1, n2, point)."""
    if warm:
        n0, n1, n2 = n_in[0], n_in[1], n_in[2]
        c = p_in.copy()
    else:
        n0 = cb[0] - ca[0]
        n1 = cb[1] - ca[1]
        n2 = cb[2] - ca[2]
        c = np.empty(3)
        for k in range(3):
            c[k] = 0.5 * (ca[k] + cb[k])
    s = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if s > 0.0:
        n0 /= s
        n1 /= s
        n2 /= s
    else:
        n0, n1, n2 = 0.0, 0.0, 1.0
    return n0, n1, n2, c


@kernel
def common_plane(va, vb, ca, cb, n_in, p_in, warm, ctol, k_max, k_min, snap_tol, ridge=True):
    """Position the common plane between convex blocks A and B (Cundall, 3DEC).

    Parameters
    ----------
    va, vb : (na, 3), (nb, 3) float64 world vertex coordinates of A and B.
    ca, cb : (3,) centroids (cold start, and the size estimate for the snap band).
    n_in, p_in : (3,) previous normal and reference point (used when ``warm``).
    warm : bool, True for an existing contact.
    ctol : float, iteration stops as soon as the gap exceeds ``ctol``.
    k_max, k_min : perturbation sizes, tan(5 deg) and tan(0.01 deg) in 3DEC.
    snap_tol : length tolerance of the feature snap; ``<= 0`` disables it.
    ridge : bool, enable the ridge steps (pdem refinement); False is plain 3DEC except that a
        level is left only after both axis sets failed.

    Returns ``(n, p, gap, d_a, d_b, iters)``; see the module docstring. ``iters`` counts
    perturbation cycles (each tries four normals). If ``gap > ctol`` the search stopped early:
    the true maximum gap is at least ``gap``.
    """
    n0, n1, n2, c = initial_plane(ca, cb, n_in, p_in, warm)
    ok, maxa, minb, ia, ib = support_gap(va, vb, n0, n1, n2, 0, 0, -_INF)
    best = minb - maxa
    iters = 0
    if best > ctol:
        n, p, gap, da, db = finish_plane(va, vb, n0, n1, n2, c, maxa, minb, ia, ib)
        return n, p, gap, da, db, iters

    if warm:
        k = k_min
    else:
        k = k_max
    run = True
    first = warm  # warm start: one cycle at k_min decides whether to iterate at all
    cycle = 0
    fails = 0
    rad_a = _radius(va, ca)
    rad_b = _radius(vb, cb)
    sq = math.sqrt(0.5)
    while run:
        p0, p1, p2, q0, q1, q2 = _perp_axes(n0, n1, n2)
        if cycle % 2 == 1:  # axes rotated by 45 degrees on alternate cycles
            p0, p1, p2, q0, q1, q2 = (
                sq * (p0 + q0),
                sq * (p1 + q1),
                sq * (p2 + q2),
                sq * (q0 - p0),
                sq * (q1 - p1),
                sq * (q2 - p2),
            )
        found = False
        bn0, bn1, bn2 = n0, n1, n2
        bmaxa, bminb, bia, bib = maxa, minb, ia, ib
        bbest = best
        for t in range(4):
            if t == 0:
                u0, u1, u2 = p0, p1, p2
            elif t == 1:
                u0, u1, u2 = -p0, -p1, -p2
            elif t == 2:
                u0, u1, u2 = q0, q1, q2
            else:
                u0, u1, u2 = -q0, -q1, -q2
            m0 = n0 + k * u0
            m1 = n1 + k * u1
            m2 = n2 + k * u2
            z = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            m0 /= z
            m1 /= z
            m2 /= z
            ok, mxa, mnb, ka, kb = support_gap(va, vb, m0, m1, m2, bia, bib, bbest)
            if ok:
                found = True
                bbest = mnb - mxa
                bn0, bn1, bn2 = m0, m1, m2
                bmaxa, bminb, bia, bib = mxa, mnb, ka, kb
        iters += 1
        cycle += 1
        if found:
            n0, n1, n2 = bn0, bn1, bn2
            maxa, minb, ia, ib = bmaxa, bminb, bia, bib
            best = bbest
            if best > ctol:
                n, p, gap, da, db = finish_plane(va, vb, n0, n1, n2, c, maxa, minb, ia, ib)
                return n, p, gap, da, db, iters
            if first:
                first = False
                k = k_max
            fails = 0
        else:
            fails += 1
            if first:
                run = False
            elif fails < 2:
                pass  # retry this k with the axes rotated by 45 degrees
            elif ridge and k <= k_min:
                # both axis sets failed at the finest level: try the ridge steps
                rok, r0, r1, r2, rmxa, rmnb, ria, rib = _ridge_step(
                    va, vb, n0, n1, n2, maxa, minb, ia, ib, 2.0 * k * rad_a, 2.0 * k * rad_b
                )
                if rok:
                    n0, n1, n2 = r0, r1, r2
                    maxa, minb, ia, ib = rmxa, rmnb, ria, rib
                    best = rmnb - rmxa
                    fails = 0
                    if best > ctol:
                        n, p, gap, da, db = finish_plane(va, vb, n0, n1, n2, c, maxa, minb, ia, ib)
                        return n, p, gap, da, db, iters
                else:
                    rok, r0, r1, r2, rmxa, rmnb, ria, rib, h = _ridge_walk(
                        va, vb, n0, n1, n2, maxa, minb, ia, ib, 2.0 * k * rad_a, 2.0 * k * rad_b, k
                    )
                    if rok:
                        n0, n1, n2 = r0, r1, r2
                        maxa, minb, ia, ib = rmxa, rmnb, ria, rib
                        best = rmnb - rmxa
                        fails = 0
                        k = min(max(k, h), k_max)
                        if best > ctol:
                            n, p, gap, da, db = finish_plane(va, vb, n0, n1, n2, c, maxa, minb, ia, ib)
                            return n, p, gap, da, db, iters
                    elif k > k_min:
                        k = max(0.5 * k, k_min)
                        fails = 0
                    else:
                        run = False
            elif k > k_min:
                k = max(0.5 * k, k_min)
                fails = 0
            else:
                run = False

    if snap_tol > 0.0:
        n0, n1, n2, maxa, minb, ia, ib = _snap(
            va, vb, ca, cb, n0, n1, n2, maxa, minb, ia, ib, k_min, snap_tol
        )
    n, p, gap, da, db = finish_plane(va, vb, n0, n1, n2, c, maxa, minb, ia, ib)
    return n, p, gap, da, db, iters


@kernel
def contact_type(va, vb, n, p, tol):
    """Count the vertices of A and B touching the plane and classify the contact (Table 1).

    A vertex of A touches when ``n.(V - p) >= -tol``, one of B when ``n.(V - p) <= tol``.
    One touching vertex is a vertex, two an edge, three or more a face. Returns
    ``(count_a, count_b, ctype)`` with ``ctype`` one of the module constants (``NONE`` when
    either count is zero).
    """
    na = 0
    for i in range(va.shape[0]):
        d = n[0] * (va[i, 0] - p[0]) + n[1] * (va[i, 1] - p[1]) + n[2] * (va[i, 2] - p[2])
        if d >= -tol:
            na += 1
    nb = 0
    for j in range(vb.shape[0]):
        d = n[0] * (vb[j, 0] - p[0]) + n[1] * (vb[j, 1] - p[1]) + n[2] * (vb[j, 2] - p[2])
        if d <= tol:
            nb += 1
    return na, nb, type_code(na, nb)


@kernel
def type_code(count_a, count_b):
    """Contact type code from the numbers of touching vertices of the two blocks."""
    a = min(count_a, 3)
    b = min(count_b, 3)
    if a == 0 or b == 0:
        return NONE
    lo = min(a, b)
    hi = max(a, b)
    if lo == 1:
        if hi == 1:
            return VERTEX_VERTEX
        if hi == 2:
            return VERTEX_EDGE
        return VERTEX_FACE
    if lo == 2:
        if hi == 2:
            return EDGE_EDGE
        return EDGE_FACE
    return FACE_FACE
