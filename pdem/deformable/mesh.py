"""Tetrahedral zoning of one convex block: nodes, positively oriented tets, surface triangles.

Method (no scipy, no external mesher):

1. **Cone.** Every face (CCW from outside) is fanned into triangles from its vertex mean, and
   every surface triangle is coned to the block's centroid. For a convex polyhedron both
   points are strictly inside their face / the block, so every cone tet has positive volume
   and the tets partition the block exactly (their volumes sum to the block's volume up to
   round-off; no point location, no Delaunay predicates).
2. **Refine by longest-edge bisection.** While the longest edge of the mesh is longer than
   ``size``, that edge is split at its midpoint and *every* tet containing it is split in two
   (one keeps the edge's first end, the other its second). Because the edge split is the
   longest of the whole mesh it is also the longest edge of each tet containing it, so this
   is Rivara's longest-edge bisection, and splitting all tets around the edge keeps the mesh
   conforming at every stage. Replacing a vertex by a point on its edge keeps the sign of a
   tet's volume, so orientation is preserved exactly.

Why bisection rather than uniform red (1->8) refinement: uniform refinement halves *every*
edge per level, so an elongated block (a 0.25 x 0.25 x 2 m column) would be refined until its
longest cone edge met ``size`` and its short directions would be over-refined by the aspect
ratio cubed. Longest-edge bisection only splits what is too long, and its shape degradation
is bounded in practice (the tests report the minimum dihedral angle).

Determinism: the edge queue is keyed on (-squared length, node ids); midpoints are keyed by
the edge's node pair (never by coordinates), so shared nodes are exact and the same input
gives a bitwise identical mesh.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TetMesh:
    """A block's zoning.

    nodes : (n, 3) float64 gridpoint positions; the block's vertices come first (same order),
        then the face centres, the centroid, then the midpoints in creation order.
    tets : (m, 4) int64 node ids, positively oriented (``(x1-x0).((x2-x0)x(x3-x0)) > 0``).
    surface : (k, 3) int64 node ids of boundary triangles, CCW seen from outside.
    surface_face : (k,) int64 index of the block face each surface triangle lies on.
    on_surface : (n,) bool, the gridpoint lies on the block's boundary.
    """

    nodes: np.ndarray
    tets: np.ndarray
    surface: np.ndarray
    surface_face: np.ndarray
    on_surface: np.ndarray


def signed_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volume of every tet (positive for the orientation of :class:`TetMesh`)."""
    x0 = nodes[tets[:, 0]]
    return np.einsum("ij,ij->i", nodes[tets[:, 1]] - x0,
                     np.cross(nodes[tets[:, 2]] - x0, nodes[tets[:, 3]] - x0)) / 6.0


def min_dihedral_angles(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Smallest dihedral angle (degrees) of every tet: the usual shape measure (0 = flat)."""
    x = nodes[tets]  # (m, 4, 3)
    # outward-ish face normals: face i is opposite vertex i
    faces = ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))
    nrm = np.stack([np.cross(x[:, b] - x[:, a], x[:, c] - x[:, a]) for a, b, c in faces], axis=1)
    nrm /= np.linalg.norm(nrm, axis=2, keepdims=True)
    worst = np.full(len(tets), np.pi)
    for i in range(4):
        for j in range(i + 1, 4):
            cosang = -np.einsum("ij,ij->i", nrm[:, i], nrm[:, j])
            worst = np.minimum(worst, np.arccos(np.clip(cosang, -1.0, 1.0)))
    return np.degrees(worst)


def _cone(poly) -> tuple[list[np.ndarray], list[list[int]]]:
    """Nodes and tets of step 1 (face fans coned to the centroid)."""
    verts = np.asarray(poly.vertices, dtype=np.float64)
    nodes = [v.copy() for v in verts]
    fs, fv = np.asarray(poly.face_start), np.asarray(poly.face_verts)
    centroid_id = len(verts) + len(fs) - 1
    tets = []
    for f in range(len(fs) - 1):
        ids = [int(i) for i in fv[fs[f]:fs[f + 1]]]
        nodes.append(verts[ids].mean(axis=0))
        fc = len(nodes) - 1
        for k in range(len(ids)):
            # (c, fc, a, b) is positive for a face CCW from outside (see module doc)
            tets.append([centroid_id, fc, ids[k], ids[(k + 1) % len(ids)]])
    nodes.append(np.asarray(poly.centroid, dtype=np.float64).copy())
    return nodes, tets


def _edges_of(t):
    a, b, c, d = t
    return ((a, b), (a, c), (a, d), (b, c), (b, d), (c, d))


def _key(a: int, b: int) -> tuple[int, int]:
    return (a, b) if a < b else (b, a)


def _bisect(nodes: list, tets: list, size: float) -> None:
    """Step 2 in place: longest-edge bisection until no edge is longer than ``size``."""
    edge_tets: dict[tuple[int, int], set[int]] = {}
    heap: list = []

    def length2(e):
        d = nodes[e[0]] - nodes[e[1]]
        return float(d @ d)

    def add(t_id):
        for a, b in _edges_of(tets[t_id]):
            e = _key(a, b)
            if e not in edge_tets:
                edge_tets[e] = set()
                heapq.heappush(heap, (-length2(e), e))
            edge_tets[e].add(t_id)

    def remove(t_id):
        for a, b in _edges_of(tets[t_id]):
            around = edge_tets.get(_key(a, b))
            if around is not None:  # None: the edge being split, already taken off
                around.discard(t_id)

    for t_id in range(len(tets)):
        add(t_id)
    limit2 = size * size
    while heap:
        neg_l2, e = heap[0]
        if -neg_l2 <= limit2:
            break
        heapq.heappop(heap)
        around = edge_tets.pop(e, None)
        if not around:
            continue  # already split (stale queue entry)
        a, b = e
        nodes.append(0.5 * (nodes[a] + nodes[b]))
        m = len(nodes) - 1
        for t_id in sorted(around):  # sorted: deterministic new tet numbering
            t = tets[t_id]
            remove(t_id)
            first = [m if v == b else v for v in t]   # keeps a
            second = [m if v == a else v for v in t]  # keeps b
            tets[t_id] = first
            add(t_id)
            tets.append(second)
            add(len(tets) - 1)


def boundary_triangles(tets: np.ndarray) -> np.ndarray:
    """The tet faces used once (the grid's boundary), ``(k, 3)`` gridpoint ids, CCW seen from
    outside for positively oriented tets, in tet order (deterministic: the same tets give the
    same triangles). ``TetMesh.surface`` is these; the output's deformed surface too
    (pdem.io.zone_surfaces)."""
    tets = np.asarray(tets, np.int64).reshape(-1, 4)
    # face opposite vertex i, ordered so that it is CCW seen from outside the tet
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    tri = tets[:, local].reshape(-1, 3)
    key = np.sort(tri, axis=1)
    _, first, count = np.unique(key, axis=0, return_index=True, return_counts=True)
    boundary = np.sort(first[count == 1])  # sorted: tet order, deterministic
    return tri[boundary]


def _surface(nodes: np.ndarray, tets: np.ndarray, poly):
    """Boundary triangles (tet faces used once), oriented outward, with their block face."""
    surface = boundary_triangles(tets)
    centre = nodes[surface].mean(axis=1)
    dist = np.abs(centre @ np.asarray(poly.normals).T - np.asarray(poly.offsets)[None, :])
    surface_face = np.argmin(dist, axis=1).astype(np.int64)
    on_surface = np.zeros(len(nodes), dtype=bool)
    on_surface[surface.ravel()] = True
    return surface.astype(np.int64), surface_face, on_surface


def tetrahedralise(poly, size: float) -> TetMesh:
    """Zone a convex polyhedron into tets whose edges are all ``<= size`` (see module doc)."""
    if not size > 0.0:
        raise ValueError(f"zone size must be positive, got {size}")
    nodes, tets = _cone(poly)
    _bisect(nodes, tets, float(size))
    node_arr = np.array(nodes, dtype=np.float64)
    tet_arr = np.array(tets, dtype=np.int64)
    surface, surface_face, on_surface = _surface(node_arr, tet_arr, poly)
    return TetMesh(node_arr, tet_arr, surface, surface_face, on_surface)
