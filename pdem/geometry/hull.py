"""Robust 3D convex hull with coplanar facets merged into convex polygons.

Incremental (beneath-beyond) construction over triangles, always inserting the point farthest
outside the current hull so that extreme points come first and points on faces or edges are
never inserted; then triangles lying in a common plane (within the tolerance) are merged and
each merged face is re-hulled in 2D, which drops collinear points. Point counts are small
(a block has tens to a few hundred vertices), so clarity wins over asymptotics here.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from pdem.geometry.errors import GeometryError
from pdem.geometry.polyhedron import ConvexPolyhedron

from .vector import cross

# Relative tolerance: distances below REL_TOL * (point-cloud diagonal) count as zero.
REL_TOL = 1e-9


def _as_points(points) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise GeometryError(f"points must have shape (n, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        bad = np.flatnonzero(~np.all(np.isfinite(p), axis=1))
        raise GeometryError(f"points contain NaN or inf (point(s) {bad.tolist()})")
    if len(p) < 4:
        raise GeometryError(f"a polyhedron needs at least 4 points, got {len(p)}")
    return p


def default_tolerance(points) -> float:
    """Distance tolerance for hull decisions on ``points``.

    ``REL_TOL`` times the bounding-box diagonal, floored at a few hundred ulps of the largest
    coordinate (blocks far from the origin, e.g. in map coordinates, carry that much
    round-off in every vertex).

    Parameters
    ----------
    points : (n, 3) array_like

    Returns
    -------
    float
    """
    p = np.asarray(points, dtype=np.float64)
    diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    return max(REL_TOL * diag, 256.0 * np.finfo(float).eps * float(np.abs(p).max()), 1e-300)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


class _TriHull:
    """Triangulated hull under incremental construction (internal)."""

    def __init__(self, p: np.ndarray, tol: float):
        self.p = p
        self.tol = tol
        self.tris: list[tuple[int, int, int]] = []
        cap = 64
        self.n = np.zeros((cap, 3))
        self.d = np.zeros(cap)
        self.alive = np.zeros(cap, dtype=bool)
        self.edge_face: dict[tuple[int, int], int] = {}

    def add(self, tris: list[tuple[int, int, int]]) -> np.ndarray:
        """Add triangles (CCW from outside); return their ids."""
        p = self.p
        t = np.array(tris, dtype=np.int64).reshape(-1, 3)
        n = cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
        norm = np.linalg.norm(n, axis=1)
        if np.any(norm == 0.0):
            raise GeometryError("hull construction produced a degenerate triangle")
        n /= norm[:, None]
        f0 = len(self.tris)
        ids = np.arange(f0, f0 + len(t))
        if ids[-1] >= len(self.d):
            cap = 2 * (ids[-1] + 1)
            self.n = np.concatenate([self.n, np.zeros((cap - len(self.d), 3))])
            self.alive = np.concatenate([self.alive, np.zeros(cap - len(self.d), dtype=bool)])
            self.d = np.concatenate([self.d, np.zeros(cap - len(self.d))])
        self.n[ids] = n
        self.d[ids] = np.einsum("ij,ij->i", n, p[t[:, 0]] + p[t[:, 1]] + p[t[:, 2]]) / 3.0
        self.alive[ids] = True
        for f, (a, b, c) in zip(ids.tolist(), t.tolist(), strict=True):
            self.tris.append((a, b, c))
            for e in ((a, b), (b, c), (c, a)):
                if e in self.edge_face:
                    raise GeometryError(
                        "hull construction failed: edge used twice (degenerate input)"
                    )
                self.edge_face[e] = f
        return ids

    def remove(self, f: int) -> None:
        a, b, c = self.tris[f]
        self.alive[f] = False
        for e in ((a, b), (b, c), (c, a)):
            del self.edge_face[e]

    def dist(self, f: int, x: np.ndarray) -> float:
        return float(self.n[f] @ x) - self.d[f]

    def neighbors(self, f: int):
        a, b, c = self.tris[f]
        return [
            ((a, b), self.edge_face[(b, a)]),
            ((b, c), self.edge_face[(c, b)]),
            ((c, a), self.edge_face[(a, c)]),
        ]

    def horizon(self, seed: int, x: np.ndarray, thresh: float):
        """Visible faces (connected to ``seed``) and the horizon loop, or None if not a disk."""
        vis = {seed}
        queue = deque([seed])
        while queue:
            f = queue.popleft()
            for _, g in self.neighbors(f):
                if g not in vis and self.dist(g, x) > thresh:
                    vis.add(g)
                    queue.append(g)
        hor = [e for f in sorted(vis) for e, g in self.neighbors(f) if g not in vis]
        nxt = dict(hor)
        if len(nxt) != len(hor) or len(set(nxt.values())) != len(hor):
            return None
        # The horizon must be a single loop, otherwise the visible region is not a disk.
        start = hor[0][0]
        v, n = nxt[start], 1
        while v != start and n <= len(hor):
            v, n = nxt[v], n + 1
        if n != len(hor):
            return None
        return vis, hor


def _initial_simplex(p: np.ndarray, tol: float) -> list[int]:
    axis = int(np.argmax(p.max(axis=0) - p.min(axis=0)))
    i0 = int(np.argmin(p[:, axis]))
    i1 = int(np.argmax(np.linalg.norm(p - p[i0], axis=1)))
    if np.linalg.norm(p[i1] - p[i0]) <= tol:
        raise GeometryError("all points coincide: the polyhedron has zero volume")
    u = _unit(p[i1] - p[i0])
    r = p - p[i0]
    perp = r - np.outer(r @ u, u)
    i2 = int(np.argmax(np.linalg.norm(perp, axis=1)))
    if np.linalg.norm(perp[i2]) <= tol:
        raise GeometryError("all points are collinear: the polyhedron has zero volume")
    n = _unit(cross(p[i1] - p[i0], p[i2] - p[i0]))
    h = r @ n
    i3 = int(np.argmax(np.abs(h)))
    if abs(h[i3]) <= tol:
        raise GeometryError("all points are coplanar: the polyhedron has zero volume")
    if h[i3] > 0.0:  # make (i0, i1, i2) face away from i3
        i1, i2 = i2, i1
    return [i0, i1, i2, i3]


def _triangulated_hull(p: np.ndarray, tol: float, active: np.ndarray) -> _TriHull:
    idx = np.flatnonzero(active)
    s = _initial_simplex(p[idx], tol)
    a, b, c, d = (int(idx[k]) for k in s)
    hull = _TriHull(p, tol)
    new = hull.add([(a, b, c), (a, d, b), (b, d, c), (c, d, a)])
    in_hull = np.zeros(len(p), dtype=bool)
    in_hull[[a, b, c, d]] = True
    # Quickhull-style conflict lists: each outside point is owned by one face it sees.
    cand = np.flatnonzero(active & ~in_hull)
    owner = np.zeros(len(cand), dtype=np.int64)
    odist = np.zeros(len(cand))
    orphan = np.ones(len(cand), dtype=bool)
    while True:
        if np.any(orphan):
            # Points whose face was removed can only see the faces just created; points
            # that see none of them are inside for good (the hull only grows): drop them.
            dist = p[cand[orphan]] @ hull.n[new].T - hull.d[new]
            k = np.argmax(dist, axis=1)
            owner = np.concatenate([owner[~orphan], new[k]])
            odist = np.concatenate([odist[~orphan], dist[np.arange(len(k)), k]])
            cand = np.concatenate([cand[~orphan], cand[orphan]])
            keep = odist > tol
            cand, owner, odist = cand[keep], owner[keep], odist[keep]
        if not len(cand):
            break
        j = int(np.argmax(odist))  # farthest point first: extreme points before face points
        pj = int(cand[j])
        x = p[pj]
        res = hull.horizon(int(owner[j]), x, tol)
        if res is None:
            res = hull.horizon(int(owner[j]), x, 0.0)
        if res is None:
            raise GeometryError("hull construction failed: visible region is not a disk")
        vis, hor = res
        for f in vis:
            hull.remove(f)
        new = hull.add([(e0, e1, pj) for e0, e1 in hor])
        cand, owner, odist = np.delete(cand, j), np.delete(owner, j), np.delete(odist, j)
        orphan = ~hull.alive[owner]
    return hull


def _polygon_2d(xy: np.ndarray, tol: float) -> list[int]:
    """Counter-clockwise convex hull (indices into ``xy``), collinear points dropped."""
    order = np.lexsort((xy[:, 1], xy[:, 0]))

    def cross(o, a, b):
        return (xy[a, 0] - xy[o, 0]) * (xy[b, 1] - xy[o, 1]) - (xy[a, 1] - xy[o, 1]) * (
            xy[b, 0] - xy[o, 0]
        )

    def chain(seq):
        h: list[int] = []
        for k in seq:
            # cross/|ob| is the distance of the middle point from line o-b.
            while len(h) >= 2 and cross(h[-2], h[-1], k) <= tol * np.hypot(*(xy[k] - xy[h[-2]])):
                h.pop()
            h.append(int(k))
        return h

    lower = chain(order)
    upper = chain(order[::-1])
    poly = lower[:-1] + upper[:-1]
    # The lexicographic extremes are never popped by the chains; drop them here if they are
    # within tol of the line through their neighbours.
    changed = True
    while changed and len(poly) > 3:
        changed = False
        for i in range(len(poly)):
            o, a, b = poly[i - 1], poly[i], poly[(i + 1) % len(poly)]
            if cross(o, a, b) <= tol * np.hypot(*(xy[b] - xy[o])):
                poly.pop(i)
                changed = True
                break
    return poly


def _merge_faces(hull: _TriHull, tol: float) -> tuple[list[list[int]], set[int]]:
    """Group coplanar triangles into convex polygons; also return the dropped vertices."""
    p = hull.p
    faces = [f for f in range(len(hull.tris)) if hull.alive[f]]
    tris = np.array([hull.tris[f] for f in faces])
    area2 = np.linalg.norm(
        cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]]), axis=1
    )
    local = {f: k for k, f in enumerate(faces)}
    group = np.full(len(faces), -1)
    polys: list[list[int]] = []
    dropped: set[int] = set()
    for s in np.argsort(-area2, kind="stable"):
        if group[s] >= 0:
            continue
        # The largest unassigned triangle defines the plane: its normal is the best
        # conditioned; members must lie within tol of that plane (no drift along a chain).
        ns, ds = hull.n[faces[s]], hull.d[faces[s]]
        gid = len(polys)
        group[s] = gid
        members = [s]
        queue = deque([s])
        while queue:
            k = queue.popleft()
            for _, g in hull.neighbors(faces[k]):
                t = local[g]
                if group[t] >= 0 or hull.n[g] @ ns <= 0.0:
                    continue
                if np.max(np.abs(p[tris[t]] @ ns - ds)) <= tol:
                    group[t] = gid
                    members.append(t)
                    queue.append(t)
        if len(members) == 1:  # a lone triangle is already a convex CCW polygon
            polys.append([int(i) for i in tris[s]])
            continue
        mt = tris[members]
        verts = np.unique(mt)
        n = cross(p[mt[:, 1]] - p[mt[:, 0]], p[mt[:, 2]] - p[mt[:, 0]]).sum(axis=0)
        n = _unit(n)
        u = _unit(cross(n, np.eye(3)[int(np.argmin(np.abs(n)))]))
        v = cross(n, u)  # (u, v, n) right-handed: CCW in (u, v) is CCW seen from outside
        xy = np.stack([p[verts] @ u, p[verts] @ v], axis=1)
        ring = _polygon_2d(xy, tol)
        kept = verts[ring]
        dropped.update(int(i) for i in set(verts.tolist()) - set(kept.tolist()))
        polys.append([int(i) for i in kept])
    return polys, dropped


def hull_faces(points, tol: float | None) -> tuple[np.ndarray, list[list[int]], float]:
    """Hull of ``points``: used point indices (ascending) and faces over those indices."""
    p0 = _as_points(points)
    tol = default_tolerance(p0) if tol is None else float(tol)
    # Work about the mean so plane offsets carry little round-off.
    p = p0 - p0.mean(axis=0)
    active = np.ones(len(p), dtype=bool)
    for _ in range(8):
        hull = _triangulated_hull(p, tol, active)
        polys, dropped = _merge_faces(hull, tol)
        kept = {i for poly in polys for i in poly}
        # A point may be collinear (within tol) on one face yet a corner of another; that
        # leaves a T-junction. It is within tol of the hull of the others, so drop it and redo.
        bad = kept & dropped
        if not bad:
            break
        active[sorted(bad)] = False
    else:
        raise GeometryError("convex hull did not converge (near-degenerate point set)")
    used = np.array(sorted(kept), dtype=np.int64)
    remap = np.full(len(p), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    faces = []
    for poly in polys:
        ids = remap[poly]
        r = int(np.argmin(ids))  # start each face at its smallest id: deterministic output
        faces.append(np.roll(ids, -r))
    return used, faces, tol


def convex_hull(points, tol: float | None = None) -> ConvexPolyhedron:
    """Convex hull of a 3D point set as a :class:`ConvexPolyhedron`.

    Coplanar facets are merged into single convex polygons (a box gives 6 quads); interior
    points and points on faces or edges are dropped. Vertices keep the input order of the
    points that survive.

    Parameters
    ----------
    points : (n, 3) array_like
        Point coordinates, ``n >= 4``.
    tol : float, optional
        Absolute distance tolerance; default :func:`default_tolerance` (relative to the
        point-cloud size).

    Returns
    -------
    ConvexPolyhedron

    Raises
    ------
    GeometryError
        Fewer than 4 points, NaN/inf, or all points coincident/collinear/coplanar.
    """
    p = _as_points(points)
    used, faces, _ = hull_faces(p, tol)
    return ConvexPolyhedron.from_faces(p[used], faces)


def hull_vertex_indices(points, tol: float | None = None) -> np.ndarray:
    """Indices (ascending) of the input points that are vertices of the convex hull."""
    return hull_faces(points, tol)[0]


def check_convex(points, tol: float | None = None, boundary: bool = False) -> np.ndarray:
    """Indices of input points that are not corners of the convex hull of all the points.

    With ``boundary=False`` (default) only points strictly inside the hull are reported: a
    vertex list with such a point cannot be a convex polyhedron, and the config layer
    reports e.g. "vertex 5 is not on the convex hull". Points of a non-convex solid can also
    land exactly on a hull face (the re-entrant corner of an L-shaped prism lies on the
    hull's bottom face); ``boundary=True`` reports those too, i.e. every point that is not a
    hull vertex (interior, on a face or edge, or a duplicate).

    Parameters
    ----------
    points : (n, 3) array_like
    tol : float, optional
        A point counts as strictly inside if it is more than ``tol`` below every face plane;
        default :func:`default_tolerance`.
    boundary : bool
        Also report points on the hull boundary that are not hull vertices.

    Returns
    -------
    (k,) int64
        Point indices, ascending.
    """
    p = _as_points(points)
    tol = default_tolerance(p) if tol is None else float(tol)
    used, faces, _ = hull_faces(p, tol)
    if boundary:
        return np.setdiff1d(np.arange(len(p)), used).astype(np.int64)
    poly = ConvexPolyhedron.from_faces(p[used], faces)
    dist = p @ poly.normals.T - poly.offsets
    return np.flatnonzero(dist.max(axis=1) < -tol).astype(np.int64)


def is_convex_point_set(points, tol: float | None = None) -> bool:
    """True if no input point lies strictly inside the hull of the others (see check_convex)."""
    return len(check_convex(points, tol)) == 0
