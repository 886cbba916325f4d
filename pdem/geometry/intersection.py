"""Volume of the intersection of half-spaces, compiled: how much two blocks share.

Sliver joining and block joining ask, for thousands of pairs of cut pieces, the area of the
face patch two pieces share (pdem.model.rockmass.touch_area): the volume of the intersection
of the two pieces grown by a small ``eps``, over ``2 eps``. Built as convex polyhedra, one
clip at a time, each pair cost ~1 ms of numpy and Python; here it is a polygon soup clipped in
one kernel.

The soup starts as a box around the first set's region and is clipped by every half-space
``n . x <= d`` in turn: each face polygon is clipped (Sutherland-Hodgman, orientation kept),
and the points the clip made on the plane become the cap face, ordered counter-clockwise seen
along ``n`` (outward). A repeated point in the cap only adds a zero-area triangle. The volume
is the divergence theorem over the faces' triangle fans, about the box's centre.
"""

from __future__ import annotations

import numpy as np

from ..jit import inline_kernel, kernel


@inline_kernel
def ring_order(xyz, n):
    """The order of the points ``xyz`` (k, 3) of a convex polygon in the plane of unit normal
    ``n`` counter-clockwise seen along ``n``: by angle about their mean, in the basis ``u = n x
    e`` (e the axis least along n), ``w = n x u``, (u, w, n) right-handed. A cap of a cut is
    then outward for the piece whose side the normal leaves."""
    e = np.zeros(3)
    e[np.argmin(np.abs(n))] = 1.0
    u = np.array([n[1] * e[2] - n[2] * e[1], n[2] * e[0] - n[0] * e[2], n[0] * e[1] - n[1] * e[0]])
    u /= np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    w = np.array([n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0]])
    k = xyz.shape[0]
    mean = np.zeros(3)
    for a in range(k):
        for c in range(3):
            mean[c] += xyz[a, c]
    mean /= k
    angle = np.empty(k)
    for a in range(k):
        qx = xyz[a, 0] - mean[0]
        qy = xyz[a, 1] - mean[1]
        qz = xyz[a, 2] - mean[2]
        angle[a] = np.arctan2(qx * w[0] + qy * w[1] + qz * w[2], qx * u[0] + qy * u[1] + qz * u[2])
    return np.argsort(angle, kind="mergesort")


@kernel
def _clip_soup(pts, start, n_faces, n, d, tol, scratch_pts, scratch_start):
    """Clip the face polygons ``pts[start[f]:start[f + 1]]`` (f < n_faces) to ``n . x <= d``
    into ``scratch_*``; returns the new face count and the points used (cap included), or
    ``(-1, 0)`` when the plane leaves them whole. Points within ``tol`` of the plane are on it:
    kept, corners of the cap, never the end of a crossing edge; a face whose kept points are
    all on the plane is dropped (the cap is that face)."""
    n_pts = start[n_faces]
    side = np.empty(n_pts, np.int64)
    above = False
    below = False
    for p in range(n_pts):
        sp = n[0] * pts[p, 0] + n[1] * pts[p, 1] + n[2] * pts[p, 2] - d
        side[p] = 1 if sp > tol else (-1 if sp < -tol else 0)
        above |= side[p] > 0
        below |= side[p] < 0
    if not above:
        return -1, 0
    if not below:
        return 0, 0
    out = 0
    nf = 0
    cap0 = scratch_pts.shape[0] - 1  # the cap's points are gathered from the end, backwards
    ncap = 0
    for f in range(n_faces):
        f0 = start[f]
        k = start[f + 1] - f0
        o0 = out
        on = 0
        for i in range(k):
            p = f0 + i
            q = f0 + (i + 1) % k
            if side[p] <= 0:
                for c in range(3):
                    scratch_pts[out, c] = pts[p, c]
                out += 1
                if side[p] == 0:
                    on += 1
                    for c in range(3):
                        scratch_pts[cap0 - ncap, c] = pts[p, c]
                    ncap += 1
            if side[p] * side[q] < 0:
                sp = n[0] * pts[p, 0] + n[1] * pts[p, 1] + n[2] * pts[p, 2] - d
                sq = n[0] * pts[q, 0] + n[1] * pts[q, 1] + n[2] * pts[q, 2] - d
                t = sp / (sp - sq)
                for c in range(3):
                    x = pts[p, c] + t * (pts[q, c] - pts[p, c])
                    scratch_pts[out, c] = x
                    scratch_pts[cap0 - ncap, c] = x
                out += 1
                on += 1
                ncap += 1
        if out - o0 >= 3 and on < out - o0:
            nf += 1
            scratch_start[nf] = out
        else:
            out = o0
    if ncap >= 3 and nf > 0:  # the cap, counter-clockwise seen along n (outward)
        cap = scratch_pts[cap0 - ncap + 1:cap0 + 1][::-1].copy()
        order = ring_order(cap, n)
        for a in range(ncap):
            for c in range(3):
                scratch_pts[out, c] = cap[order[a], c]
            out += 1
        nf += 1
        scratch_start[nf] = out
    return nf, out


@kernel
def halfspace_volume(normals, offsets, lo, hi):
    """Volume of the box ``[lo, hi]`` cut by every half-space ``normals[i] . x <= offsets[i]``
    (unit normals): 0 when empty. The box must hold the region for it to be the region's.
    Points within 1e-12 of the box's size of a plane count as on it."""
    m = normals.shape[0]
    tol = 1e-12 * max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2])
    cap = 6 * 4 + m * 64  # points: each clip adds at most two a face and the cap
    pts = np.empty((cap, 3))
    start = np.zeros(6 + m + 1, np.int64)
    corner = np.empty((8, 3))
    for i in range(8):
        corner[i, 0] = hi[0] if i & 1 else lo[0]
        corner[i, 1] = hi[1] if i & 2 else lo[1]
        corner[i, 2] = hi[2] if i & 4 else lo[2]
    # the box's faces, counter-clockwise seen from outside
    faces = ((0, 4, 6, 2), (1, 3, 7, 5), (0, 1, 5, 4), (2, 6, 7, 3), (0, 2, 3, 1),
             (4, 5, 7, 6))
    k = 0
    for f in range(6):
        for i in range(4):
            for c in range(3):
                pts[k, c] = corner[faces[f][i], c]
            k += 1
        start[f + 1] = k
    nf = 6
    n_pts = k
    other = np.empty((cap, 3))
    other_start = np.zeros(6 + m + 1, np.int64)
    for i in range(m):
        if nf == 0:
            return 0.0
        need = 3 * n_pts + 5 * nf + 8  # the clipped faces, the cap's points twice
        if need > cap:
            cap = 2 * need
            grown = np.empty((cap, 3))
            grown[:n_pts] = pts[:n_pts]
            pts = grown
            other = np.empty((cap, 3))
        got, used = _clip_soup(pts, start, nf, normals[i], offsets[i], tol, other,
                               other_start)
        if got < 0:  # the plane leaves the region whole
            continue
        nf, n_pts = got, used
        pts, other = other, pts
        start, other_start = other_start, start
    ref = 0.5 * (lo + hi)
    vol = 0.0
    for f in range(nf):
        f0 = start[f]
        for j in range(f0 + 1, start[f + 1] - 1):
            ax = pts[f0, 0] - ref[0]
            ay = pts[f0, 1] - ref[1]
            az = pts[f0, 2] - ref[2]
            bx = pts[j, 0] - ref[0]
            by = pts[j, 1] - ref[1]
            bz = pts[j, 2] - ref[2]
            cx = pts[j + 1, 0] - ref[0]
            cy = pts[j + 1, 1] - ref[1]
            cz = pts[j + 1, 2] - ref[2]
            vol += ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    return max(vol / 6.0, 0.0)
