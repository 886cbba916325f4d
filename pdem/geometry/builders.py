"""Constructors for common block shapes."""

from __future__ import annotations

from itertools import combinations

import numpy as np

from pdem.geometry.errors import GeometryError
from pdem.geometry.hull import convex_hull, default_tolerance, hull_faces
from pdem.geometry.polyhedron import ConvexPolyhedron, newell_normal

# Box faces over corner ids (bit 0 = x, bit 1 = y, bit 2 = z), CCW seen from outside.
_BOX_FACES = [
    [0, 4, 6, 2],  # -x
    [1, 3, 7, 5],  # +x
    [0, 1, 5, 4],  # -y
    [2, 6, 7, 3],  # +y
    [0, 2, 3, 1],  # -z
    [4, 5, 7, 6],  # +z
]
BOX_NORMALS = np.array(
    [[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], dtype=np.float64
)


def box(lo, hi) -> ConvexPolyhedron:
    """Axis-aligned box ``[lo, hi]``.

    Parameters
    ----------
    lo, hi : (3,) array_like
        Opposite corners, ``lo < hi`` componentwise.

    Returns
    -------
    ConvexPolyhedron
        8 vertices (vertex ``k`` takes ``hi`` in axis ``i`` iff bit ``i`` of ``k`` is set),
        6 quadrilateral faces with exact axis normals.
    """
    lo = np.asarray(lo, dtype=np.float64).reshape(3)
    hi = np.asarray(hi, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise GeometryError("box corners contain NaN or inf")
    if np.any(hi <= lo):
        raise GeometryError(f"box needs lo < hi in every axis, got lo={lo}, hi={hi}")
    bits = (np.arange(8)[:, None] >> np.arange(3)) & 1
    verts = np.where(bits == 1, hi, lo)
    offsets = np.concatenate([[-lo[0], hi[0], -lo[1], hi[1], -lo[2], hi[2]]])
    return ConvexPolyhedron.from_faces(verts, _BOX_FACES, BOX_NORMALS, offsets)


def from_vertices(points, tol: float | None = None) -> ConvexPolyhedron:
    """Convex polyhedron spanned by ``points`` (their convex hull); see :func:`convex_hull`."""
    return convex_hull(points, tol)


def tetrahedron(p0, p1, p2, p3) -> ConvexPolyhedron:
    """Tetrahedron with the given corners (any order; orientation is fixed automatically)."""
    pts = np.array([p0, p1, p2, p3], dtype=np.float64)
    poly = convex_hull(pts)
    if poly.n_vertices != 4:
        raise GeometryError("tetrahedron corners are degenerate")
    return poly


def prism(base_polygon, extrusion_vector) -> ConvexPolyhedron:
    """Right or oblique prism: a convex planar polygon swept along a vector.

    Parameters
    ----------
    base_polygon : (n, 3) array_like
        Convex planar polygon, vertices in order (either orientation), ``n >= 3``.
    extrusion_vector : (3,) array_like
        Sweep vector; must not be parallel to the base plane.

    Returns
    -------
    ConvexPolyhedron
    """
    base = np.asarray(base_polygon, dtype=np.float64)
    e = np.asarray(extrusion_vector, dtype=np.float64).reshape(3)
    if base.ndim != 2 or base.shape[1] != 3 or len(base) < 3:
        raise GeometryError(f"base polygon must have shape (n >= 3, 3), got {base.shape}")
    if not (np.all(np.isfinite(base)) and np.all(np.isfinite(e))):
        raise GeometryError("prism input contains NaN or inf")
    tol = default_tolerance(base)
    area = newell_normal(base)
    if np.linalg.norm(area) <= tol * tol:
        raise GeometryError("prism base polygon has zero area")
    n = area / np.linalg.norm(area)
    if np.max(np.abs((base - base.mean(axis=0)) @ n)) > tol:
        raise GeometryError("prism base polygon is not planar")
    # Convex (in the given order): every corner turns the same way as the overall polygon.
    turn = np.cross(base - np.roll(base, 1, axis=0), np.roll(base, -1, axis=0) - base) @ n
    if np.any(turn < -tol * np.linalg.norm(np.roll(base, -1, axis=0) - base, axis=1)):
        raise GeometryError("prism base polygon is not convex (or its vertices are not in order)")
    if abs(e @ n) <= tol:
        raise GeometryError("prism extrusion vector lies in the base plane (zero volume)")
    return convex_hull(np.concatenate([base, base + e]))


def from_planes(normals, offsets, bounds=None) -> ConvexPolyhedron:
    """Intersection of half-spaces ``normals[i] . x <= offsets[i]``.

    Vertices are the feasible intersections of plane triples (fine for up to ~30 planes),
    hulled. Redundant planes are allowed. Faces lying on an input plane take that plane's
    exact unit normal and offset.

    Parameters
    ----------
    normals : (m, 3) array_like
        Outward normals (need not be unit).
    offsets : (m,) array_like
        Plane offsets in the units of the given normals.
    bounds : (2, 3) array_like, optional
        ``(lo, hi)`` of an axis-aligned box to intersect with as well.

    Returns
    -------
    ConvexPolyhedron

    Raises
    ------
    GeometryError
        If the intersection is empty, has zero volume, or is unbounded.
    """
    N = np.asarray(normals, dtype=np.float64)
    d = np.asarray(offsets, dtype=np.float64).reshape(-1)
    if N.ndim != 2 or N.shape[1] != 3 or len(N) != len(d):
        raise GeometryError(f"normals (m, 3) and offsets (m,) mismatch: {N.shape}, {d.shape}")
    if not (np.all(np.isfinite(N)) and np.all(np.isfinite(d))):
        raise GeometryError("planes contain NaN or inf")
    nrm = np.linalg.norm(N, axis=1)
    if np.any(nrm == 0.0):
        raise GeometryError("a plane normal is zero")
    N, d = N / nrm[:, None], d / nrm
    if bounds is not None:
        lo, hi = (np.asarray(b, dtype=np.float64).reshape(3) for b in bounds)
        N = np.concatenate([N, BOX_NORMALS])
        d = np.concatenate([d, [-lo[0], hi[0], -lo[1], hi[1], -lo[2], hi[2]]])
    m_user = len(N)
    # A large box around everything turns "unbounded" into "touches the big box", which can
    # be told apart from "empty" (no feasible vertex). It sits beyond every triple
    # intersection, so it never cuts a bounded polyhedron.
    pts = _triple_points(N, d)
    big = 10.0 * max(np.abs(pts).max() if len(pts) else 0.0, np.abs(d).max(), 1.0)
    N = np.concatenate([N, BOX_NORMALS])
    d = np.concatenate([d, np.full(6, big)])
    dscale = float(np.abs(d[:m_user]).max())
    pts = _triple_points(N, d)
    # Feasibility tolerance per point, relative to the point's own magnitude: spurious
    # near-vertices that matter lie near the block, so a tolerance set by far-away triple
    # intersections (or the big box) would be far too loose for small blocks.
    tol = 1e-10 * np.abs(pts).max(axis=1) + 1e-12 * dscale
    feas = pts[np.all(pts @ N.T - d <= tol[:, None], axis=1)]
    if len(feas) < 4:
        raise GeometryError("half-space intersection is empty or has zero volume")
    try:
        used, faces, _ = hull_faces(feas, None)
    except GeometryError as exc:
        raise GeometryError(f"half-space intersection has zero volume ({exc})") from exc
    v = feas[used]
    fn, fd = [], []
    for face in faces:
        poly = v[face]
        n = newell_normal(poly)
        n = n / np.linalg.norm(n)
        # Match this face to the input plane it lies on; only the big box is left otherwise.
        err = np.max(np.abs(poly @ N.T - d), axis=0)
        err[N @ n < 1.0 - 1e-6] = np.inf
        k = int(np.argmin(err))
        if k >= m_user or not np.isfinite(err[k]):
            raise GeometryError("half-space intersection is unbounded")
        fn.append(N[k])
        fd.append(d[k])
    return ConvexPolyhedron.from_faces(v, faces, np.array(fn), np.array(fd))


def _triple_points(N: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Intersection points of all non-degenerate plane triples."""
    tri = np.array(list(combinations(range(len(N)), 3)), dtype=np.int64)
    if not len(tri):
        return np.empty((0, 3))
    A = N[tri]  # (t, 3, 3)
    b = d[tri]
    det = np.linalg.det(A)
    ok = np.abs(det) > 1e-12
    return np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
