"""Scene -> blocks: shapes from the scene file, mass properties, the BlockStore."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import ConfigError
from ..config.schema import Block, BoxShape, Scene
from ..dynamics.rotation import quat_to_matrix
from ..geometry import (
    ConvexPolyhedron,
    GeometryError,
    box,
    check_convex,
    face_areas,
    from_planes,
    from_vertices,
    prism,
)
from ..registry import Registry
from .blocks import BlockStore
from .fields import BLOCK, allocate


@dataclass
class BlockSpec:
    """One expanded block of the scene: its name, convex pieces (world frame) and scene entry.

    Most blocks are one convex piece; a joined (concave) block is several, moving as one
    rigid body (3DEC's leader/follower groups). ``parent``: the name of the scene block it was
    cut from (its own name if uncut)."""

    name: str
    entry: int  # index in scene.blocks
    pieces: list[ConvexPolyhedron]
    spec: Block
    parent: str = ""
    # model time at which the block is excavated (None: it stays), see pdem.model.rockmass
    excavate_at: float | None = None
    # index of the stage whose start removes the block (None: no stage does)
    excavate_stage: int | None = None
    # group and material when not the scene entry's (mesh cells carry their own)
    group_name: str | None = None
    material_name: str | None = None

    @property
    def group(self) -> str:
        return self.group_name if self.group_name is not None else self.spec.group

    @property
    def material(self) -> str:
        return self.material_name if self.material_name is not None else self.spec.material

    @property
    def shape(self) -> ConvexPolyhedron:
        """The block's single convex piece (joined blocks have no single shape)."""
        if len(self.pieces) != 1:
            raise ValueError(f"block {self.name!r} is joined from {len(self.pieces)} pieces")
        return self.pieces[0]

    @property
    def volume(self) -> float:
        return sum(p.volume for p in self.pieces)

    @property
    def centroid(self) -> np.ndarray:
        return sum(p.volume * np.asarray(p.centroid) for p in self.pieces) / self.volume

    @property
    def face_areas(self) -> np.ndarray:
        return np.concatenate([p.face_areas() for p in self.pieces])

    def principal_frame(self):
        """(body-frame pieces, centroid, R, principal moments per unit density) of the rigid
        body; ``world = R @ body + centroid``. One piece: the piece's own principal frame."""
        if len(self.pieces) == 1:
            body, c, R, moments = self.pieces[0].principal_frame()
            return [body], c, R, moments
        c = self.centroid
        inertia = np.zeros((3, 3))
        for p in self.pieces:  # parallel-axis theorem, per unit density
            d = np.asarray(p.centroid) - c
            inertia += np.asarray(p.inertia) + p.volume * (d @ d * np.eye(3) - np.outer(d, d))
        moments, R = np.linalg.eigh(inertia)
        if np.linalg.det(R) < 0.0:
            R[:, 2] = -R[:, 2]
        return [p.transformed(R.T, -c @ R) for p in self.pieces], c, R, moments


def spec_face_areas(specs: list[BlockSpec]) -> list[np.ndarray]:
    """Face areas of every block (its pieces' faces in order), computed in one batch for all
    the blocks' pieces (pdem.geometry.polyhedron.face_areas), then kept on the pieces."""
    face_areas([p for s in specs for p in s.pieces])
    return [s.face_areas for s in specs]


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of rotation matrix R (Shepperd's method), w >= 0."""
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.empty(4)
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    if q[0] < 0:
        q = -q
    return q / np.linalg.norm(q)


def _random_hull(rng, diameter, nverts):
    for _ in range(100):
        pts = rng.normal(size=(nverts, 3))
        pts /= np.linalg.norm(pts, axis=1)[:, None]
        pts *= 0.5 * diameter
        try:
            poly = from_vertices(pts)
        except GeometryError:
            continue
        if poly.volume > 0.05 * diameter**3:  # reject slivers
            return poly
    raise GeometryError("could not generate a non-degenerate random polyhedron")


def _lattice(region: BoxShape, count: int, cell: float):
    lo = np.array(region.min)
    span = np.array(region.max) - lo
    per_axis = np.floor(span / cell)
    if not (per_axis < 2.0**62).all():
        # found by the fuzz: the cast to int overflowed (a numpy warning and a wrong count)
        raise ValueError(f"size {cell:g} m is too small for the region ({per_axis.max():.3g} "
                         "sites along one axis)")
    dims = np.maximum(per_axis.astype(int), 1)
    n_sites = math.prod(int(d) for d in dims)  # Python ints: np.prod wraps around silently
    if n_sites < count:
        raise ValueError(
            f"region holds only {n_sites} sites of size {cell:g}; count is {count}"
        )
    # the first ``count`` sites only: a large region of small sites has far more (1e18 would
    # never finish), and the order (x fastest) is the same
    sites = []
    for k in range(dims[2]):
        for j in range(dims[1]):
            for i in range(dims[0]):
                if len(sites) == count:
                    return sites
                sites.append(lo + (np.array([i, j, k]) + 0.5) * span / dims)
    return sites


def _box(p):
    yield None, box(p.min, p.max)


def _polyhedron(p):
    pts = np.asarray(p.vertices, float)
    if p.faces is not None:  # a closed surface, possibly concave: its convex pieces
        from ..geometry.concave import convex_pieces

        pieces = convex_pieces(pts, p.faces)
        yield None, pieces if len(pieces) > 1 else pieces[0]
        return
    inside = check_convex(pts, boundary=True)
    if len(inside):
        raise GeometryError(
            f"vertices {list(map(int, inside))} are not on the convex hull: the "
            "polyhedron is not convex (split a concave block into convex pieces)"
        )
    yield None, from_vertices(pts)


def _prism(p):
    yield None, prism(np.asarray(p.base, float), np.asarray(p.extrude, float))


def _planes(p):
    yield None, from_planes(np.asarray(p.normals, float), np.asarray(p.offsets, float))


def _array(a):
    base = box(a.box.min, a.box.max)
    k = 0
    for iz in range(a.count[2]):
        for iy in range(a.count[1]):
            for ix in range(a.count[0]):
                off = np.array([ix, iy, iz], float) * np.array(a.spacing)
                yield k, base.transformed(np.eye(3), off)
                k += 1


def _random(r):
    rng = np.random.default_rng(r.seed)
    for k, site in enumerate(_lattice(r.region, r.count, r.size[1])):
        d = rng.uniform(r.size[0], r.size[1])
        shape = _random_hull(rng, d, r.vertices)
        yield k, shape.transformed(np.eye(3), site - shape.centroid)


# Block shapes by scene key: each builder yields (member index or None, world-frame shape, or a
# list of convex pieces for a concave block) for its entry's parameters; a family (index given)
# names its members ``NAME[k]``. A new shape is its schema model (config/schema.py,
# SHAPE_KEYS) plus a builder and a line here.
SHAPES: Registry = Registry("block shape")
for _name, _builder in (("box", _box), ("polyhedron", _polyhedron), ("prism", _prism),
                        ("planes", _planes), ("array", _array), ("random", _random)):
    SHAPES.register(_name, _builder)


def expand_blocks(scene: Scene, max_blocks: int | None = None) -> list[BlockSpec]:
    """Every block of the scene in gid order, shapes in the world frame: the ``blocks:``
    entries, then their cuts, joins and excavations (pdem.model.rockmass)."""
    out: list[BlockSpec] = []
    errors: list[str] = []
    for i, b in enumerate(scene.blocks):
        kind = b.shape_kind
        if kind == "mesh":
            from .mesh_blocks import mesh_blocks

            out.extend(mesh_blocks(scene, i, b))
            continue
        try:
            for k, shape in SHAPES[kind](getattr(b, kind)):
                name = b.name if k is None else f"{b.name}[{k}]"
                pieces = shape if isinstance(shape, list) else [shape]
                out.append(BlockSpec(name, i, pieces, b, parent=name))
        except (GeometryError, ValueError) as exc:
            errors.append(f"blocks[{i}] ({b.name!r}).{kind}: {exc}")
    if errors:
        raise ConfigError(errors)
    from .rockmass import build_rock_mass

    return build_rock_mass(scene, out, max_blocks)


def _fixed(spec, arr, r):
    arr["fixed"][r] = spec.fixed


def _velocity(spec, arr, r):
    # a fixed block has no velocity; a prescribed one keeps it (velocity_fixed)
    arr["vfix"][r] = spec.velocity_fixed
    if not spec.fixed:
        arr["v"][r] = spec.velocity
        arr["w"][r] = spec.angular_velocity


def _force(spec, arr, r):
    arr["applied_force"][r] = spec.force


# Conditions on blocks by scene key: each sets the block's static fields (pdem.model.fields)
# from its ``blocks[i]`` entry; the motion kernel reads those fields.
BLOCK_CONDITIONS: Registry = Registry("block condition")
for _name, _apply in (("fixed", _fixed), ("velocity", _velocity), ("force", _force)):
    BLOCK_CONDITIONS.register(_name, _apply)


def block_store(scene: Scene, specs: list[BlockSpec]):
    """BlockStore of every block of the scene (gid order), body frame = principal axes;
    returns (store, sorted group names)."""
    n = len(specs)
    arr = allocate(BLOCK, n)
    mats = list(scene.materials)
    groups = sorted({b.group for b in scene.blocks if b.mesh is None} | {s.group for s in specs})
    vl, fn, fo, fv, fvs, ed, tags, centers = [], [], [], [], [0], [], [], []
    piece_start = [0]
    vert_start = [0]
    face_start = [0]
    edge_start = [0]
    edir_start = [0]
    edirs = []
    for r, s in enumerate(specs):
        bodies, centroid, R, moments = s.principal_frame()
        rho = scene.materials[s.material].density
        arr["gid"][r] = r
        arr["owned"][r] = 1
        arr["x"][r] = centroid
        arr["x0"][r] = centroid
        arr["x_stage"][r] = centroid
        arr["q"][r] = quat_from_matrix(R)
        arr["mass"][r] = rho * s.volume
        arr["inertia"][r] = rho * moments
        arr["mscale"][r] = 1.0
        arr["material"][r] = mats.index(s.material)
        arr["group"][r] = groups.index(s.group)
        for apply in BLOCK_CONDITIONS.values():
            apply(s.spec, arr, r)
        arr["radius"][r] = max(np.linalg.norm(body.vertices, axis=1).max() for body in bodies)
        piece_start.append(piece_start[-1] + len(bodies))
        for body in bodies:
            # a one-piece block's centre is its centroid: exactly zero in the body frame
            centers.append(np.zeros(3) if len(bodies) == 1 else np.asarray(body.centroid))
            v0 = vert_start[-1]
            vl.append(body.vertices)
            vert_start.append(v0 + body.n_vertices)
            fn.append(body.normals)
            fo.append(body.offsets)
            tags.append(body.face_tag if body.face_tag is not None
                        else np.full(body.n_faces, -1))
            for f in range(body.n_faces):
                ids = body.face_verts[body.face_start[f]:body.face_start[f + 1]] + v0
                fv.append(ids)
                fvs.append(fvs[-1] + len(ids))
            face_start.append(face_start[-1] + body.n_faces)
            ed.append(body.edges + v0)
            edge_start.append(edge_start[-1] + len(body.edges))
            dirs = unique_directions(body.vertices[body.edges[:, 1]]
                                     - body.vertices[body.edges[:, 0]])
            edirs.append(dirs)
            edir_start.append(edir_start[-1] + len(dirs))
    # world angular momentum from the initial angular velocity: L = R diag(I) R^T w
    for r in range(n):
        Rm = quat_to_matrix(arr["q"][r])
        arr["L"][r] = Rm @ (arr["inertia"][r] * (Rm.T @ arr["w"][r]))
    verts_local = np.concatenate(vl) if vl else np.zeros((0, 3))
    n_pieces = piece_start[-1]
    piece_start = np.array(piece_start, np.int64)
    return BlockStore(arr, dict(
        piece_start=piece_start,
        piece_block=np.repeat(np.arange(n), np.diff(piece_start)),
        piece_gid=np.arange(n_pieces, dtype=np.int64),
        piece_center=np.array(centers, float).reshape(-1, 3),
        piece_x=np.zeros((n_pieces, 3)),
        piece_lo=np.zeros((n_pieces, 3)),
        piece_hi=np.zeros((n_pieces, 3)),
        vert_start=np.array(vert_start, np.int64),
        verts_local=verts_local,
        verts_world=np.zeros_like(verts_local),
        face_start=np.array(face_start, np.int64),
        face_tag=np.concatenate(tags).astype(np.int32) if tags else np.zeros(0, np.int32),
        fvert_start=np.array(fvs, np.int64),
        face_verts=np.concatenate(fv).astype(np.int64) if fv else np.zeros(0, np.int64),
        normals_local=np.concatenate(fn) if fn else np.zeros((0, 3)),
        offsets_local=np.concatenate(fo) if fo else np.zeros(0),
        edge_start=np.array(edge_start, np.int64),
        edges=np.concatenate(ed).astype(np.int64) if ed else np.zeros((0, 2), np.int64),
        edir_start=np.array(edir_start, np.int64),
        edirs_local=np.concatenate(edirs) if edirs else np.zeros((0, 3)),
    )), groups


def unique_directions(vectors: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Unit directions of ``vectors`` with parallel ones (either sense) merged: the fast common
    plane's cost grows with the product of the two blocks' edge-direction counts."""
    d = vectors / np.linalg.norm(vectors, axis=1)[:, None]
    out: list[np.ndarray] = []
    for v in d:
        if not any(abs(abs(float(v @ u)) - 1.0) < tol for u in out):
            out.append(v)
    return np.array(out).reshape(-1, 3)
