"""The face planes of a mesh cell of a fixed type (tetra, hexahedron, wedge, pyramid), checked
and oriented in one compiled call.

:func:`pdem.geometry.mesh_import.cell_polyhedron` checks a cell in ~two dozen numpy calls
(~0.2 ms a cell, most of a meshed model's build: 27,000 hexahedra took 6 s). A cell of a
fixed type with distinct nodes (no collapsed faces) is checked here instead, with the same
arithmetic in the same order: the Newell area vectors from each face's triangle fan, their
norms, the mean offsets ``n . x`` over each face's nodes (each dot product summed
``(x n_x + y n_y) + z n_z`` on both paths: numpy's einsum, which the numpy path used before,
sums in an order that follows the CPU's vector width), the same tolerance. The normals and
offsets a block keeps are therefore the same bits (tests/unit/test_cell_planes.py). What a
check only compares with a tolerance (the flatness, warp and convexity distances) may round
differently; a cell any check fails is handed back (``ok`` False) and the numpy path checks
it again and words the error, so every message is that path's.
"""

from __future__ import annotations

import numpy as np

from ..jit import kernel

EPS = float(np.finfo(float).eps)


def template(faces: tuple[tuple[int, ...], ...]) -> tuple[np.ndarray, np.ndarray]:
    """A cell type's faces (node positions, pdem.geometry.mesh_import.CELL_FACES) as CSR
    arrays ``(face_start, face_verts)``, int64."""
    start = np.zeros(len(faces) + 1, np.int64)
    np.cumsum([len(f) for f in faces], out=start[1:])
    return start, np.array([k for f in faces for k in f], np.int64)


@kernel
def cell_planes(points, ids, fs, fv, rel_tol, coord_eps):
    """``(ok, v, n, d, oriented)`` of the cell with point ids ``ids`` and faces ``fs``/``fv``
    (positions in ``ids``): its vertices, unit outward normals and offsets, and its faces
    turned outward. ``ok`` False: repeated ids, a non-finite coordinate, or a face that is
    degenerate, warped or that another node lies outside (by more than the tolerance of
    pdem.geometry.mesh_import.cell_tolerance): the caller checks it the numpy way."""
    k = ids.shape[0]
    nf = fs.shape[0] - 1
    v = np.empty((k, 3))
    n = np.zeros((nf, 3))
    d = np.zeros(nf)
    oriented = fv.copy()
    for i in range(k):
        for j in range(i):
            if ids[i] == ids[j]:  # a collapsed cell: merged the numpy way
                return False, v, n, d, oriented
        for c in range(3):
            x = points[ids[i], c]
            if not np.isfinite(x):
                return False, v, n, d, oriented
            v[i, c] = x
    # the tolerance (cell_tolerance)
    scale = 0.0
    diag2 = 0.0
    mean = np.zeros(3)
    for c in range(3):
        lo = v[0, c]
        hi = v[0, c]
        for i in range(k):
            lo = min(lo, v[i, c])
            hi = max(hi, v[i, c])
            scale = max(scale, abs(v[i, c]))
            mean[c] += v[i, c]
        diag2 += (hi - lo) * (hi - lo)
        mean[c] /= k
    diag = np.sqrt(diag2)
    tol = max(rel_tol * diag, (256.0 * EPS + 8.0 * coord_eps) * scale, 1e-300)
    for f in range(nf):
        # Newell's area vector from the face's triangle fan (v0, v_t, v_t+1), summed in order
        a = fv[fs[f]]
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for t in range(fs[f] + 1, fs[f + 1] - 1):
            b = fv[t]
            c = fv[t + 1]
            e1x = v[b, 0] - v[a, 0]
            e1y = v[b, 1] - v[a, 1]
            e1z = v[b, 2] - v[a, 2]
            e2x = v[c, 0] - v[a, 0]
            e2y = v[c, 1] - v[a, 1]
            e2z = v[c, 2] - v[a, 2]
            sx += e1y * e2z - e1z * e2y
            sy += e1z * e2x - e1x * e2z
            sz += e1x * e2y - e1y * e2x
        area2 = np.sqrt(sx * sx + sy * sy + sz * sz)
        if area2 <= 2.0 * tol * diag:  # a zero-area face
            return False, v, n, d, oriented
        n[f, 0] = sx / area2
        n[f, 1] = sy / area2
        n[f, 2] = sz / area2
        s = 0.0
        for h in range(fs[f], fs[f + 1]):
            p = fv[h]
            s += v[p, 0] * n[f, 0] + v[p, 1] * n[f, 1] + v[p, 2] * n[f, 2]
        d[f] = s / (fs[f + 1] - fs[f])
        for h in range(fs[f], fs[f + 1]):  # warped: a face node off the face's plane
            p = fv[h]
            if abs(v[p, 0] * n[f, 0] + v[p, 1] * n[f, 1] + v[p, 2] * n[f, 2] - d[f]) > tol:
                return False, v, n, d, oriented
        # the mean of the nodes is inside a convex cell: the face points away from it
        h_mean = n[f, 0] * mean[0] + n[f, 1] * mean[1] + n[f, 2] * mean[2] - d[f]
        if abs(h_mean) <= tol:  # flat: zero volume
            return False, v, n, d, oriented
        if h_mean > 0.0:  # numbered clockwise: turned
            for c in range(3):
                n[f, c] = -n[f, c]
            d[f] = -d[f]
            m = fs[f + 1] - fs[f]
            for h in range(m):
                oriented[fs[f] + h] = fv[fs[f + 1] - 1 - h]
    for i in range(k):  # convex: no node outside a face's plane
        for f in range(nf):
            if v[i, 0] * n[f, 0] + v[i, 1] * n[f, 1] + v[i, 2] * n[f, 2] - d[f] > tol:
                return False, v, n, d, oriented
    return True, v, n, d, oriented
