"""Half-edge connectivity of a closed polygonal surface.

Half-edges are numbered like ``face_verts``: half-edge ``h`` leaves vertex ``face_verts[h]``
and runs to the next vertex of the same face, so the CSR face layout doubles as the half-edge
layout and no extra permutation has to be stored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pdem.geometry.errors import GeometryError
from pdem.jit import kernel


@dataclass(frozen=True, eq=False)
class HalfEdges:
    """Half-edge arrays; see :func:`build_half_edges`."""

    origin: np.ndarray
    twin: np.ndarray
    next: np.ndarray
    face: np.ndarray
    vert_he: np.ndarray
    edges: np.ndarray


def build_half_edges(nv: int, face_start: np.ndarray, face_verts: np.ndarray) -> HalfEdges:
    """Build half-edge adjacency and the unique edge list, checking the surface is closed.

    Parameters
    ----------
    nv : int
        Number of vertices.
    face_start, face_verts : int64
        Faces in CSR form, each counter-clockwise seen from outside.

    Returns
    -------
    HalfEdges
        ``origin[h]`` start vertex, ``twin[h]`` the opposite half-edge, ``next[h]`` the
        following half-edge around the same face, ``face[h]`` its face, ``vert_he[v]`` one
        half-edge leaving ``v``, ``edges`` (ne, 2) unique ``(i, j)`` with ``i < j``, sorted.

    Raises
    ------
    GeometryError
        If the faces do not form a closed, consistently oriented 2-manifold in which every
        vertex is used.
    """
    fs = np.ascontiguousarray(face_start, dtype=np.int64)
    fv = np.ascontiguousarray(face_verts, dtype=np.int64)
    nf = len(fs) - 1
    counts = np.diff(fs)
    if nf < 4 or np.any(counts < 3) or fs[0] != 0 or fs[-1] != len(fv):
        raise GeometryError("faces must be at least 4 polygons of at least 3 vertices each")
    code, at, twin, nxt, face, vert_he, edges = _half_edges(int(nv), fs, fv)
    if code:
        raise GeometryError(_ERRORS[code].format(at=at))
    return HalfEdges(fv, twin, nxt, face, vert_he, edges)


def cut_piece_edges(nv: int, face_start: np.ndarray, face_verts: np.ndarray) -> np.ndarray:
    """The sorted unique edges of a closed surface (:func:`build_half_edges`'s ``edges``),
    its vertex ids checked first (in range, else "face vertex id out of range", as
    pdem.geometry.polyhedron.ConvexPolyhedron.from_csr does), then the same checks and
    errors; without the half-edge record. For the arrays of a cut piece (int64, contiguous):
    every piece of a rock mass comes through here (~20 us of numpy checks a piece)."""
    code = _csr_code(int(nv), face_start, face_verts)
    if code == 1:
        raise GeometryError("face vertex id out of range")
    if code == 2:
        raise GeometryError("faces must be at least 4 polygons of at least 3 vertices each")
    code, at, _, _, _, _, edges = _half_edges(int(nv), face_start, face_verts)
    if code:
        raise GeometryError(_ERRORS[code].format(at=at))
    return edges


@kernel
def _csr_code(nv, fs, fv):
    """0 if faces ``fs``/``fv`` over ``nv`` vertices are at least 4 polygons of at least 3
    valid vertex ids each; 1: a vertex id out of range; 2: too few faces or corners."""
    for h in range(fv.shape[0]):
        if fv[h] < 0 or fv[h] >= nv:
            return 1
    nf = fs.shape[0] - 1
    if nf < 4 or fs[0] != 0 or fs[nf] != fv.shape[0]:
        return 2
    for f in range(nf):
        if fs[f + 1] - fs[f] < 3:
            return 2
    return 0


# what :func:`_half_edges` found wrong, by its code (``at``: a vertex or Euler's sum)
_ERRORS = {
    1: "a face repeats a vertex consecutively",
    2: "a directed edge is used by two faces (inconsistent orientation)",
    3: "surface is not closed: an edge has only one adjacent face",
    4: "a vertex is not used by any face",
    5: "Euler characteristic V - E + F = {at}, expected 2 (surface is not a topological sphere)",
    6: "vertex {at} is not manifold (faces around it form >1 fan)",
}


@kernel
def _half_edges(nv, fs, fv):
    """:func:`build_half_edges` compiled, returning ``(code, at, twin, next, face, vert_he,
    edges)`` with ``code`` 0 or an :data:`_ERRORS` key. Every cut piece of a rock mass is
    made through here (numpy's per-call overhead was ~80 us a piece)."""
    nf = fs.shape[0] - 1
    nh = fv.shape[0]
    face = np.empty(nh, np.int64)
    nxt = np.empty(nh, np.int64)
    for f in range(nf):
        for h in range(fs[f], fs[f + 1]):
            face[h] = f
            nxt[h] = h + 1 if h + 1 < fs[f + 1] else fs[f]
    empty = np.empty((0, 2), np.int64)
    dest = np.empty(nh, np.int64)
    for h in range(nh):
        dest[h] = fv[nxt[h]]
        if fv[h] == dest[h]:
            return 1, 0, nxt, nxt, face, nxt, empty
    # Each directed edge must occur exactly once, and its reverse exactly once: that is the
    # closed, consistently oriented manifold condition. (Sorted keys: a hull of a scanned
    # boulder can have 10^4 faces, where a scan of every pair would take seconds.)
    key = np.empty(nh, np.int64)
    for h in range(nh):
        key[h] = fv[h] * nv + dest[h]
    order = np.argsort(key, kind="mergesort")
    skey = key[order]
    for i in range(1, nh):
        if skey[i] == skey[i - 1]:
            return 2, 0, nxt, nxt, face, nxt, empty
    twin = np.empty(nh, np.int64)
    for h in range(nh):
        r = dest[h] * nv + fv[h]
        pos = np.searchsorted(skey, r)
        if pos >= nh or skey[pos] != r:
            return 3, 0, nxt, nxt, face, nxt, empty
        twin[h] = order[pos]
    vert_he = np.full(nv, -1, np.int64)
    for h in range(nh - 1, -1, -1):  # the first half-edge leaving each vertex (deterministic)
        vert_he[fv[h]] = h
    for v in range(nv):
        if vert_he[v] < 0:
            return 4, 0, twin, nxt, face, vert_he, empty
    ne = 0
    for h in range(nh):
        ne += 1 if fv[h] < dest[h] else 0
    key = np.empty(ne, np.int64)
    k = 0
    for h in range(nh):
        if fv[h] < dest[h]:
            key[k] = fv[h] * nv + dest[h]
            k += 1
    key = np.sort(key)
    edges = np.empty((ne, 2), np.int64)
    for k in range(ne):
        edges[k, 0] = key[k] // nv
        edges[k, 1] = key[k] % nv
    if nv - ne + nf != 2:
        return 5, nv - ne + nf, twin, nxt, face, vert_he, edges
    # Vertex manifoldness: walking twin/next around each vertex must visit all its half-edges.
    degree = np.zeros(nv, np.int64)
    for h in range(nh):
        degree[fv[h]] += 1
    for v in range(nv):
        h0 = vert_he[v]
        h = h0
        n = 0
        while True:
            n += 1
            h = nxt[twin[h]]
            if h == h0 or n > degree[v]:
                break
        if n != degree[v]:
            return 6, v, twin, nxt, face, vert_he, edges
    return 0, 0, twin, nxt, face, vert_he, edges
