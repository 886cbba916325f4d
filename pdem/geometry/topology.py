"""Half-edge connectivity of a closed polygonal surface.

Half-edges are numbered like ``face_verts``: half-edge ``h`` leaves vertex ``face_verts[h]``
and runs to the next vertex of the same face, so the CSR face layout doubles as the half-edge
layout and no extra permutation has to be stored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pdem.geometry.errors import GeometryError


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
    fs = np.asarray(face_start, dtype=np.int64)
    fv = np.asarray(face_verts, dtype=np.int64)
    nf = len(fs) - 1
    nh = len(fv)
    counts = np.diff(fs)
    if nf < 4 or np.any(counts < 3) or fs[0] != 0 or fs[-1] != nh:
        raise GeometryError("faces must be at least 4 polygons of at least 3 vertices each")
    face = np.repeat(np.arange(nf, dtype=np.int64), counts)
    local = np.arange(nh, dtype=np.int64) - fs[face]
    nxt = fs[face] + (local + 1) % counts[face]
    origin = fv
    dest = fv[nxt]
    if np.any(origin == dest):
        raise GeometryError("a face repeats a vertex consecutively")
    # Each directed edge must occur exactly once, and its reverse exactly once: that is the
    # closed, consistently oriented manifold condition.
    key = origin * nv + dest
    order = np.argsort(key, kind="stable")
    skey = key[order]
    if np.any(skey[1:] == skey[:-1]):
        raise GeometryError("a directed edge is used by two faces (inconsistent orientation)")
    rkey = dest * nv + origin
    pos = np.searchsorted(skey, rkey)
    pos_c = np.minimum(pos, nh - 1)
    if np.any(skey[pos_c] != rkey):
        raise GeometryError("surface is not closed: an edge has only one adjacent face")
    twin = order[pos_c]
    vert_he = np.full(nv, -1, dtype=np.int64)
    # Reverse order so the first half-edge leaving each vertex wins (deterministic choice).
    vert_he[origin[::-1]] = np.arange(nh - 1, -1, -1, dtype=np.int64)
    if np.any(vert_he < 0):
        raise GeometryError("a vertex is not used by any face")
    fwd = origin < dest
    edges = np.stack([origin[fwd], dest[fwd]], axis=1)
    edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
    if nv - len(edges) + nf != 2:
        raise GeometryError(
            f"Euler characteristic V - E + F = {nv - len(edges) + nf}, expected 2 "
            "(surface is not a topological sphere)"
        )
    # Vertex manifoldness: walking twin/next around each vertex must visit all its half-edges.
    degree = np.bincount(origin, minlength=nv)
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
            raise GeometryError(f"vertex {v} is not manifold (faces around it form >1 fan)")
    return HalfEdges(origin, twin, nxt, face, vert_he, edges)
