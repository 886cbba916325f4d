"""Block shapes by scene key (``blocks[i].box``, ``.array``, ...): one registry entry per kind
holds everything the code knows of it (its builder, its member count, its size estimate for
the pre-flight, whether it may be zoned), so build (pdem.model.build) and pre-flight
(pdem.preflight) look a kind up instead of naming it.

A new shape kind is one entry in :data:`SHAPES` (here, or registered from outside pdem's tree):
it carries its scene model (``params``), and the scene grammar follows the registry (the
``Block`` field, ``SHAPE_KEYS``, ``ZONED_SHAPES``: config.schema.SHAPE_MODELS)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config.schema import (
    SHAPE_MODELS,
    ArrayOf,
    BoxShape,
    MeshShape,
    PlanesShape,
    PolyhedronShape,
    PrismShape,
    RandomPolyhedra,
    ShapeModel,
)
from ..geometry import (
    GeometryError,
    box,
    check_convex,
    from_planes,
    from_vertices,
    prism,
)
from ..geometry.concave import convex_pieces
from ..registry import Registry


@dataclass(frozen=True)
class ShapeKind:
    """One shape kind of a ``blocks:`` entry, by its scene key (its name in :data:`SHAPES`).

    ``params``: the pydantic model of the key's value (a :class:`pdem.strict.Strict`);
    registering the kind makes the key a field of ``Block`` (the grammar's ``SHAPE_MODELS``
    follows this registry). ``params`` below is an entry's value of it
    (``getattr(block, kind)``).
    ``build(params)`` yields (member index or None, world-frame shape, or a list of convex
    pieces for a concave block); a family (index given) names its members ``NAME[k]``. With
    ``builds_share``, ``build(params, members)`` builds only the member indices in the range
    ``members`` (a rank's share of a large family). None: the kind is built elsewhere (a
    mesh: pdem.model.mesh_blocks, from the file, spread over the ranks).
    ``polytope(params)``: (vertices, faces, edges) of one block, an upper estimate (the
    pre-flight's memory estimate).
    ``members(params)``: a family's member count; None for a single block.
    ``zoned``: a block of this kind may be zoned (config.schema.ZONED_SHAPES)."""

    params: type
    build: Callable[..., Iterator[tuple[int | None, Any]]] | None
    polytope: Callable[[Any], tuple[int, int, int]]
    members: Callable[[Any], int] | None = None
    builds_share: bool = False
    zoned: bool = False

    @property
    def family(self) -> bool:
        return self.members is not None

    def count(self, params) -> int:
        """The blocks the entry makes: 1 for a single block, else the family's members."""
        return 1 if self.members is None else self.members(params)

    def size(self, params) -> tuple[int, int, int, int]:
        """(blocks, vertices, faces, edges): the blocks the entry makes and each one's
        vertex, face and edge counts (pdem.preflight.estimate)."""
        return (self.count(params), *self.polytope(params))


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


def _array(a, members: range | None = None):
    """The members of ``base.transformed(np.eye(3), offset)`` (x fastest), computed for all
    members at once: the rotated base once, then per member the same additions and
    matrix-vector products (stacked), so bitwise the same shapes as one call per member.
    ``members``: only these member indices (a rank's share of a large array)."""
    base = box(a.box.min, a.box.max)
    eye = np.eye(3)
    base.transformed(eye, np.zeros(3))  # the same checks as a call per member
    nx, ny, nz = a.count
    ks = np.arange(nx * ny * nz) if members is None else np.arange(members.start, members.stop)
    idx = np.stack([ks % nx, ks // nx % ny, ks // (nx * ny)], axis=1).astype(float)
    offs = idx * np.array(a.spacing, float)
    verts_r = base.vertices @ eye.T
    normals = _frozen(base.normals @ eye.T)
    centroid_r = eye @ base.centroid
    inertia = _frozen(eye @ base.inertia @ eye.T)
    for c0 in range(0, len(offs), _ARRAY_CHUNK):
        t = offs[c0:c0 + _ARRAY_CHUNK]
        verts = _frozen(verts_r + t[:, None, :])
        stacked = np.ascontiguousarray(np.broadcast_to(normals, (len(t),) + normals.shape))
        offsets = _frozen(base.offsets + (stacked @ t[:, :, None])[:, :, 0])
        cents = _frozen(centroid_r + t)
        for j in range(len(t)):
            yield int(ks[c0 + j]), base.moved(vertices=verts[j], normals=normals,
                                              offsets=offsets[j], centroid=cents[j],
                                              inertia=inertia)


_ARRAY_CHUNK = 1 << 16


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


def _random(r):
    rng = np.random.default_rng(r.seed)
    for k, site in enumerate(_lattice(r.region, r.count, r.size[1])):
        d = rng.uniform(r.size[0], r.size[1])
        shape = _random_hull(rng, d, r.vertices)
        yield k, shape.transformed(np.eye(3), site - shape.centroid)


def _cuboid(p) -> tuple[int, int, int]:
    return 8, 6, 12


def _triangulated(v: int) -> tuple[int, int, int]:
    """A polytope of ``v`` vertices: Euler's V - E + F = 2 with the worst case of triangular
    faces (E = 3V - 6, F = 2V - 4), at least a tetrahedron's."""
    return v, max(2 * v - 4, 4), max(3 * v - 6, 6)


def _random_polytope(p) -> tuple[int, int, int]:
    v = p.vertices  # >= 4 (the schema): _triangulated(v) alike
    return v, 2 * v - 4, 3 * v - 6


# The kinds, in the order ``Block`` lists their keys
SHAPES: Registry[ShapeKind] = Registry("block shape")
for _name, _kind in (
    ("box", ShapeKind(BoxShape, _box, _cuboid, zoned=True)),
    ("polyhedron", ShapeKind(PolyhedronShape, _polyhedron,
                             lambda p: _triangulated(len(p.vertices)), zoned=True)),
    ("prism", ShapeKind(PrismShape, _prism, lambda p: _triangulated(2 * len(p.base)),
                        zoned=True)),
    ("planes", ShapeKind(PlanesShape, _planes, lambda p: _triangulated(2 * len(p.normals)),
                         zoned=True)),
    ("array", ShapeKind(ArrayOf, _array, _cuboid, members=lambda p: math.prod(p.count),
                        builds_share=True, zoned=True)),
    ("random", ShapeKind(RandomPolyhedra, _random, _random_polytope, members=lambda p: p.count,
                         zoned=True)),
    # counted once the mesh is read (the cuts' blocks likewise): one box-like block here
    ("mesh", ShapeKind(MeshShape, None, _cuboid, zoned=True)),
):
    SHAPES.register(_name, _kind)
# the scene grammar's shape keys follow the kinds (config cannot import model: it keeps its own
# registry, kept equal to this one): one registration here, from anywhere, is a kind
SHAPE_MODELS.follow(SHAPES, lambda kind: ShapeModel(kind.params, kind.zoned))


def family_size(block) -> int | None:
    """Members of a family entry (``array``, ``random``, ...), None for a single block."""
    kind = SHAPES[block.shape_kind]
    return kind.count(getattr(block, block.shape_kind)) if kind.family else None


def shape_size(block) -> tuple[int, int, int, int]:
    """(blocks, vertices, faces, edges) of a ``blocks:`` entry (:meth:`ShapeKind.size`)."""
    return SHAPES[block.shape_kind].size(getattr(block, block.shape_kind))
