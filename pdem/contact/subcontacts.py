"""Sub-contacts: where two blocks touch on their common plane, with areas and overlaps.

3DEC discretises the faces touching the common plane into sub-contacts (eqs. 24-25 text). pdem
does it with the contact region itself: the vertices of each block within ``touch_tol`` of the
common plane, projected on it, span a point, a segment or a convex polygon per block; the
sub-contacts are the corners of the intersection of the two. A face-face contact therefore gets
one sub-contact per corner of the common area, carrying a share of that area (a centroid fan,
so the shares sum to the exact common area and 3DEC's halving for double-counted springs is not
needed); vertex and edge contacts get points carrying ``point_area`` each. The overlap at each
sub-contact is measured between the two blocks' own surfaces (plane fits through their touching
vertices), so a tilted face carries a linearly varying load.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..jit import inline_kernel, kernel

EMPTY = 0
POINT = 1
SEGMENT = 2
POLYGON = 3


@kernel
def plane_basis(n):
    """Deterministic in-plane unit vectors (e1, e2) with e1 x e2 = n."""
    b = _plane_basis(n[0], n[1], n[2])
    return np.array([b[0], b[1], b[2]]), np.array([b[3], b[4], b[5]])


@inline_kernel
def _plane_basis(n0, n1, n2):
    """:func:`plane_basis` as six numbers (e1, e2), the same operations."""
    a0, a1, a2 = (1.0, 0.0, 0.0) if abs(n0) < 0.9 else (0.0, 1.0, 0.0)
    d = a0 * n0 + a1 * n1 + a2 * n2
    x = a0 - d * n0
    y = a1 - d * n1
    z = a2 - d * n2
    norm = np.sqrt(x ** 2 + y ** 2 + z ** 2)
    x /= norm
    y /= norm
    z /= norm
    return x, y, z, n1 * z - n2 * y, n2 * x - n0 * z, n0 * y - n1 * x


@kernel
def _cross2(ox, oy, ax, ay, bx, by):
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


@kernel
def hull2d(pts, eps):
    """Convex hull (Andrew's monotone chain) of 2D points, CCW, collinear points dropped.

    Returns (hull (k,2), kind) with kind POINT, SEGMENT or POLYGON."""
    m = pts.shape[0]
    return _hull2d(pts, eps, np.empty(m, np.int64), np.empty((2 * m + 1, 2)))


@kernel
def _hull2d(pts, eps, order, h):
    """:func:`hull2d` in ``order`` (room for the points) and ``h`` (for twice as many and one);
    the hull is a view of ``h``."""
    m = pts.shape[0]
    # lexicographic order by (x, y): insertion sort, pre-sorted for larger inputs (the order of
    # exact duplicates does not change the hull)
    if m > 32:
        order[:m] = np.argsort(pts[:, 0] * 1.0 + pts[:, 1] * 1e-7)
    else:
        for i in range(m):
            order[i] = i
    for i in range(1, m):
        j = i
        while j > 0:
            a = order[j - 1]
            b = order[j]
            if pts[a, 0] > pts[b, 0] or (pts[a, 0] == pts[b, 0] and pts[a, 1] > pts[b, 1]):
                order[j - 1] = b
                order[j] = a
                j -= 1
            else:
                break
    k = 0
    for ii in range(m):
        i = order[ii]
        while k >= 2 and _cross2(h[k - 2, 0], h[k - 2, 1], h[k - 1, 0], h[k - 1, 1],
                                 pts[i, 0], pts[i, 1]) <= eps:
            k -= 1
        h[k, 0] = pts[i, 0]
        h[k, 1] = pts[i, 1]
        k += 1
    lower = k + 1
    for ii in range(m - 2, -1, -1):
        i = order[ii]
        while k >= lower and _cross2(h[k - 2, 0], h[k - 2, 1], h[k - 1, 0], h[k - 1, 1],
                                     pts[i, 0], pts[i, 1]) <= eps:
            k -= 1
        h[k, 0] = pts[i, 0]
        h[k, 1] = pts[i, 1]
        k += 1
    k = max(k - 1, 1)
    out = h[:k]
    # collapse to a point/segment when the extent is negligible
    span = 0.0
    for i in range(k):
        d = (out[i, 0] - out[0, 0]) ** 2 + (out[i, 1] - out[0, 1]) ** 2
        if d > span:
            span = d
    if span <= eps:
        return out[:1], POINT
    if k <= 2:
        return out[:2], SEGMENT
    area2 = 0.0
    for i in range(k):
        j = (i + 1) % k
        area2 += out[i, 0] * out[j, 1] - out[j, 0] * out[i, 1]
    if area2 <= eps * np.sqrt(span):
        # thin sliver: keep the two farthest points as a segment
        bi = 0
        bj = 1
        best = -1.0
        for i in range(k):
            for j in range(i + 1, k):
                d = (out[i, 0] - out[j, 0]) ** 2 + (out[i, 1] - out[j, 1]) ** 2
                if d > best:
                    best = d
                    bi = i
                    bj = j
        seg = np.empty((2, 2))
        seg[0] = out[bi]
        seg[1] = out[bj]
        return seg, SEGMENT
    return out, POLYGON


@kernel
def height_fit(st, h):
    """Coefficients (c0, cs, ct) of the least-squares plane h = c0 + cs s + ct t through the
    touching vertices; degenerates to a line or a constant when they do not span a plane."""
    m = st.shape[0]
    ms = 0.0
    mt = 0.0
    mh = 0.0
    for i in range(m):
        ms += st[i, 0]
        mt += st[i, 1]
        mh += h[i]
    ms /= m
    mt /= m
    mh /= m
    sss = 0.0
    stt = 0.0
    sst = 0.0
    ssh = 0.0
    sth = 0.0
    for i in range(m):
        ds = st[i, 0] - ms
        dt = st[i, 1] - mt
        dh = h[i] - mh
        sss += ds * ds
        stt += dt * dt
        sst += ds * dt
        ssh += ds * dh
        sth += dt * dh
    det = sss * stt - sst * sst
    scale = sss + stt
    cs = 0.0
    ct = 0.0
    if scale > 0.0 and det > 1e-12 * scale * scale:
        cs = (ssh * stt - sth * sst) / det
        ct = (sth * sss - ssh * sst) / det
    elif scale > 0.0:
        # collinear: slope along the line only
        cs = ssh / scale
        ct = sth / scale
    return mh - cs * ms - ct * mt, cs, ct


@kernel
def _clip_polygon(subject, clip, cur, nxt):
    """Sutherland-Hodgman: convex ``subject`` clipped by convex CCW ``clip``, in ``cur`` and
    ``nxt`` (room for both polygons' corners and two); a view of one of them."""
    nc = subject.shape[0]
    cur[:nc] = subject
    m = clip.shape[0]
    for e in range(m):
        if nc == 0:
            break
        ax = clip[e, 0]
        ay = clip[e, 1]
        bx = clip[(e + 1) % m, 0]
        by = clip[(e + 1) % m, 1]
        nn = 0
        for i in range(nc):
            px = cur[i, 0]
            py = cur[i, 1]
            qx = cur[(i + 1) % nc, 0]
            qy = cur[(i + 1) % nc, 1]
            sp = _cross2(ax, ay, bx, by, px, py)
            sq = _cross2(ax, ay, bx, by, qx, qy)
            if sp >= 0.0:
                nxt[nn, 0] = px
                nxt[nn, 1] = py
                nn += 1
            if (sp >= 0.0) != (sq >= 0.0):
                tt = sp / (sp - sq)
                nxt[nn, 0] = px + tt * (qx - px)
                nxt[nn, 1] = py + tt * (qy - py)
                nn += 1
        cur, nxt = nxt, cur
        nc = nn
    return cur[:nc]


@kernel
def _clip_segment(seg, poly):
    """Part of segment ``seg`` inside convex CCW polygon ``poly`` (Cyrus-Beck)."""
    t0 = 0.0
    t1 = 1.0
    dx = seg[1, 0] - seg[0, 0]
    dy = seg[1, 1] - seg[0, 1]
    m = poly.shape[0]
    for e in range(m):
        ax = poly[e, 0]
        ay = poly[e, 1]
        bx = poly[(e + 1) % m, 0]
        by = poly[(e + 1) % m, 1]
        s0 = _cross2(ax, ay, bx, by, seg[0, 0], seg[0, 1])
        ds = (bx - ax) * dy - (by - ay) * dx
        if ds == 0.0:
            if s0 < 0.0:
                return np.empty((0, 2))
            continue
        t = -s0 / ds
        if ds > 0.0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
    if t0 > t1:
        return np.empty((0, 2))
    out = np.empty((2, 2))
    out[0, 0] = seg[0, 0] + t0 * dx
    out[0, 1] = seg[0, 1] + t0 * dy
    out[1, 0] = seg[0, 0] + t1 * dx
    out[1, 1] = seg[0, 1] + t1 * dy
    return out


@kernel
def _point_in_polygon(x, y, poly, tol):
    m = poly.shape[0]
    for e in range(m):
        if _cross2(poly[e, 0], poly[e, 1], poly[(e + 1) % m, 0], poly[(e + 1) % m, 1], x, y) < -tol:
            return False
    return True


@kernel
def _segment_cross(s1, s2):
    """Crossing point of two 2D segments (None-like empty array if they miss)."""
    d1x = s1[1, 0] - s1[0, 0]
    d1y = s1[1, 1] - s1[0, 1]
    d2x = s2[1, 0] - s2[0, 0]
    d2y = s2[1, 1] - s2[0, 1]
    den = d1x * d2y - d1y * d2x
    if den == 0.0:
        return np.empty((0, 2))
    ex = s2[0, 0] - s1[0, 0]
    ey = s2[0, 1] - s1[0, 1]
    t = (ex * d2y - ey * d2x) / den
    u = (ex * d1y - ey * d1x) / den
    if t < 0.0 or t > 1.0 or u < 0.0 or u > 1.0:
        return np.empty((0, 2))
    out = np.empty((1, 2))
    out[0, 0] = s1[0, 0] + t * d1x
    out[0, 1] = s1[0, 1] + t * d1y
    return out


@kernel
def merge_close_corners(pts, area, tol):
    """:func:`_merge_close_corners` into arrays of its own."""
    k = pts.shape[0]
    out, out_area = _merge_close_corners(pts, area, tol, np.empty(k, np.bool_),
                                         np.empty((k, 2)), np.empty(k))
    return out.copy(), out_area.copy()


@kernel
def _merge_close_corners(pts, area, tol, apart, out, out_area):
    """A polygon region's corners (in order) with each run of consecutive corners closer than
    ``tol`` to the next merged into one, at their area-weighted centroid, carrying their summed
    area. A sliver where two faces overlap by microns (diagonal neighbours in a settling stack)
    or the near-duplicate corners of a slightly turned face keep one sub-contact per place
    instead of two a hair apart: the same force and moment to within ``tol`` times the force,
    for fewer sub-contacts (the 20^3 cube stack: 14 % fewer). ``apart``, ``out`` and
    ``out_area``: room for the corners; the result is ``(pts, area)`` or views of those."""
    k = pts.shape[0]
    for i in range(k):  # apart[i]: corner i is farther than tol from corner i - 1
        j = i - 1 if i > 0 else k - 1
        apart[i] = (pts[i, 0] - pts[j, 0]) ** 2 + (pts[i, 1] - pts[j, 1]) ** 2 > tol * tol
    first = 0  # a corner that starts a cluster (none apart: one cluster of all, from 0)
    for i in range(k):
        if apart[i]:
            first = i
            break
    m = 0
    # sum a x, sum a y, sum a, sum x, sum y, count
    sax = say = sa = sx = sy = cnt = 0.0
    for t in range(k + 1):
        i = (first + t) % k
        if t == k or (t > 0 and apart[i]):  # close the cluster before corner i
            w = sa if sa > 0.0 else cnt
            out[m, 0] = (sax if sa > 0.0 else sx) / w
            out[m, 1] = (say if sa > 0.0 else sy) / w
            out_area[m] = sa
            m += 1
            sax = say = sa = sx = sy = cnt = 0.0
            if t == k:
                break
        sax += area[i] * pts[i, 0]
        say += area[i] * pts[i, 1]
        sa += area[i]
        sx += pts[i, 0]
        sy += pts[i, 1]
        cnt += 1.0
    if m == k:
        return pts, area
    return out[:m], out_area[:m]


# Room for one contact region (:func:`region_scratch`), reused from contact to contact by the
# geometry update: the region of two cubes is a few dozen numbers, and the ~20 small arrays it
# allocated cost as much as its arithmetic (docs/validation.md, Benchmarks).
RegionScratch = namedtuple("RegionScratch",
                           "h st ht order hull_a hull_b cur nxt area apart merged merged_area "
                           "overlap counts")


@kernel
def region_scratch(max_verts):
    """:data:`RegionScratch` for pieces of up to ``max_verts`` vertices."""
    m = 2 * max_verts
    cap = 2 * (m + 1) + 2  # both hulls' corners and two (the clip)
    return RegionScratch(np.empty(m), np.empty((m, 2)), np.empty(m), np.empty(m, np.int64),
                         np.empty((m + 1, 2)), np.empty((m + 1, 2)), np.empty((cap, 2)),
                         np.empty((cap, 2)), np.empty(cap), np.empty(cap, np.bool_),
                         np.empty((cap, 2)), np.empty(cap), np.empty(cap), np.empty(2, np.int64))


@kernel
def contact_region(va, vb, n, p, touch_tol):
    """Touching region of blocks A (below the plane) and B (above) on the common plane.

    Parameters
    ----------
    va, vb : (na, 3), (nb, 3) world vertices.
    n, p : common-plane unit normal (A -> B) and reference point.
    touch_tol : vertices within this distance of their block's extreme along n touch.

    Returns
    -------
    pts : (k, 2) sub-contact points in plane coordinates (e1, e2) about ``p``.
    overlap : (k,) surface overlap at each point (positive = interpenetration).
    area : (k,) area carried by each point when the region is a polygon, else 0.
    kind : EMPTY, POINT, SEGMENT or POLYGON (the region's dimension).
    e1, e2 : the in-plane basis used.
    counts : (2,) touching vertices of A and of B (contact type, Table 1).
    """
    ws = region_scratch(max(va.shape[0], vb.shape[0]))
    pts, overlap, area, kind, e, counts = region_in(va, vb, n, p, touch_tol, ws)
    return pts.copy(), overlap.copy(), area.copy(), kind, np.array([e[0], e[1], e[2]]), \
        np.array([e[3], e[4], e[5]]), counts.copy()


@kernel
def region_in(va, vb, n, p, touch_tol, ws):
    """:func:`contact_region` in the room of ``ws`` (:func:`region_scratch`, for pieces of at
    least as many vertices): ``pts``, ``overlap``, ``area`` and ``counts`` are views of it (or
    small arrays of their own), valid until its next use, and the basis is six numbers
    ``(e1, e2)``."""
    e = _plane_basis(n[0], n[1], n[2])
    e10, e11, e12, e20, e21, e22 = e
    na = va.shape[0]
    nb = vb.shape[0]
    n0, n1, n2 = n[0], n[1], n[2]
    p0, p1, p2 = p[0], p[1], p[2]
    # heights above the plane: A's in h[:na], B's in h[na:]
    h = ws.h
    amax = -np.inf
    for i in range(na):
        hi = n0 * (va[i, 0] - p0) + n1 * (va[i, 1] - p1) + n2 * (va[i, 2] - p2)
        h[i] = hi
        amax = max(amax, hi)
    bmin = np.inf
    for i in range(nb):
        hi = n0 * (vb[i, 0] - p0) + n1 * (vb[i, 1] - p1) + n2 * (vb[i, 2] - p2)
        h[na + i] = hi
        bmin = min(bmin, hi)
    # touching vertices projected on the plane: A's in st[:ka], B's in st[ka:ka + kb], with
    # their heights in ht
    st = ws.st
    ht = ws.ht
    ka = 0
    for i in range(na):
        if h[i] >= amax - touch_tol:
            d0 = va[i, 0] - p0
            d1 = va[i, 1] - p1
            d2 = va[i, 2] - p2
            st[ka, 0] = d0 * e10 + d1 * e11 + d2 * e12
            st[ka, 1] = d0 * e20 + d1 * e21 + d2 * e22
            ht[ka] = h[i]
            ka += 1
    kb = 0
    for i in range(nb):
        if h[na + i] <= bmin + touch_tol:
            d0 = vb[i, 0] - p0
            d1 = vb[i, 1] - p1
            d2 = vb[i, 2] - p2
            st[ka + kb, 0] = d0 * e10 + d1 * e11 + d2 * e12
            st[ka + kb, 1] = d0 * e20 + d1 * e21 + d2 * e22
            ht[ka + kb] = h[na + i]
            kb += 1
    sta = st[:ka]
    stb = st[ka:ka + kb]
    counts = ws.counts
    counts[0] = ka
    counts[1] = kb
    # size scale for the 2D tolerances
    scale = 0.0
    for k in range(ka + kb):
        scale = max(scale, abs(st[k, 0]) + abs(st[k, 1]))
    scale = max(scale, touch_tol, 1e-300)
    eps = 1e-12 * scale * scale
    polya, kinda = _hull2d(sta, eps, ws.order, ws.hull_a)
    polyb, kindb = _hull2d(stb, eps, ws.order, ws.hull_b)
    ca0, cas, cat = height_fit(sta, ht[:ka])
    cb0, cbs, cbt = height_fit(stb, ht[ka:ka + kb])

    if kinda == POLYGON and kindb == POLYGON:
        pts = _clip_polygon(polya, polyb, ws.cur, ws.nxt)
        kind = POLYGON if pts.shape[0] >= 3 else EMPTY
    elif kinda == POLYGON and kindb == SEGMENT:
        pts = _clip_segment(polyb, polya)
        kind = SEGMENT
    elif kindb == POLYGON and kinda == SEGMENT:
        pts = _clip_segment(polya, polyb)
        kind = SEGMENT
    elif kinda == SEGMENT and kindb == SEGMENT:
        pts = _segment_cross(polya, polyb)
        kind = POINT
    elif kinda == POINT and kindb == POLYGON:
        pts = polya if _point_in_polygon(polya[0, 0], polya[0, 1], polyb, 1e-9 * scale) \
            else ws.cur[:0]
        kind = POINT
    elif kindb == POINT and kinda == POLYGON:
        pts = polyb if _point_in_polygon(polyb[0, 0], polyb[0, 1], polya, 1e-9 * scale) \
            else ws.cur[:0]
        kind = POINT
    else:
        pts = ws.cur[:0]
        kind = EMPTY

    # A polygon clip can come back with near-duplicate corners; a degenerate area is no polygon.
    area = ws.area[:pts.shape[0]]
    area[:] = 0.0
    if kind == POLYGON:
        k = pts.shape[0]
        cx = 0.0
        cy = 0.0
        for i in range(k):
            cx += pts[i, 0]
            cy += pts[i, 1]
        cx /= k
        cy /= k
        total = 0.0
        for i in range(k):
            j = (i + 1) % k
            tri = 0.5 * _cross2(cx, cy, pts[i, 0], pts[i, 1], pts[j, 0], pts[j, 1])
            area[i] += 0.5 * tri
            area[j] += 0.5 * tri
            total += tri
        if total <= eps:
            kind = EMPTY
            pts = ws.cur[:0]
            area = ws.area[:0]
        else:  # corners within the touch tolerance of each other: one sub-contact
            pts, area = _merge_close_corners(pts, area, touch_tol, ws.apart, ws.merged,
                                             ws.merged_area)
    elif kind == SEGMENT and pts.shape[0] == 2:
        if (pts[0, 0] - pts[1, 0]) ** 2 + (pts[0, 1] - pts[1, 1]) ** 2 <= eps:
            pts = pts[:1]
            area = ws.area[:1]
            area[0] = 0.0
            kind = POINT
    overlap = ws.overlap
    if pts.shape[0] == 0:
        # Numerically empty intersection (blocks meet at a corner): one point at the reference
        # point, loaded by the common-plane gap.
        pts = ws.cur[:1]
        pts[0, 0] = 0.0
        pts[0, 1] = 0.0
        area = ws.area[:1]
        area[0] = 0.0
        overlap[0] = amax - bmin
        return pts, overlap[:1], area, EMPTY, e, counts
    for i in range(pts.shape[0]):
        s = pts[i, 0]
        t = pts[i, 1]
        overlap[i] = (ca0 + cas * s + cat * t) - (cb0 + cbs * s + cbt * t)
    return pts, overlap[:pts.shape[0]], area, kind, e, counts
