"""Exact volume, centroid and inertia tensor of a closed polyhedron with planar faces.

Each face is fanned into triangles and each triangle is joined to a reference point, giving
signed tetrahedra whose moments are known in closed form; the signed sum is the divergence
theorem applied to the closed surface, so the result is exact up to round-off.
"""

from __future__ import annotations

import numpy as np

from .vector import cross


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
    v = np.asarray(vertices, dtype=np.float64)
    tri = fan_triangles(np.asarray(face_start), np.asarray(face_verts))
    # Tetrahedra are taken from the vertex mean, not the origin: for blocks far from the origin
    # this keeps the products small and avoids catastrophic cancellation in the shift to the
    # centroid below.
    ref = v.mean(axis=0)
    a = v[tri[:, 0]] - ref
    b = v[tri[:, 1]] - ref
    c = v[tri[:, 2]] - ref
    det = np.einsum("ij,ij->i", a, cross(b, c))  # 6 x signed tetrahedron volume
    volume = det.sum() / 6.0
    s = a + b + c
    first = (det[:, None] * s).sum(axis=0) / 24.0  # sum of V_t * (a+b+c)/4
    # integral over tet (0,a,b,c) of x x^T = V/20 (aa^T + bb^T + cc^T + ss^T), V = det/6.
    outer = (
        np.einsum("i,ij,ik->jk", det, a, a)
        + np.einsum("i,ij,ik->jk", det, b, b)
        + np.einsum("i,ij,ik->jk", det, c, c)
        + np.einsum("i,ij,ik->jk", det, s, s)
    ) / 120.0
    g = first / volume
    cov = outer - volume * np.outer(g, g)  # parallel-axis shift to the centroid
    inertia = np.trace(cov) * np.eye(3) - cov
    inertia = 0.5 * (inertia + inertia.T)
    return float(volume), ref + g, inertia
