"""Exact volume, centroid and inertia tensor of a closed polyhedron with planar faces.

Each face is fanned into triangles and each triangle is joined to a reference point, giving
signed tetrahedra whose moments are known in closed form; the signed sum is the divergence
theorem applied to the closed surface, so the result is exact up to round-off.
"""

from __future__ import annotations

import numpy as np

from ..jit import kernel


def fan_triangles(face_start: np.ndarray, face_verts: np.ndarray) -> np.ndarray:
    """Fan every face polygon into triangles ``(v0, v_i, v_{i+1})``.

    Parameters
    ----------
    face_start : (nf+1,) int64
        CSR offsets into ``face_verts``.
    face_verts : (sum,) int64
        Vertex ids of each face, counter-clockwise seen from outside.

    Returns
    -------
    (nt, 3) int64
        Vertex ids of the triangles, orientation inherited from the faces.
    """
    tris = []
    for f in range(len(face_start) - 1):
        ids = face_verts[face_start[f] : face_start[f + 1]]
        k = len(ids)
        t = np.empty((k - 2, 3), dtype=np.int64)
        t[:, 0] = ids[0]
        t[:, 1] = ids[1 : k - 1]
        t[:, 2] = ids[2:k]
        tris.append(t)
    if not tris:
        return np.empty((0, 3), dtype=np.int64)
    return np.concatenate(tris)


def mass_properties(
    vertices: np.ndarray, face_start: np.ndarray, face_verts: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, centroid and inertia tensor (about the centroid, unit density).

    Parameters
    ----------
    vertices : (nv, 3) float64
        Vertex coordinates.
    face_start, face_verts : int64
        Faces in CSR form, counter-clockwise seen from outside (outward right-hand normal).

    Returns
    -------
    volume : float
        Enclosed volume (positive for outward-oriented faces).
    centroid : (3,) float64
        Centre of volume.
    inertia : (3, 3) float64
        Inertia tensor about the centroid per unit density:
        ``I = tr(C) 1 - C`` with ``C = integral (x - c)(x - c)^T dV``.
    """
    volume, centroid, inertia = _mass_properties(
        np.ascontiguousarray(vertices, dtype=np.float64),
        np.ascontiguousarray(face_start, dtype=np.int64),
        np.ascontiguousarray(face_verts, dtype=np.int64))
    return float(volume), centroid, inertia


@kernel
def _mass_properties(v, face_start, face_verts):
    """:func:`mass_properties` compiled: every cut piece of a rock mass is made through it
    (numpy's per-call overhead on a dozen faces was ~130 us a piece, a fifth of the cutting)."""
    # Tetrahedra are taken from the vertex mean, not the origin: for blocks far from the origin
    # this keeps the products small and avoids catastrophic cancellation in the shift to the
    # centroid below.
    ref = np.zeros(3)
    for i in range(v.shape[0]):
        for k in range(3):
            ref[k] += v[i, k]
    ref /= max(v.shape[0], 1)
    det_sum = 0.0
    first = np.zeros(3)
    outer = np.zeros((3, 3))
    a = np.empty(3)
    b = np.empty(3)
    c = np.empty(3)
    s = np.empty(3)
    for f in range(face_start.shape[0] - 1):
        f0 = face_start[f]
        for i in range(f0 + 1, face_start[f + 1] - 1):  # the face's fan (v0, v_i, v_i+1)
            for k in range(3):
                a[k] = v[face_verts[f0], k] - ref[k]
                b[k] = v[face_verts[i], k] - ref[k]
                c[k] = v[face_verts[i + 1], k] - ref[k]
                s[k] = a[k] + b[k] + c[k]
            det = (a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2])
                   + a[2] * (b[0] * c[1] - b[1] * c[0]))  # 6 x signed tetrahedron volume
            det_sum += det
            for j in range(3):
                first[j] += det * s[j]  # sum of V_t * (a+b+c)/4, times 24
                # integral over tet (0,a,b,c) of x x^T = V/20 (aa^T + bb^T + cc^T + ss^T)
                for k in range(3):
                    outer[j, k] += det * (a[j] * a[k] + b[j] * b[k] + c[j] * c[k]
                                          + s[j] * s[k])
    volume = det_sum / 6.0
    if volume == 0.0:  # refused by the caller (ConvexPolyhedron.from_faces)
        return volume, ref, np.zeros((3, 3))
    g = first / 24.0 / volume
    cov = outer / 120.0
    for j in range(3):
        for k in range(3):
            cov[j, k] -= volume * g[j] * g[k]  # parallel-axis shift to the centroid
    tr = cov[0, 0] + cov[1, 1] + cov[2, 2]
    inertia = np.empty((3, 3))
    for j in range(3):
        for k in range(3):
            inertia[j, k] = (tr if j == k else 0.0) - 0.5 * (cov[j, k] + cov[k, j])
    return volume, ref + g, inertia
