"""Zoning a scene's blocks: a zoned block's shape becomes its surface grid (a polyhedron of
surface triangles), and its rows in a fresh store take the identity frame."""

from __future__ import annotations

import numpy as np

from ..config.errors import ConfigError
from ..geometry.polyhedron import ConvexPolyhedron
from .mesh import TetMesh, boundary_triangles, signed_volumes, tetrahedralise

# a mesh block's boundary triangles on one face: their unit normals within this of each other
# (1 - cos), their planes within this fraction of the body's size
PLANE_TOL = 1e-9


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


class _Planes:
    """The face planes a mesh block's surface triangles lie on (what :func:`surface_polyhedron`
    reads of a block's polyhedron)."""

    def __init__(self, normals: np.ndarray, offsets: np.ndarray):
        self.normals, self.offsets = normals, offsets


def tets_as_zones(pieces) -> tuple[TetMesh, _Planes]:
    """A ``mesh`` block's tetrahedral cells (its convex pieces, joined by the mesh's
    ``cell_data_group``) as the zones of one grid, as 3DEC imports a zoned mesh: gridpoints
    the cells' corners (shared where their coordinates are equal, as a mesh's shared nodes are),
    each tet positively oriented, the boundary triangles grouped into the body's faces by plane.
    ValueError naming what is wrong: a cell that is not a tetrahedron, a body that is not
    convex (its contacts take it as one convex piece)."""
    for k, p in enumerate(pieces):
        if len(p.vertices) != 4:
            raise ValueError(f"cell {k} of the block has {len(p.vertices)} corners: a zoned mesh "
                             "block's zones are its tetrahedral cells (mesh it with tetrahedra)")
    corners = np.concatenate([np.asarray(p.vertices, np.float64) for p in pieces])
    nodes, inverse = np.unique(corners, axis=0, return_inverse=True)
    tets = inverse.reshape(-1, 4).astype(np.int64)
    flip = signed_volumes(nodes, tets) < 0.0
    tets[flip] = tets[flip][:, [0, 1, 3, 2]]
    surface = boundary_triangles(tets)
    a, b, c = (nodes[surface[:, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = np.einsum("ij,ij->i", n, a)
    scale = float(np.ptp(nodes, axis=0).max())
    face = np.empty(len(surface), np.int64)
    normals: list[np.ndarray] = []
    offsets: list[float] = []
    for t in range(len(surface)):  # in triangle order: deterministic face numbering
        for f, (m, o) in enumerate(zip(normals, offsets, strict=True)):
            if 1.0 - float(n[t] @ m) < PLANE_TOL and abs(d[t] - o) < PLANE_TOL * scale:
                face[t] = f
                break
        else:
            face[t] = len(normals)
            normals.append(n[t])
            offsets.append(float(d[t]))
    planes = _Planes(np.array(normals), np.array(offsets))
    out = nodes @ planes.normals.T - planes.offsets[None, :]
    worst = np.unravel_index(int(np.argmax(out)), out.shape)
    if out[worst] > 1e-9 * scale:
        x = nodes[worst[0]]
        raise ValueError(
            f"its {len(tets)} tetrahedra make a concave body (the corner at "
            f"[{x[0]:.6g}, {x[1]:.6g}, {x[2]:.6g}] lies {out[worst]:.3g} m outside the plane of "
            "one of its boundary faces): a zoned mesh block must be convex; group its cells "
            "into convex blocks with cell_data_group")
    on_surface = np.zeros(len(nodes), bool)
    on_surface[surface.ravel()] = True
    return TetMesh(nodes, tets, surface, face, on_surface), planes


def zone_specs(scene, specs) -> None:
    """Zone every zoned block's shape (``blocks[i].zones``): its spec's one piece becomes the
    surface polyhedron, ``spec.zoning`` the (mesh, surface node ids); a ``mesh`` block's
    tetrahedral cells are its zones (:func:`tets_as_zones`). Specs without pieces (outside a
    build share) are left alone."""
    errors = []
    for s in specs:
        z = s.spec.zones
        if z is None or s.pieces is None:
            continue
        if s.spec.mesh is not None:
            try:
                mesh, planes = tets_as_zones(s.pieces)
            except ValueError as exc:
                errors.append(f"blocks[{s.entry}] ({s.name!r}).zones: {exc}")
                continue
            poly, surf = surface_polyhedron(planes, mesh)
            s.pieces = [poly]
            s.zoning = (mesh, surf)
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
        if getattr(s, "zoning", None) is None:  # rigid: each of its pieces' own directions
            for p in range(k, g["piece_start"][r + 1]):
                dirs.append(g["edirs_local"][g["edir_start"][p]:g["edir_start"][p + 1]])
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
    # (a zoned block is one piece: joined zoned blocks are refused, pdem.model.rockmass)
    g["edirs_local"] = np.concatenate(dirs).reshape(-1, 3) if dirs else g["edirs_local"]
    g["edir_start"] = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
