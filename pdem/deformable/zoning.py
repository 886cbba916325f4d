"""Zoning a scene's blocks: a zoned block's shape becomes its surface grid (a polyhedron of
surface triangles), and its rows in a fresh store take the identity frame."""

from __future__ import annotations

import numpy as np

from ..config.errors import ConfigError
from ..geometry.polyhedron import ConvexPolyhedron
from .mesh import tetrahedralise


def surface_polyhedron(poly: ConvexPolyhedron, mesh) -> tuple[ConvexPolyhedron, np.ndarray]:
    """The block as its surface grid: vertices the surface gridpoints (ascending node id),
    faces the surface triangles (in ``mesh.surface`` order) on their block face's exact plane.
    Returns (polyhedron, surface node ids)."""
    surf_nodes = np.unique(mesh.surface)
    tris = np.searchsorted(surf_nodes, mesh.surface)
    normals = np.asarray(poly.normals)[mesh.surface_face]
    offsets = np.asarray(poly.offsets)[mesh.surface_face]
    return ConvexPolyhedron.from_faces(mesh.nodes[surf_nodes], list(tris), normals, offsets), \
        surf_nodes


def zone_specs(scene, specs) -> None:
    """Zone every zoned block's shape (``blocks[i].zones``): its spec's one piece becomes the
    surface polyhedron, ``spec.zoning`` the (mesh, surface node ids). Specs without pieces
    (outside a build share) are left alone."""
    errors = []
    for s in specs:
        z = s.spec.zones
        if z is None or s.pieces is None:
            continue
        if len(s.pieces) != 1:
            errors.append(f"blocks[{s.entry}] ({s.name!r}).zones: the block is joined from "
                          f"{len(s.pieces)} convex pieces; zoned blocks must be convex yet")
            continue
        mesh = tetrahedralise(s.pieces[0], z.size)
        poly, surf = surface_polyhedron(s.pieces[0], mesh)
        s.pieces = [poly]
        s.zoning = (mesh, surf)
    if errors:
        raise ConfigError(errors)


def direction_edges(mesh, surf_nodes: np.ndarray, verts: np.ndarray,
                    tol: float = 1e-9) -> np.ndarray:
    """The surface edges whose directions stand for the zoned block's edge directions (the
    fast common plane's edge candidates), as surface-vertex pairs: one segment of the
    block's own edges (surface edges between triangles on two block faces) per set of
    parallel ones, at the built geometry. Every surface edge would make the plane search
    quadratic in the grid's surface (a 2,000-triangle face against another: ~0.4 s per
    contact update); the count is fixed at build, so it never changes as the surface deforms."""
    tris = np.searchsorted(surf_nodes, mesh.surface)
    a = tris.reshape(-1)
    b = np.roll(tris, -1, axis=1).reshape(-1)
    face = np.repeat(mesh.surface_face, 3)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((hi, lo))
    lo, hi, face = lo[order], hi[order], face[order]
    # each surface edge twice (its two triangles, adjacent after the sort): a block edge
    # where their block faces differ
    first = np.arange(0, len(lo), 2)
    feature = first[face[first] != face[first + 1]]
    kept: list[np.ndarray] = []
    pairs = []
    for k in feature:
        d = verts[hi[k]] - verts[lo[k]]
        d = d / np.linalg.norm(d)
        if not any(abs(abs(float(d @ u)) - 1.0) < tol for u in kept):
            kept.append(d)
            pairs.append((lo[k], hi[k]))
    return np.array(pairs, np.int64).reshape(-1, 2)


def identity_frames(geometry: dict, arr: dict, specs) -> None:
    """Zoned rows of a freshly built store: pose the identity (the body frame is the world
    frame shifted to the centroid), piece geometry in that frame, and the edge directions of
    :func:`direction_edges`, whose edges are put first in the piece's edge rows
    (pdem.deformable.contact.refresh_pieces turns them with the surface)."""
    g = geometry
    dirs, counts = [], []
    for r, s in enumerate(specs):
        k = g["piece_start"][r]
        e0, e1 = g["edge_start"][k], g["edge_start"][k + 1]
        if getattr(s, "zoning", None) is None:
            dirs.append(g["edirs_local"][g["edir_start"][k]:g["edir_start"][k + 1]])
            counts.append(len(dirs[-1]))
            continue
        poly = s.pieces[0]
        c = arr["x"][r]
        v0, v1 = g["vert_start"][k], g["vert_start"][k + 1]
        f0, f1 = g["face_start"][k], g["face_start"][k + 1]
        g["verts_local"][v0:v1] = poly.vertices - c
        g["normals_local"][f0:f1] = poly.normals
        g["offsets_local"][f0:f1] = poly.offsets - poly.normals @ c
        arr["q"][r] = (1.0, 0.0, 0.0, 0.0)
        mesh, surf = s.zoning
        rep = direction_edges(mesh, surf, poly.vertices)
        edges = g["edges"][e0:e1] - v0
        key = np.minimum(edges[:, 0], edges[:, 1]) * v1 + np.maximum(edges[:, 0], edges[:, 1])
        at = np.nonzero(key[:, None] == (rep[:, 0] * v1 + rep[:, 1])[None, :])[0]
        rest = np.setdiff1d(np.arange(e1 - e0), at)
        g["edges"][e0:e1] = edges[np.concatenate([at, rest])] + v0
        ends = g["verts_local"][g["edges"][e0:e0 + len(at)]]
        d = ends[:, 1] - ends[:, 0]
        dirs.append(d / np.linalg.norm(d, axis=1)[:, None])
        counts.append(len(at))
    # one-piece blocks only reach here with zones (joined zoned blocks are refused)
    g["edirs_local"] = np.concatenate(dirs).reshape(-1, 3) if dirs else g["edirs_local"]
    g["edir_start"] = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
