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


def identity_frames(geometry: dict, arr: dict, specs) -> None:
    """Zoned rows of a freshly built store: pose the identity (the body frame is the world
    frame shifted to the centroid), piece geometry in that frame, and every edge its own
    direction (the fast common plane's directions; merging parallel ones would change their
    count as the surface deforms)."""
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
        ends = g["verts_local"][g["edges"][e0:e1]]
        d = ends[:, 1] - ends[:, 0]
        dirs.append(d / np.linalg.norm(d, axis=1)[:, None])
        counts.append(e1 - e0)
    # one-piece blocks only reach here with zones (joined zoned blocks are refused)
    g["edirs_local"] = np.concatenate(dirs).reshape(-1, 3) if dirs else g["edirs_local"]
    g["edir_start"] = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
