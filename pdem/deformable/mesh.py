"""Tetrahedral zoning of one convex block: nodes, positively oriented tets, surface triangles.

Method (pure numpy, no external mesher): a structured lattice in the block's own frame,
clipped by the block's faces, then cleaned.

1. **Frame and lattice.** The third axis is the normal of the block's largest face; the first
   is the projected block edge that gives the smallest bounding rectangle across it. Along
   each axis the block's extent ``L_i`` is cut into ``n_i = ceil(L_i / (size / sqrt 2))``
   equal spacings ``h_i = L_i / n_i``, then any spacing more than :data:`ASPECT` times the
   smallest is cut down to that (a thin slab gets boxes at most 3:1, not 10:1 slivers). Every
   lattice box is split into the 6 Kuhn (Freudenthal) tets around its main diagonal; all
   boxes alike, so the lattice is conforming. A box, bar or slab lies on lattice planes and
   is meshed by these tets alone; a prism whose end faces are the largest is cut in its
   cross-section only.
2. **Snap.** A lattice node within ``SNAP * min(h)`` of a face plane moves onto it (within
   that distance of two planes: onto their edge; of three planes of a block vertex: onto the
   vertex; no move longer than twice that distance), so no cut leaves a piece thinner than
   that. The moved nodes of any lattice tet reaching into the block that the moves flatten
   go back. The lattice is padded by a box on every side and its outer nodes never move, so
   it still covers the block.
3. **Clip.** A lattice tet inside the block is a zone. A tet cut by face planes is clipped to
   the block (a convex cell) and coned from its vertex mean, every face of the cell with more
   than three corners fanned from the mean of its corners. A cut point is named by what it
   is, never by its coordinates: (lattice edge, plane), (lattice triangle, two planes) or a
   block vertex, and its position is computed from that name alone, so the two tets on a
   lattice triangle clip it to the same polygon and fan it from the same centre: the mesh is
   conforming. The cells are convex and their cone points inside, so the tets are positive
   and partition the block exactly; the block's vertices are nodes at their exact
   coordinates.
4. **Clean.** Clusters of cut points much closer than a short edge merge; edges shorter than
   ``SHORT * min(h)`` collapse (a node merges into a neighbour that lies on all its block
   planes, so the surface stays on the faces; block vertices stay) where the zones around
   stay positive, keep their volume, and stay at ``COLLAPSE_BELOW`` degrees or better (or
   improve); zones still under that get a collapse or a move of their nodes towards their
   neighbours' mean (within their block planes) where that improves them. Every step is
   checked locally, and the result as a whole (positive, no face in three zones, volumes
   adding up); a failure retries without the snap.

The size rule: every zone lies in one lattice box of sides at most ``size / sqrt 2``. Uncut
zones have the box's sides, face diagonals (at most ``size``) and main diagonal (at most
``sqrt(3/2) size``) as edges; no edge is longer than a box diagonal with both ends snapped the
most (``sqrt(3/2) size + 4 SNAP min(h)``, at most ``2.07 size``; the collapse and the moves
keep that bound).

Why not cone + longest-edge bisection (the earlier method): its cone tets from the centroid
are as elongated as the block, and bisection keeps their shape and refines them until their
long edges meet the size: a 0.1 x 0.1 x 2 bar at 0.1 took 13,648 zones at 2.6 degrees (here
696 at 35.9). Why not Delaunay (scipy's Qhull, not a dependency): the lattice's points are
cospherical in every box, so a Delaunay tetrahedralisation of lattice plus boundary points
has slivers that need the same cleaning, and it keeps the block's faces only if the boundary
points are dense; the clipped lattice is conforming and exact by construction.

Determinism: lattice tets are clipped in lattice order, planes in index order; cut points
and centres are keyed by integer tuples (insertion-ordered dicts), means are over corners
sorted by key, and the cleaning visits edges and zones in stable sorted order, so the same
input gives a bitwise identical mesh.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations, permutations

import numpy as np

# cells at most this many times longer than the smallest lattice spacing (Kuhn tets of a 3:1
# box: 18.4 degrees minimum dihedral angle; 2:1 would double the zones of a thin slab)
ASPECT = 3.0
# lattice nodes within this fraction of the smallest spacing of a face plane snap onto it
SNAP = 0.3
# zones with a smaller dihedral angle (degrees) are improved by edge collapse
COLLAPSE_BELOW = 15.0
# edges shorter than this fraction of the smallest spacing are collapsed where that keeps
# the zones around at COLLAPSE_BELOW or better
SHORT = 0.35
# nodes closer than this fraction of a short edge merge as one cluster
TINY = 0.05
# a collapse keeps the volume of the zones it changes to this fraction (twin zones it removes
# held a sliver's volume; a fold would change it by a zone's)
VOLUME_TOL = 1e-9


@dataclass(frozen=True)
class TetMesh:
    """A block's zoning.

    nodes : (n, 3) float64 gridpoint positions; the block's vertices come first (same order,
        exact coordinates), then the lattice nodes, cut points and cell centres in order of
        first use by ``tets``.
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


# cross products written out (index tables): the mesher measures a few tets at a time
_FA, _FB, _FC = (np.array(c) for c in zip((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1),
                                                       strict=True))
_PI, _PJ = (np.array(c) for c in zip(*combinations(range(4), 2), strict=True))
_C1, _C2 = np.array([1, 2, 0]), np.array([2, 0, 1])


def signed_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volume of every tet (positive for the orientation of :class:`TetMesh`)."""
    x0 = nodes[tets[:, 0]]
    u, v, w = nodes[tets[:, 1]] - x0, nodes[tets[:, 2]] - x0, nodes[tets[:, 3]] - x0
    return (u * (v[:, _C1] * w[:, _C2] - v[:, _C2] * w[:, _C1])).sum(axis=1) / 6.0


def min_dihedral_angles(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Smallest dihedral angle (degrees) of every tet: the usual shape measure (0 = flat)."""
    return _min_dihedral(nodes[tets])


def _min_dihedral(x: np.ndarray) -> np.ndarray:
    """:func:`min_dihedral_angles` of the tets ``x`` (k, 4, 3) (cross products written out:
    the mesher calls it on a few tets at a time)."""
    a = x[:, _FA]
    u, v = x[:, _FB] - a, x[:, _FC] - a  # face i is opposite vertex i
    nrm = u[..., _C1] * v[..., _C2] - u[..., _C2] * v[..., _C1]
    with np.errstate(invalid="ignore", divide="ignore"):
        nrm = nrm / np.sqrt((nrm * nrm).sum(axis=2))[..., None]
    cos = -(nrm[:, _PI] * nrm[:, _PJ]).sum(axis=2)
    # a degenerate face (NaN) counts as flat
    worst = cos.max(axis=1)
    worst[np.isnan(worst)] = 1.0
    return np.degrees(np.arccos(np.clip(worst, -1.0, 1.0)))


# the face of a tet opposite vertex i, CCW seen from outside for a positive tet
_LOCAL_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


class _Fail(Exception):
    """The clip met a configuration it cannot name consistently (retried without snap)."""


def _frame(poly) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows of the lattice frame (a1, a2, a3), and the block's extent in it (lo, hi)."""
    verts = np.asarray(poly.vertices, dtype=np.float64)
    normals = np.asarray(poly.normals, dtype=np.float64)
    areas = np.asarray(poly.face_areas())
    a3 = normals[int(np.argmax(areas))]
    best = None
    for i, j in np.asarray(poly.edges):
        d = verts[j] - verts[i]
        d = d - (d @ a3) * a3
        n = np.linalg.norm(d)
        if n <= 1e-9 * poly.radius():
            continue
        a1 = d / n
        a2 = np.cross(a3, a1)
        u = verts @ np.stack([a1, a2]).T
        area = float(np.prod(u.max(axis=0) - u.min(axis=0)))
        if best is None or area < best[0] * (1 - 1e-9):  # near ties: the first edge
            best = (area, a1, a2)
    rot = np.stack([best[1], best[2], a3])
    u = (verts - np.asarray(poly.centroid)) @ rot.T
    return rot, u.min(axis=0), u.max(axis=0)


def _spacings(lo, hi, size: float) -> np.ndarray:
    """Lattice boxes per axis: spacings at most ``size / sqrt(2)`` (the Kuhn tets' face
    diagonals at most ``size``), at most ASPECT times the smallest."""
    ext = hi - lo
    n = np.maximum(1, np.ceil(ext / (size / np.sqrt(2.0)) - 1e-9)).astype(np.int64)
    h = ext / n
    cap = ASPECT * h.min()
    n = np.where(h > cap * (1 + 1e-9), np.ceil(ext / cap - 1e-9), n).astype(np.int64)
    return n


def _kuhn(n: np.ndarray) -> np.ndarray:
    """The 6 Kuhn tets of every lattice box, (6 * boxes, 4) node ids, box-major."""
    n1, n2, n3 = (int(v) for v in n)
    s = np.array([(n2 + 1) * (n3 + 1), n3 + 1, 1], np.int64)  # node id strides
    i, j, k = np.meshgrid(np.arange(n1), np.arange(n2), np.arange(n3), indexing="ij")
    base = (i * s[0] + j * s[1] + k * s[2]).reshape(-1)
    local = []
    for p in permutations(range(3)):
        v, t = 0, [0]
        for a in p:
            v += s[a]
            t.append(v)
        # an odd permutation gives a negative path simplex: swap two corners
        parity = sum(p[x] > p[y] for x in range(3) for y in range(x + 1, 3)) % 2
        local.append([t[0], t[2], t[1], t[3]] if parity else t)
    return (base[:, None, None] + np.array(local, np.int64)[None]).reshape(-1, 4)


class _Clipper:
    """Cut-point bookkeeping shared by all lattice tets of one block (frame coordinates)."""

    def __init__(self, normals, offsets, bverts, vfaces, nodes, node_on, node_d, eps):
        self.n, self.o, self.eps = normals, offsets, eps
        self.bverts = bverts
        self.triples = {}  # sorted plane triple through a block vertex -> vertex id
        for v, fs in enumerate(vfaces):
            for t in combinations(sorted(fs), 3):
                self.triples.setdefault(t, v)
        self.nodes, self.node_d = nodes, node_d
        nv = len(bverts)
        # temporary ids: block vertices, then lattice nodes, then cut points and centres
        self.pos = [p for p in bverts] + [p for p in nodes]
        self.on = [frozenset(fs) for fs in vfaces] + [frozenset(s) for s in node_on]
        self.key_id: dict[tuple, int] = {}
        self.nv = nv

    def _add(self, key, p, on) -> int:
        on = set(on)
        on.update(int(f) for f in np.nonzero(np.abs(self.n @ p - self.o) < self.eps)[0])
        if len(on) >= 3:
            for t in combinations(sorted(on), 3):
                v = self.triples.get(t)
                if v is not None:
                    self.key_id[key] = v
                    return v
        self.pos.append(p)
        self.on.append(frozenset(on))
        i = len(self.pos) - 1
        self.key_id[key] = i
        return i

    def _solve(self, rows, rhs):
        m = np.array(rows)
        if abs(np.linalg.det(m)) < 1e-12:
            raise _Fail("parallel planes")
        return np.linalg.solve(m, np.array(rhs))

    def edge_point(self, i: int, j: int, g: int) -> int:
        key = (0, i, j, g)  # a lattice edge's cut
        got = self.key_id.get(key)
        if got is not None:
            return got
        di, dj = self.node_d[i], self.node_d[j]
        if not di[g] * dj[g] < 0.0:
            raise _Fail("edge does not cross")
        t = di[g] / (di[g] - dj[g])
        p = self.nodes[i] + t * (self.nodes[j] - self.nodes[i])
        return self._add(key, p, (g,))

    def tri_point(self, tri: tuple, f: int, g: int) -> int:
        f, g = min(f, g), max(f, g)
        key = (1, *tri, f, g)
        got = self.key_id.get(key)
        if got is not None:
            return got
        a, b, c = (self.nodes[x] for x in tri)
        nt = np.cross(b - a, c - a)
        p = self._solve([nt, self.n[f], self.n[g]], [nt @ a, self.o[f], self.o[g]])
        return self._add(key, p, (f, g))

    def plane_point(self, f: int, h: int, g: int) -> int:
        t = tuple(sorted((f, h, g)))
        key = (2, *t)
        got = self.key_id.get(key)
        if got is not None:
            return got
        p = self._solve([self.n[x] for x in t], [self.o[x] for x in t])
        return self._add(key, p, t)

    def centre(self, key, ids) -> int:
        got = self.key_id.get(key)
        if got is not None:
            return got
        p = np.mean([self.pos[i] for i in sorted(ids)], axis=0)
        self.pos.append(p)
        self.on.append(frozenset.intersection(*(self.on[i] for i in ids)))
        self.key_id[key] = len(self.pos) - 1
        return len(self.pos) - 1

    def clip(self, t_index: int, tet: np.ndarray, planes) -> list:
        """Zones of lattice tet ``tet`` (4 lattice node ids) clipped by ``planes``."""
        x = self.nodes[tet]
        inv = np.linalg.inv((x[1:] - x[0]).T)
        lattice_id = {int(self.node_tid[q]): int(q) for q in tet}
        ent_cache: dict[int, frozenset] = {}

        def entity(v: int) -> frozenset:
            # the lattice nodes of this tet spanning the smallest face that holds v
            e = ent_cache.get(v)
            if e is None:
                if v in lattice_id:
                    e = frozenset((lattice_id[v],))
                else:
                    b = inv @ (self.pos[v] - x[0])
                    bary = (1.0 - b.sum(), *b)
                    e = frozenset(int(tet[k]) for k in range(4) if bary[k] > 1e-10)
                ent_cache[v] = e
            return e

        def tid(q):  # temp id of lattice node q (a block vertex when snapped onto one)
            return self.node_tid[q]

        faces = []
        for lf in _LOCAL_FACES:
            tri = tuple(int(q) for q in tet[lf])
            faces.append(((3, *sorted(tri)), [tid(q) for q in tri]))
        for g in planes:
            ng, og = self.n[g], self.o[g]
            sign = {}
            for _, poly in faces:
                for v in poly:
                    if v not in sign:
                        if g in self.on[v]:
                            sign[v] = 0
                        else:
                            sign[v] = 1 if ng @ self.pos[v] - og > 0.0 else -1
            if not any(s > 0 for s in sign.values()):
                continue
            if not any(s < 0 for s in sign.values()):
                return []
            new = []
            for fkey, poly in faces:
                out = []
                m = len(poly)
                for k in range(m):
                    a, b = poly[k], poly[(k + 1) % m]
                    if sign[a] <= 0:
                        out.append(a)
                    if sign[a] * sign[b] < 0:
                        c = self._cross(a, b, g, entity)
                        sign[c] = 0
                        out.append(c)
                out = [v for k, v in enumerate(out) if v != out[k - 1]]
                if len(out) >= 3:
                    new.append((fkey, out))
            cap = sorted({v for _, poly in new for v in poly if sign[v] == 0})
            if len(cap) >= 3:
                new.append(((4, t_index, g), self._ccw(cap, ng)))
            faces = new
        corners = sorted({v for _, poly in faces for v in poly})
        cone = self.centre((5, t_index), corners)
        out = []
        for fkey, poly in faces:
            if len(poly) == 3:
                out.append((cone, *poly))
                continue
            c = self.centre(fkey, poly)
            m = len(poly)
            out.extend((cone, c, poly[k], poly[(k + 1) % m]) for k in range(m))
        return out

    def _cross(self, a: int, b: int, g: int, entity) -> int:
        u = sorted(entity(a) | entity(b))
        common = sorted(self.on[a] & self.on[b])
        if len(u) == 2:
            return self.edge_point(u[0], u[1], g)
        if len(common) >= 2:
            return self.plane_point(common[0], common[1], g)
        if len(u) == 3 and common:
            return self.tri_point(tuple(u), common[0], g)
        raise _Fail("unnamed cut point")

    def _ccw(self, ids, normal) -> list:
        p = np.array([self.pos[i] for i in ids])
        nx, ny, nz = normal
        # two axes across the normal: e1 = n x (1, 0, 0) or n x (0, 1, 0), e2 = n x e1
        e1 = np.array([0.0, nz, -ny]) if abs(nx) < 0.9 else np.array([-nz, 0.0, nx])
        e2 = np.array([ny * e1[2] - nz * e1[1], nz * e1[0] - nx * e1[2], nx * e1[1] - ny * e1[0]])
        d = p - p.mean(axis=0)
        ang = np.arctan2(d @ e2, d @ e1)
        return [ids[k] for k in np.argsort(ang, kind="stable")]


def _snap(nodes, normals, offsets, bverts, vfaces, reach, movable):
    """Move the ``movable`` lattice nodes near face planes onto them (see module doc).
    Returns the moved nodes and each node's planes (a tuple of face ids)."""
    d = nodes @ normals.T - offsets
    near = (np.abs(d) < reach) & movable[:, None]
    moved = nodes.copy()
    on: list[tuple] = [()] * len(nodes)
    triples = {}
    for v, fs in enumerate(vfaces):
        for t in combinations(sorted(fs), 3):
            triples.setdefault(t, v)
    for q in np.nonzero(near.any(axis=1))[0]:
        fs = sorted(np.nonzero(near[q])[0], key=lambda f: (abs(d[q, f]), f))
        chosen: list[int] = []
        p = nodes[q]
        for f in fs:
            trial = chosen + [int(f)]
            if len(trial) == 3:
                v = triples.get(tuple(sorted(trial)))
                if v is None:
                    continue
                if np.linalg.norm(bverts[v] - nodes[q]) <= 2.0 * reach:
                    p, chosen = bverts[v], trial
                break
            m = normals[trial]
            gram = m @ m.T
            if np.linalg.det(gram) < 1e-6:  # parallel planes: no edge
                continue
            step = m.T @ np.linalg.solve(gram, m @ nodes[q] - offsets[trial])
            if np.linalg.norm(step) <= 2.0 * reach:
                p, chosen = nodes[q] - step, trial
        moved[q] = p
        on[q] = tuple(sorted(chosen))
    return moved, on


def _attempt(poly, size, snap):
    rot, lo, hi = _frame(poly)
    c = np.asarray(poly.centroid, dtype=np.float64)
    bverts = (np.asarray(poly.vertices, dtype=np.float64) - c) @ rot.T
    normals = np.asarray(poly.normals, dtype=np.float64) @ rot.T
    offsets = np.asarray(poly.offsets, dtype=np.float64) - np.asarray(poly.normals) @ c
    fs, fv = np.asarray(poly.face_start), np.asarray(poly.face_verts)
    vfaces: list[list[int]] = [[] for _ in range(len(bverts))]
    for f in range(len(fs) - 1):
        for v in fv[fs[f]:fs[f + 1]]:
            vfaces[int(v)].append(f)
    n = _spacings(lo, hi, size)
    h = (hi - lo) / n
    # one cell of padding around the block's extent: snapping moves the nodes near the
    # block, never the lattice's own boundary, so the moved lattice still covers the block
    axes = [np.concatenate([[lo[a] - h[a]], lo[a] + h[a] * np.arange(n[a]), hi[a:a + 1],
                            [hi[a] + h[a]]]) for a in range(3)]
    n = n + 2
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    pad = np.stack(np.meshgrid(*[(np.arange(k + 1) == 0) | (np.arange(k + 1) == k)
                                 for k in n], indexing="ij"), axis=-1).reshape(-1, 3)
    reach = snap * h.min()
    nodes, node_on = _snap(grid, normals, offsets, bverts, vfaces, reach, ~pad.any(axis=1))
    tets = _kuhn(n)
    eps = 1e-12 * float(np.abs(bverts).max())
    # the moved lattice must still tile space wherever it meets the block (a flattened or
    # flipped tet there leaves a gap beside an overlap): the moved nodes of such tets go
    # back to their lattice place until there is none
    while True:
        d = nodes @ normals.T - offsets
        sgn = np.sign(d).astype(np.int8)
        sgn[np.abs(d) < eps] = 0
        for q, fs_on in enumerate(node_on):
            if fs_on:
                sgn[q, list(fs_on)] = 0
        ts = sgn[tets]  # (m, 4, F)
        meets = np.nonzero(~(ts > 0).all(axis=1).any(axis=1))[0]
        flat = meets[signed_volumes(nodes, tets[meets]) <= 0.05 * np.prod(h) / 6.0]
        back = [int(q) for q in np.unique(tets[flat]) if node_on[q]]
        if not back:
            break
        for q in back:
            nodes[q], node_on[q] = grid[q], ()
    outside = (ts >= 0).all(axis=1).any(axis=1)
    inside = (ts <= 0).all(axis=(1, 2))
    live = ~outside
    node_on = [tuple(sorted(set(fs_on) | set(np.nonzero(sgn[q] == 0)[0].tolist())))
               for q, fs_on in enumerate(node_on)]
    clip = _Clipper(normals, offsets, bverts, vfaces, nodes, node_on, d, eps)
    # lattice nodes snapped onto three planes of a block vertex are that vertex
    nv = len(bverts)
    node_tid = np.arange(nv, nv + len(nodes))
    for q, fs_on in enumerate(node_on):
        for t in combinations(fs_on, 3):
            if t in clip.triples:
                node_tid[q] = clip.triples[t]
                break
    clip.node_tid = node_tid
    pieces: list[np.ndarray] = []
    order: list[int] = []
    keep = np.nonzero(inside)[0]
    pieces.append(node_tid[tets[keep]])
    order.extend(keep.tolist())
    for t in np.nonzero(live & ~inside)[0]:
        planes = np.nonzero((ts[t] > 0).any(axis=0))[0]
        out = clip.clip(int(t), tets[t], [int(g) for g in planes])
        if out:
            pieces.append(np.array(out, np.int64))
            order.extend([int(t)] * len(out))
    tmp = np.concatenate(pieces)
    tmp = tmp[np.argsort(np.array(order), kind="stable")]
    pos = np.array(clip.pos)
    fixed = np.arange(len(pos)) < nv
    # no edge longer than a lattice box's diagonal (the longest edge of its Kuhn tets) with
    # both ends snapped the most (2 reach each: the longest edge the clipped lattice can have)
    longest = (float(np.sqrt(h @ h)) + 4.0 * reach) * (1 + 1e-12)
    tmp = _collapse(pos, tmp, clip.on, fixed, normals, offsets, SHORT * h.min(),
                    COLLAPSE_BELOW, longest)
    _smooth(pos, tmp, clip.on, fixed, normals, offsets, COLLAPSE_BELOW, longest)
    # renumber: block vertices first, then the rest by first use
    used, first = np.unique(tmp.reshape(-1), return_index=True)
    if not np.array_equal(used[:nv], np.arange(nv)):
        raise _Fail("a block vertex is not a node")
    rest = used
    rest_first = first[rest >= nv]
    rest = rest[rest >= nv][np.argsort(rest_first, kind="stable")]
    new_id = np.full(len(pos), -1, np.int64)
    new_id[:nv] = np.arange(nv)
    new_id[rest] = np.arange(nv, nv + len(rest))
    out_tets = new_id[tmp]
    out_nodes = c + pos[np.concatenate([np.arange(nv), rest])] @ rot
    out_nodes[:nv] = np.asarray(poly.vertices, dtype=np.float64)
    v = signed_volumes(out_nodes, out_tets)
    if not v.min() > 0.0:
        raise _Fail("a zone is not positive")
    # the checks above are local (each collapse, each cell): the whole must be a partition,
    # every tet face shared by at most two zones and the volumes adding up to the block's
    _, count = np.unique(np.sort(out_tets[:, _LOCAL_FACES].reshape(-1, 3), axis=1), axis=0,
                         return_counts=True)
    if count.max() > 2 or abs(v.sum() - poly.volume) > 1e-11 * poly.volume:
        raise _Fail("not a partition")
    return out_nodes, out_tets


def _tet_quality(x: np.ndarray) -> float:
    """Smallest dihedral angle (degrees) of the tets ``x`` (k, 4, 3); -1 if any is not
    positive."""
    if len(x) == 0:
        return 180.0
    u, v, w = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]
    vol = (u * (v[:, _C1] * w[:, _C2] - v[:, _C2] * w[:, _C1])).sum(axis=1)
    if not vol.min() > 0.0:
        return -1.0
    return float(_min_dihedral(x).min())


def _twins(rows) -> set[int]:
    """Positions of the pairs of rows with the same four nodes: the two thin zones either side
    of a face whose apexes a collapse merges, which then cancel (both go)."""
    seen: dict[tuple, int] = {}
    out: set[int] = set()
    for k, r in enumerate(rows):
        key = tuple(sorted(r))
        if len(set(key)) == 4 and key in seen:
            out.update((seen.pop(key), k))
        else:
            seen[key] = k
    return out


def _collapse(nodes, tets, on, fixed, normals, offsets, short: float, worst: float,
              longest: float):
    """Edge collapse (a node ``b`` merges into a neighbour ``a``; one node id replaces another
    everywhere, so conformity is kept) of the edges shorter than ``short`` and of the zones
    whose smallest dihedral angle is under ``worst``. Allowed when ``b`` is not a block vertex,
    ``a`` lies on every block plane ``b`` lies on (the surface stays on the faces; else ``a``
    moves onto the edge of its plane and ``b``'s, when that is within ``short``), the zones
    around ``b`` that survive are positive, fill the same volume and have no edge longer
    than ``longest``, and their worst angle is at least ``worst`` or better than before.
    Short edges go first (shortest first), then the bad zones (worst first). Returns the
    tets left."""
    qual = list(min_dihedral_angles(nodes, tets))  # per tet, kept up to date
    vol = list(signed_volumes(nodes, tets))
    tets = [list(t) for t in tets.tolist()]
    alive = [True] * len(tets)
    star: list[list[int]] = [[] for _ in range(len(nodes))]
    for k, t in enumerate(tets):
        for q in t:
            star[q].append(k)

    def attempt(a: int, b: int, improve_only: bool) -> bool:
        if fixed[b]:
            return False
        planes = on[a] | on[b]
        p = nodes[a]
        if planes != on[a]:
            # b on a plane a is not on (two cut points either side of a block edge): a moves
            # onto the planes of both, when they meet in an edge near it
            if fixed[a] or len(planes) > 2:
                return False
            m = normals[sorted(planes)]
            gram = m @ m.T
            if np.linalg.det(gram) < 1e-6:
                return False
            p = p - m.T @ np.linalg.solve(gram, m @ p - offsets[sorted(planes)])
            if np.linalg.norm(p - nodes[a]) > short:
                return False
        around = [m for m in star[b] if alive[m]]
        keep = [m for m in around if a not in tets[m]]
        if not keep or len(keep) == len(around):  # b alone, or a is not b's neighbour
            return False
        moved = [m for m in star[a] if alive[m] and b not in tets[m]] \
            if planes != on[a] else []
        rows = [[a if q == b else q for q in tets[m]] for m in keep + moved]
        drop = _twins(rows)
        ms = [m for k, m in enumerate(keep + moved) if k not in drop]
        if not ms:
            return False
        new = np.array([r for k, r in enumerate(rows) if k not in drop])
        keep_a, nodes[a] = nodes[a].copy(), p
        try:
            reach = nodes[new.reshape(-1)] - p
            if (reach * reach).sum(axis=1).max() > longest * longest:
                return False
            v_new = signed_volumes(nodes, new)
            if not v_new.min() > 0.0:
                return False
            v_old = sum(vol[m] for m in around + moved)
            if abs(v_new.sum() - v_old) > VOLUME_TOL * v_old:
                return False
            q_old = min(qual[m] for m in around + moved)
            q_each = _min_dihedral(nodes[new])
            q_new = float(q_each.min())
            if not (q_new > q_old or (not improve_only and q_new >= worst)):
                return False
        finally:
            nodes[a] = keep_a
        nodes[a], on[a] = p, planes
        for m in around + moved:
            alive[m] = False
        for m, t_new, v, q in zip(ms, new.tolist(), v_new.tolist(), q_each.tolist(), strict=True):
            alive[m], tets[m], vol[m], qual[m] = True, t_new, v, q
        star[a].extend(keep)
        star[b] = []
        return True

    def merge(rep: int, others: list[int]) -> bool:
        """``others`` merge into ``rep`` where the zones left are positive and keep their
        volume."""
        gone = set(others)
        around = sorted({m for q in [rep, *others] for m in star[q] if alive[m]})
        new_t = [[rep if q in gone else q for q in tets[m]] for m in around]
        drop = _twins(new_t)
        keep = [k for k, t in enumerate(new_t) if len(set(t)) == 4 and k not in drop]
        if not keep:
            return False
        new = np.array([new_t[k] for k in keep])
        v_new = signed_volumes(nodes, new)
        v_old = sum(vol[m] for m in around)
        if not v_new.min() > 0.0 or abs(v_new.sum() - v_old) > VOLUME_TOL * v_old:
            return False
        q_each = _min_dihedral(nodes[new])
        for m in around:
            alive[m] = False
        for k, v, q in zip(keep, v_new.tolist(), q_each.tolist(), strict=True):
            m = around[k]
            alive[m], tets[m], vol[m], qual[m] = True, new_t[k], v, q
            if m not in star[rep]:
                star[rep].append(m)
        for q in others:
            star[q] = []
        return True

    arr = np.array(tets, np.int64)
    e = np.sort(arr[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]].reshape(-1, 2), axis=1)
    e = np.unique(e, axis=0)
    length = np.linalg.norm(nodes[e[:, 0]] - nodes[e[:, 1]], axis=1)
    # clusters of nodes much closer than the short edges (cut points where a block edge
    # passes next to a lattice edge, one per lattice triangle around it) merge at once:
    # merging them two by two flattens the zones between the others
    parent = {}

    def root(q):
        while parent.get(q, q) != q:
            q = parent[q]
        return q

    for k in np.nonzero(length < TINY * short)[0]:
        a, b = root(int(e[k, 0])), root(int(e[k, 1]))
        if a != b:
            parent[max(a, b)] = min(a, b)
    groups: dict[int, list[int]] = {}
    for q in sorted(parent):
        groups.setdefault(root(q), [root(q)]).append(q)
    for members in groups.values():
        rep = max(members, key=lambda q: (bool(fixed[q]), len(on[q]), -q))
        if any(fixed[q] for q in members if q != rep) or \
                any(not on[q] <= on[rep] for q in members):
            continue
        merge(rep, [q for q in members if q != rep])
    for k in np.argsort(length, kind="stable"):
        if length[k] >= short:
            break
        a, b = int(e[k, 0]), int(e[k, 1])
        if star[a] and star[b]:
            attempt(a, b, False) or attempt(b, a, False)
    ang = np.array(qual)
    for k in [int(k) for k in np.argsort(ang, kind="stable") if ang[k] < worst]:
        if not alive[k]:
            continue
        t = tets[k]
        pairs = sorted((float(np.linalg.norm(nodes[a] - nodes[b])), a, b)
                        for a in t for b in t if a != b)
        for _, a, b in pairs:
            if attempt(a, b, True):
                break
    return np.array([t for t, ok in zip(tets, alive, strict=True) if ok], np.int64)


def _smooth(nodes, tets, on, fixed, normals, offsets, worst: float, longest: float,
            sweeps: int = 3):
    """Move the nodes of zones whose smallest dihedral angle is under ``worst`` towards the
    mean of their neighbours (kept on their block planes: a node on one plane moves in it, on
    two along their edge), where that improves the worst angle around them, keeps their
    volume and makes no edge longer than ``longest``. ``nodes`` is changed in place."""
    star: list[list[int]] = [[] for _ in range(len(nodes))]
    for k, t in enumerate(tets.tolist()):
        for q in t:
            star[q].append(k)
    for _ in range(sweeps):
        ang = min_dihedral_angles(nodes, tets)
        bad = np.argsort(ang, kind="stable")[:int((ang < worst).sum())]
        moved = False
        for q in sorted({int(q) for q in tets[bad].reshape(-1)}):
            planes = sorted(on[q])
            if fixed[q] or len(planes) > 2:
                continue
            around = tets[star[q]]
            ring = np.unique(around)
            # candidates: the neighbours' mean, and away from the face opposite q in each of
            # its bad zones (a sliver's four nodes are nearly in one plane)
            targets = [(nodes[ring].sum(axis=0) - nodes[q]) / (len(ring) - 1)]
            for t in tets[bad]:
                if q in t:
                    a, b, c = (nodes[r] for r in t if r != q)
                    n = np.cross(b - a, c - a)
                    n *= np.sign(n @ (nodes[q] - a)) / np.linalg.norm(n)
                    targets.append(nodes[q] + 0.3 * np.linalg.norm(b - a) * n)
            q_old = _tet_quality(nodes[around])
            v_old = signed_volumes(nodes, around).sum()
            keep = nodes[q].copy()
            done = False
            for target in targets:
                if planes:  # onto the node's planes (its face or edge)
                    m = normals[planes]
                    target = target - m.T @ np.linalg.solve(m @ m.T, m @ target - offsets[planes])
                for w in (1.0, 0.5, 0.25):
                    nodes[q] = keep + w * (target - keep)
                    reach = nodes[ring] - nodes[q]
                    if (reach * reach).sum(axis=1).max() <= longest * longest and \
                            _tet_quality(nodes[around]) > q_old and \
                            abs(signed_volumes(nodes, around).sum() - v_old) <= 1e-12 * v_old:
                        done = moved = True
                        break
                if done:
                    break
            if not done:
                nodes[q] = keep
        if not moved:
            break


def boundary_triangles(tets: np.ndarray) -> np.ndarray:
    """The tet faces used once (the grid's boundary), ``(k, 3)`` gridpoint ids, CCW seen from
    outside for positively oriented tets, in tet order (deterministic: the same tets give the
    same triangles). ``TetMesh.surface`` is these; the output's deformed surface too
    (pdem.io.zone_surfaces)."""
    tets = np.asarray(tets, np.int64).reshape(-1, 4)
    tri = tets[:, _LOCAL_FACES].reshape(-1, 3)
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
    """Zone a convex polyhedron into the clipped Kuhn tets of a lattice of spacing at most
    ``size / sqrt 2`` in the block's frame (see the module doc for the exact rule)."""
    if not size > 0.0:
        raise ValueError(f"zone size must be positive, got {size}")
    err = None
    for snap in (SNAP, 0.0):
        try:
            node_arr, tet_arr = _attempt(poly, float(size), snap)
            break
        except _Fail as e:
            err = e
    else:
        raise RuntimeError(f"tetrahedralise: no valid zoning of the block ({err})")
    surface, surface_face, on_surface = _surface(node_arr, tet_arr, poly)
    return TetMesh(node_arr, tet_arr, surface, surface_face, on_surface)
