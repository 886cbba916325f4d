"""Cutting convex blocks by planes: joint sets, block subdivision and excavation.

A jointed rock mass is built by cutting a few large convex blocks with joint sets (families of
parallel planes) and then removing excavations (convex regions given by their bounding
planes). Every operation here is a sequence of single-plane splits of a convex polyhedron,
each of which yields at most two convex pieces, so every result is convex.

Face provenance is kept in ``ConvexPolyhedron.face_tag``: a piece's face that lies on a
parent face inherits the parent's tag (``UNTAGGED`` = -1 if the parent had none), and a face
made by a cut gets the tag passed with that cut (e.g. the joint set's index), so contact
properties can later be chosen per joint set.

Conventions: x = east, y = north, z = up; dip in degrees below horizontal, dip direction in
degrees clockwise from north. These functions run once at model build, per block, in numpy and
Python, except the clipping of a piece's faces (``_clip_kernel``), its half-edges and mass
properties (pdem.geometry.topology, .mass): compiled, as a rock mass makes thousands of pieces
a second through them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from pdem.geometry.builders import BOX_NORMALS
from pdem.geometry.errors import GeometryError
from pdem.geometry.hull import default_tolerance, hull_faces
from pdem.geometry.polyhedron import ConvexPolyhedron
from pdem.jit import kernel

from .intersection import ring_order
from .vector import cross

#: Tag of a face that no cut has labelled (the original model surface).
UNTAGGED = -1

# A cut face's normal must be this close to a candidate plane's to inherit its tag (fallback
# path only: the direct path carries tags by face index).
_PLANE_MATCH_COS = 1.0 - 1e-6

Region = tuple[np.ndarray, np.ndarray] | ConvexPolyhedron


# ---------------------------------------------------------------------------- small helpers
def _unit_plane(normal, offset) -> tuple[np.ndarray, float]:
    """Normalise a plane ``normal . x = offset`` to a unit normal (offset scaled alike)."""
    n = np.asarray(normal, dtype=np.float64).reshape(3)
    d = float(offset)
    nrm = float(np.linalg.norm(n))
    if not (np.all(np.isfinite(n)) and np.isfinite(d)) or nrm == 0.0:
        raise GeometryError(f"invalid plane: normal {n}, offset {d}")
    return n / nrm, d / nrm


def _check_tol(tol) -> float:
    tol = float(tol)
    if not (np.isfinite(tol) and tol >= 0.0):
        raise GeometryError(f"tol must be a finite non-negative length, got {tol}")
    return tol


def face_tags(poly: ConvexPolyhedron) -> np.ndarray:
    """Per-face tags of ``poly``: its ``face_tag``, or all ``UNTAGGED`` if it has none."""
    if poly.face_tag is not None:
        return np.asarray(poly.face_tag)
    return np.full(poly.n_faces, UNTAGGED, dtype=np.int64)


def _tagged(poly: ConvexPolyhedron) -> ConvexPolyhedron:
    """``poly`` itself if it carries tags, else a copy tagged ``UNTAGGED`` everywhere."""
    return poly if poly.face_tag is not None else poly.with_face_tag(face_tags(poly))


# ---------------------------------------------------------------------------- one split
def split_by_plane(
    poly: ConvexPolyhedron, normal, offset, tol: float = 0.0, tag: int = UNTAGGED
) -> tuple[ConvexPolyhedron | None, ConvexPolyhedron | None]:
    """Split a convex polyhedron by the plane ``normal . x = offset``.

    Parameters
    ----------
    poly : ConvexPolyhedron
        Block to cut.
    normal : (3,) array_like
        Plane normal (need not be unit; ``offset`` is in its units).
    offset : float
        Plane offset.
    tol : float
        Sliver thickness: a piece whose extent along the normal is below ``tol`` is not
        created and the other side gets the whole block. The geometric round-off tolerance
        of the block (:func:`~pdem.geometry.hull.default_tolerance`) is always applied as a
        floor, so a plane touching a vertex, edge or face, or missing the block, never makes
        a zero-volume piece.
    tag : int
        ``face_tag`` of the new face on the cut plane.

    Returns
    -------
    below, above : ConvexPolyhedron or None
        The pieces with ``normal . x <= offset`` and ``>= offset``; ``None`` for a side with
        no piece, the other then being ``poly`` itself (tagged, geometry untouched). Both
        carry ``face_tag``: parent faces keep the parent's tags (``UNTAGGED`` if it had
        none), the cut face (last face of each piece) gets ``tag``. Parent faces keep their
        exact planes, the cut face gets the exact cut plane; the volumes add up to the
        parent's to round-off.
    """
    below, above, cut = _plane_cut(poly, normal, offset, tol, tag)
    if cut is None:
        return below, above
    n, d = cut.plane
    return cut.piece(n, d, keep=-1), cut.piece(-n, -d, keep=1)


def clip_below(
    poly: ConvexPolyhedron, normal, offset, tol: float = 0.0, tag: int = UNTAGGED
) -> ConvexPolyhedron | None:
    """The ``below`` piece of :func:`split_by_plane` (the same numbers), without making the
    other one: clipping a polyhedron by a half-space."""
    below, _, cut = _plane_cut(poly, normal, offset, tol, tag)
    if cut is None:
        return below
    n, d = cut.plane
    return cut.piece(n, d, keep=-1)


def _plane_cut(poly, normal, offset, tol, tag):
    """(below, above, None) when the plane leaves ``poly`` whole (see :func:`split_by_plane`),
    else (None, None, the cut)."""
    n, d = _unit_plane(normal, offset)
    return _unit_plane_cut(poly, n, d, _check_tol(tol), tag)


def _unit_plane_cut(poly, n, d, tol, tag):
    """:func:`_plane_cut` by the unit plane ``n . x = d`` with a checked ``tol``."""
    snap = default_tolerance(poly.vertices)
    s = poly.vertices @ n - d
    thin = max(tol, snap)
    if s.max() < thin:
        return _tagged(poly), None, None
    if s.min() > -thin:
        return None, _tagged(poly), None
    cut = _Cut(poly, *_cut_points(poly.vertices, poly.edges, s, snap), snap, tag)
    cut.plane = (n, d)
    return None, None, cut


@kernel
def _cut_points(vertices, edges, s, snap):
    """``(side, points, edge_key)`` of a plane cut, compiled (per piece of a rock mass: a
    dozen numpy calls were ~10 % of its build). ``s``: the vertices' signed distances to the
    plane. A vertex within ``snap`` of the plane is on it (``side`` 0) and belongs to both
    pieces, so a cut through a vertex does not leave a needle edge next to it; else ``side``
    is +1 above, -1 below. ``points``: the vertices, then one row per edge, its intersection
    point where the edge crosses the plane (shared by both pieces and both faces at it), NaN
    elsewhere. ``edge_key``: ``i * nv + j`` of each edge (sorted: the edges are)."""
    nv = vertices.shape[0]
    ne = edges.shape[0]
    side = np.empty(nv, np.int64)
    for i in range(nv):
        side[i] = 1 if s[i] > snap else (-1 if s[i] < -snap else 0)
    points = np.full((nv + ne, 3), np.nan)
    points[:nv] = vertices
    edge_key = np.empty(ne, np.int64)
    for k in range(ne):
        a = edges[k, 0]
        b = edges[k, 1]
        edge_key[k] = a * nv + b
        if side[a] * side[b] < 0:
            t = s[a] / (s[a] - s[b])
            for j in range(3):
                points[nv + k, j] = vertices[a, j] + t * (vertices[b, j] - vertices[a, j])
    return side, points, edge_key


class _Cut:
    """One plane cut of one polyhedron, shared by its two sides (internal)."""

    def __init__(self, poly, side, points, edge_key, snap, tag):
        self.poly = poly
        self.side = side
        self.snap = snap
        self.tag = int(tag)
        self.points = points
        self.edge_key = edge_key

    def piece(self, n: np.ndarray, d: float, keep: int) -> ConvexPolyhedron:
        """Piece on the ``keep`` side (-1: below, +1: above) of the plane; its cap normal is n."""
        side = self.side * -keep  # now <= 0 means kept
        try:
            return self._clip_faces(side, n, d)
        except GeometryError:
            # Near-degenerate cut (points within round-off of each other in odd places): the
            # hull of the kept points is always closed, planes are re-matched for the tags.
            return self._clip_hull(side, n, d)

    # -------------------------------------------------------------- direct face clipping
    def _clip_faces(self, side: np.ndarray, n: np.ndarray, d: float) -> ConvexPolyhedron:
        poly = self.poly
        ok, start, verts, kept, used = _clip_kernel(
            self.points, poly.n_vertices, poly.face_start, poly.face_verts, side,
            self.edge_key, self.snap, n)
        if not ok:
            raise GeometryError("cut section has fewer than 3 distinct corners")
        v, normals, offsets, ftags = _piece_arrays(
            self.points, used, kept, poly.normals, poly.offsets, face_tags(poly), n, d,
            self.tag)
        return ConvexPolyhedron.from_csr(v, start, verts, normals, offsets, ftags, fresh=True)

    # -------------------------------------------------------------- fallback: hull
    def _clip_hull(self, side: np.ndarray, n: np.ndarray, d: float) -> ConvexPolyhedron:
        poly = self.poly
        nv = poly.n_vertices
        kept = np.concatenate(
            [np.flatnonzero(side <= 0), nv + np.flatnonzero(~np.isnan(self.points[nv:, 0]))]
        )
        used, faces, _ = hull_faces(self.points[kept], None)
        v = self.points[kept][used]
        cand_n = np.concatenate([poly.normals, n[None, :]])
        cand_d = np.concatenate([poly.offsets, [d]])
        cand_t = np.concatenate([face_tags(poly), [self.tag]])
        match = [_match_plane(v[f], cand_n, cand_d) for f in faces]
        return ConvexPolyhedron.from_faces(v, faces, cand_n[match], cand_d[match]).with_face_tag(
            cand_t[match]
        )


def _match_plane(face_pts: np.ndarray, cand_n: np.ndarray, cand_d: np.ndarray) -> int:
    """Index of the candidate plane that a face polygon lies on (smallest distance)."""
    area = cross(face_pts - face_pts[0], np.roll(face_pts, -1, axis=0) - face_pts[0]).sum(axis=0)
    nf = area / np.linalg.norm(area)
    err = np.max(np.abs(face_pts @ cand_n.T - cand_d), axis=0)
    err[cand_n @ nf < _PLANE_MATCH_COS] = np.inf
    k = int(np.argmin(err))
    if not np.isfinite(err[k]):
        raise GeometryError("a cut piece's face lies on none of the cutting planes")
    return k


# ---------------------------------------------------------------------------- the face clip
@kernel
def _piece_arrays(points, used, kept, normals, offsets, tags, n, d, tag):
    """A clipped piece's vertices (``points[used]``) and its faces' planes and tags: the
    parent's kept faces', then the cap's (``n``, ``d``, ``tag``). Copies only, compiled (four
    numpy concatenations a piece)."""
    v = np.empty((used.shape[0], 3))
    for i in range(used.shape[0]):
        for j in range(3):
            v[i, j] = points[used[i], j]
    nk = kept.shape[0]
    out_n = np.empty((nk + 1, 3))
    out_d = np.empty(nk + 1)
    out_t = np.empty(nk + 1, np.int64)
    for i in range(nk):
        f = kept[i]
        for j in range(3):
            out_n[i, j] = normals[f, j]
        out_d[i] = offsets[f]
        out_t[i] = tags[f]
    for j in range(3):
        out_n[nk, j] = n[j]
    out_d[nk] = d
    out_t[nk] = tag
    return v, out_n, out_d, out_t


@kernel
def _clip_kernel(points, nv, face_start, face_verts, side, edge_key, snap, n):
    """One piece of a plane cut, compiled (every cut piece of a rock mass is made here: in
    Python, per face and per point, it was most of a rock mass's build).

    Each face polygon is clipped to ``side <= 0`` (Sutherland-Hodgman; a crossing edge's point
    is ``nv +`` its index in ``edge_key``); a face left with 3 or more points not all on the
    plane is kept. The points on the plane (cut points and vertices with ``side == 0``) within
    ``snap`` of a smaller one become it; repeats in a face are dropped; the cap is the merged
    points on the plane, counter-clockwise seen along ``n``. Returns ``(ok, face_start,
    face_verts, kept, used)``: the faces (the kept ones, then the cap) over the local ids
    ``0..len(used)``, ``kept`` the parent's indices of the kept faces, ``used`` the points
    used; ``ok`` False when the cap has fewer than 3 distinct corners."""
    nf = face_start.shape[0] - 1
    cap_total = face_verts.shape[0] * 2 + 2
    start = np.zeros(nf + 2, np.int64)
    ids = np.empty(cap_total + points.shape[0], np.int64)
    kept = np.empty(nf, np.int64)
    nk = 0
    pos = 0
    for f in range(nf):
        f0 = face_start[f]
        k = face_start[f + 1] - f0
        p0 = pos
        on = 0
        for i in range(k):
            p = face_verts[f0 + i]
            q = face_verts[f0 + (i + 1) % k]
            if side[p] <= 0:
                ids[pos] = p
                pos += 1
                on += 1 if side[p] == 0 else 0
            if side[p] * side[q] < 0:
                key = min(p, q) * nv + max(p, q)
                ids[pos] = nv + np.searchsorted(edge_key, key)
                pos += 1
                on += 1
        if pos - p0 >= 3 and on < pos - p0:
            kept[nk] = f
            nk += 1
            start[nk] = pos
        else:
            pos = p0
    # the points on the plane, sorted, and each merged into the smallest one within snap
    on_plane = np.zeros(points.shape[0], np.bool_)
    for j in range(pos):
        i = ids[j]
        if i >= nv or side[i] == 0:
            on_plane[i] = True
    cap_ids = np.nonzero(on_plane)[0]
    rep = np.arange(points.shape[0])
    for a in range(cap_ids.shape[0]):
        i = cap_ids[a]
        for b in range(cap_ids.shape[0]):
            g = cap_ids[b]
            dx = points[i, 0] - points[g, 0]
            dy = points[i, 1] - points[g, 1]
            dz = points[i, 2] - points[g, 2]
            if np.sqrt(dx * dx + dy * dy + dz * dz) <= snap:
                rep[i] = g
                break
    # the kept faces remapped, their cyclic repeats dropped; faces left with < 3 points go
    out = np.empty_like(ids)
    ostart = np.zeros(nk + 2, np.int64)
    okept = np.empty(nk, np.int64)
    no = 0
    opos = 0
    for m in range(nk):
        s0 = start[m]
        s1 = start[m + 1]
        k = s1 - s0
        o0 = opos
        for j in range(k):
            cur = rep[ids[s0 + j]]
            prev = rep[ids[s0 + (j - 1) % k]]
            if k <= 1 or cur != prev:
                out[opos] = cur
                opos += 1
        if opos - o0 >= 3:
            okept[no] = kept[m]
            no += 1
            ostart[no] = opos
        else:
            opos = o0
    # the cap ring: the distinct merged points, by angle about their mean seen along n
    is_rep = np.zeros(points.shape[0], np.bool_)
    for a in range(cap_ids.shape[0]):
        is_rep[rep[cap_ids[a]]] = True
    ring = np.nonzero(is_rep)[0]
    kr = ring.shape[0]
    if kr < 3:
        return False, ostart, out, okept, ring
    order = ring_order(points[ring], n)
    for a in range(kr):
        out[opos] = ring[order[a]]
        opos += 1
    ostart[no + 1] = opos
    # local ids: the used points in increasing order
    used_mask = np.zeros(points.shape[0], np.bool_)
    for j in range(opos):
        used_mask[out[j]] = True
    used = np.nonzero(used_mask)[0]
    local = np.full(points.shape[0], -1, np.int64)
    for a in range(used.shape[0]):
        local[used[a]] = a
    verts = np.empty(opos, np.int64)
    for j in range(opos):
        verts[j] = local[out[j]]
    return True, ostart[:no + 2], verts, okept[:no], used


# ---------------------------------------------------------------------------- joint sets
def _sincosd(deg: float) -> tuple[float, float]:
    """``sin`` and ``cos`` of an angle in degrees, exact at multiples of 90 degrees."""
    r = float(deg) % 360.0
    exact = {0.0: (0.0, 1.0), 90.0: (1.0, 0.0), 180.0: (0.0, -1.0), 270.0: (-1.0, 0.0)}
    if r in exact:
        return exact[r]
    rad = np.radians(r)
    return float(np.sin(rad)), float(np.cos(rad))


def dip_normal(dip: float, dip_direction: float) -> np.ndarray:
    """Upward unit normal of a plane with the given dip and dip direction (degrees).

    ``n = (sin(dip) sin(dd), sin(dip) cos(dd), cos(dip))`` with x = east, y = north, z = up,
    dip below horizontal in ``[0, 90]``, dip direction clockwise from north. Multiples of 90
    degrees give exact axis components (so e.g. a vertical east-dipping set is exactly
    ``x = const``).
    """
    if not (np.isfinite(dip) and np.isfinite(dip_direction)) or not 0.0 <= dip <= 90.0:
        raise GeometryError(
            f"dip must be in [0, 90] degrees and dip direction finite, got {dip}, {dip_direction}"
        )
    sd, cd = _sincosd(dip)
    sa, ca = _sincosd(dip_direction)
    n = np.array([sd * sa, sd * ca, cd])
    return n / np.linalg.norm(n)


def joint_set_planes(
    dip: float,
    dip_direction: float,
    origin,
    spacing: float | None = None,
    count: int | None = None,
    bounds=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Planes of a joint set given as an engineer would: orientation, a point, a spacing.

    Parameters
    ----------
    dip, dip_direction : float
        Degrees; see :func:`dip_normal`.
    origin : (3,) array_like
        A point on one plane of the set.
    spacing : float, optional
        Normal distance between consecutive planes. ``None``: a single plane through
        ``origin`` (``count`` must then be ``None`` or 0; ``bounds`` is ignored).
    count : int, optional
        Number of planes on EACH side of the plane through ``origin``: the planes are
        ``origin + k * spacing * n`` for ``k = -count, ..., count``, i.e. ``2 * count + 1``
        planes. Takes precedence over ``bounds``.
    bounds : (2, 3) array_like, optional
        ``(lo, hi)`` of an axis-aligned box; used when ``count`` is ``None``: all planes
        ``origin + k * spacing * n`` (any integer ``k``) passing strictly through the box.

    Returns
    -------
    normal : (3,) float64
        Upward unit normal (see :func:`dip_normal`).
    offsets : (m,) float64
        Ascending plane offsets, ``normal . x = offsets[i]``.
    """
    n = dip_normal(dip, dip_direction)
    o = np.asarray(origin, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(o)):
        raise GeometryError(f"joint set origin must be finite, got {o}")
    d0 = float(n @ o)
    if spacing is None:
        if count:
            raise GeometryError("a joint set with a count needs a spacing")
        return n, np.array([d0])
    spacing = float(spacing)
    if not (np.isfinite(spacing) and spacing > 0.0):
        raise GeometryError(f"joint spacing must be positive, got {spacing}")
    if count is not None:
        if int(count) != count or count < 0:
            raise GeometryError(f"joint count must be a non-negative integer, got {count}")
        k = np.arange(-int(count), int(count) + 1)
    elif bounds is not None:
        k = _fill_indices(n, d0, spacing, bounds)
    else:
        raise GeometryError("a joint set with a spacing needs a count or bounds")
    return n, d0 + k * spacing


def _fill_indices(n: np.ndarray, d0: float, spacing: float, bounds) -> np.ndarray:
    """Plane indices ``k`` with ``d0 + k * spacing`` strictly inside the box's extent along n."""
    lo, hi = (np.asarray(b, dtype=np.float64).reshape(3) for b in bounds)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi < lo):
        raise GeometryError(f"bounds must be finite (lo, hi) with lo <= hi, got {lo}, {hi}")
    corners = np.where(((np.arange(8)[:, None] >> np.arange(3)) & 1) == 1, hi, lo)
    proj = corners @ n
    k = np.arange(np.floor((proj.min() - d0) / spacing), np.ceil((proj.max() - d0) / spacing) + 1)
    d = d0 + k * spacing
    return k[(d > proj.min()) & (d < proj.max())].astype(np.int64)


# ---------------------------------------------------------------------------- many blocks
def _plane_tags(tags, m: int) -> np.ndarray:
    t = np.asarray(tags)
    if t.ndim == 0:
        t = np.full(m, int(t), dtype=np.int64)
    if t.shape != (m,) or not np.issubdtype(t.dtype, np.integer):
        raise GeometryError(f"tags must be an int or {m} ints (one per plane), got {tags!r}")
    return t.astype(np.int64)


def _selected(polys: Sequence[ConvexPolyhedron], select) -> np.ndarray:
    if select is None:
        return np.ones(len(polys), dtype=bool)
    if callable(select):
        return np.array([bool(select(p)) for p in polys], dtype=bool)
    sel = np.asarray(select, dtype=bool)
    if sel.shape != (len(polys),):
        raise GeometryError(f"select must be a callable or {len(polys)} booleans")
    return sel


def _cut_one(poly, n, offsets, tags, tol) -> list[ConvexPolyhedron]:
    """Pieces of one block cut by parallel planes with ascending offsets, in offset order."""
    out = []
    rest = _tagged(poly)
    # Planes outside the block's extent along n cannot cut it: skip them without a split.
    proj = poly.vertices @ n
    window = slice(*np.searchsorted(offsets, [proj.min(), proj.max()], side="right"))
    # the set's unit normal and the tolerance once, each plane's offset over the same norm
    # (split_by_plane's numbers)
    unit, _ = _unit_plane(n, 0.0)
    norm = float(np.linalg.norm(np.asarray(n, dtype=np.float64).reshape(3)))
    tol = _check_tol(tol)
    for d, t in zip(offsets[window], tags[window], strict=True):
        d = float(d)
        if not np.isfinite(d):
            raise GeometryError(f"invalid plane: normal {unit * norm}, offset {d}")
        below, above, cut = _unit_plane_cut(rest, unit, d / norm, tol, t)
        if cut is not None:
            below, above = cut.piece(unit, d / norm, keep=-1), cut.piece(-unit, -d / norm,
                                                                          keep=1)
        if above is None:  # this plane, and every later (higher) one, is above what is left
            break
        if below is not None:
            out.append(below)
            rest = above
    out.append(rest)
    return out


def cut_blocks(
    polys: Sequence[ConvexPolyhedron],
    tags,
    normal,
    offsets,
    tol: float = 0.0,
    select: Callable[[ConvexPolyhedron], bool] | Sequence[bool] | None = None,
) -> tuple[list[ConvexPolyhedron], np.ndarray]:
    """Cut every block by a set of parallel planes ``normal . x = offsets[i]``.

    Parameters
    ----------
    polys : sequence of ConvexPolyhedron
        Parent blocks.
    tags : int or (m,) int array_like
        ``face_tag`` given to faces made by the planes: one value for the whole set (e.g.
        the joint set's index) or one per plane (in the order of ``offsets``).
    normal : (3,) array_like
        Common plane normal (need not be unit; ``offsets`` are in its units).
    offsets : (m,) array_like
        Plane offsets, any order, duplicates allowed.
    tol : float
        Sliver thickness, see :func:`split_by_plane`.
    select : callable or (len(polys),) bool array_like, optional
        Which parents to cut: ``select(poly) -> bool`` or a mask; the others are passed
        through whole. Default: all.

    Returns
    -------
    pieces : list of ConvexPolyhedron
        For each parent in order, its pieces in increasing ``normal . x`` (a parent that no
        plane cuts, or that is not selected, gives one piece: itself). All carry
        ``face_tag``. Deterministic for given inputs; a caller may name piece ``k`` of
        parent ``P`` as ``P[k]`` (see :func:`piece_names`).
    parent : (len(pieces),) int64
        Index into ``polys`` of each piece's parent (non-decreasing).
    """
    d = np.asarray(offsets, dtype=np.float64).reshape(-1)
    n, scale = _unit_plane(normal, 1.0)
    d = d * scale
    t = _plane_tags(tags, len(d))
    order = np.argsort(d, kind="stable")
    d, t = d[order], t[order]
    tol = _check_tol(tol)
    pieces, parent = [], []
    for i, (poly, sel) in enumerate(zip(polys, _selected(polys, select), strict=True)):
        out = _cut_one(poly, n, d, t, tol) if sel else [_tagged(poly)]
        pieces.extend(out)
        parent.extend([i] * len(out))
    return pieces, np.array(parent, dtype=np.int64)


def piece_names(names: Sequence[str], parent) -> list[str]:
    """Names ``P[k]`` for the pieces of :func:`cut_blocks`: parent name and piece number.

    Parameters
    ----------
    names : sequence of str
        Parent names, indexed like the ``polys`` given to :func:`cut_blocks`.
    parent : (n,) int array_like
        Parent index of each piece, as returned by :func:`cut_blocks`.

    Returns
    -------
    list of str
        ``f"{names[p]}[{k}]"`` where ``k`` counts the pieces of parent ``p`` from 0.
    """
    seen: dict[int, int] = {}
    out = []
    for p in np.asarray(parent, dtype=np.int64).tolist():
        k = seen.get(p, 0)
        seen[p] = k + 1
        out.append(f"{names[p]}[{k}]")
    return out


# ---------------------------------------------------------------------------- excavation
def box_planes(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals ``(6, 3)`` and offsets ``(6,)`` of the box ``[lo, hi]``."""
    lo = np.asarray(lo, dtype=np.float64).reshape(3)
    hi = np.asarray(hi, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi <= lo):
        raise GeometryError(f"box needs finite lo < hi in every axis, got lo={lo}, hi={hi}")
    return BOX_NORMALS.copy(), np.array([-lo[0], hi[0], -lo[1], hi[1], -lo[2], hi[2]])


def cylinder_planes(start, end, radius: float, sides: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Bounding planes of a polygonal prism approximating a cylinder (e.g. a tunnel).

    The cross-section is the regular ``sides``-gon inscribed in the circle of ``radius`` (its
    corners on the circle), so the prism's volume is
    ``radius**2 * sides * sin(2 pi / sides) / 2 * |end - start|``. Its first corner lies along
    ``u = unit(e x a)``, ``a`` the axis direction and ``e`` the coordinate axis least aligned
    with ``a`` (for a horizontal tunnel along x, ``u`` is vertical).

    Parameters
    ----------
    start, end : (3,) array_like
        Centres of the two end faces.
    radius : float
        Circumradius of the cross-section.
    sides : int
        Number of lateral faces, at least 3.

    Returns
    -------
    normals : (sides + 2, 3) float64
        Outward unit normals: the ``sides`` lateral faces, then the start and end caps.
    offsets : (sides + 2,) float64
        Plane offsets; the prism is ``normals @ x <= offsets``.
    """
    p0 = np.asarray(start, dtype=np.float64).reshape(3)
    p1 = np.asarray(end, dtype=np.float64).reshape(3)
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    if not (np.all(np.isfinite(axis)) and length > 0.0):
        raise GeometryError(f"cylinder needs distinct finite end points, got {p0}, {p1}")
    if not (np.isfinite(radius) and radius > 0.0) or int(sides) != sides or sides < 3:
        raise GeometryError(f"cylinder needs radius > 0 and sides >= 3, got {radius}, {sides}")
    a = axis / length
    u = cross(np.eye(3)[int(np.argmin(np.abs(a)))], a)
    u /= np.linalg.norm(u)
    w = cross(a, u)
    phi = (np.arange(sides) + 0.5) * (2.0 * np.pi / sides)  # face normals between corners
    lateral = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w
    normals = np.concatenate([lateral, [-a, a]])
    apothem = radius * np.cos(np.pi / sides)
    offsets = np.concatenate([lateral @ p0 + apothem, [-a @ p0, a @ p1]])
    return normals, offsets


def _region_planes(region: Region) -> tuple[np.ndarray, np.ndarray]:
    """Unit outward normals and offsets of a convex region (planes or a polyhedron)."""
    if isinstance(region, ConvexPolyhedron):
        return np.asarray(region.normals), np.asarray(region.offsets)
    N, D = region
    N = np.asarray(N, dtype=np.float64)
    D = np.asarray(D, dtype=np.float64).reshape(-1)
    if N.ndim != 2 or N.shape[1] != 3 or len(N) != len(D):
        raise GeometryError(
            f"region planes must be normals (m, 3) and offsets (m,), got {N.shape}, {D.shape}"
        )
    planes = [_unit_plane(n, d) for n, d in zip(N, D, strict=True)]
    return np.array([p[0] for p in planes]).reshape(-1, 3), np.array([p[1] for p in planes])


def _active_planes(poly, N, D, tol) -> list[int] | None:
    """Region planes bounding the overlap of ``poly`` and the region, or None if they do not overlap."""
    # Cheap rejection first (most blocks of a model are far from an excavation), with the
    # same thickness criterion as split_by_plane.
    thin = max(tol, default_tolerance(poly.vertices))
    if np.any((poly.vertices @ N.T - D).min(axis=0) > -thin):
        return None
    inner = poly.with_face_tag(np.full(poly.n_faces, UNTAGGED, dtype=np.int64))
    for i, (n, d) in enumerate(zip(N, D, strict=True)):
        inner, _ = split_by_plane(inner, n, d, tol, tag=i)
        if inner is None:
            return None
    # A region plane carrying no face of the intersection is redundant there (for a full-
    # dimensional convex intersection, irredundant half-spaces are exactly its facets), so
    # cutting by it would only chop the block needlessly.
    return sorted(set(inner.face_tag.tolist()) - {UNTAGGED})


def excavate(
    poly: ConvexPolyhedron, region: Region, tol: float = 0.0, tag: int = UNTAGGED
) -> tuple[list[ConvexPolyhedron], float]:
    """Remove a convex region from a convex block.

    The block is cut by each region plane that bounds the overlap in turn; the part outside
    the plane is kept as a piece and cutting continues with the inside remainder, which is
    removed at the end. Blocks that do not overlap the region are returned whole; blocks
    fully inside it vanish.

    Parameters
    ----------
    poly : ConvexPolyhedron
        Block.
    region : (normals (m, 3), offsets (m,)) or ConvexPolyhedron
        Convex region ``normals @ x <= offsets``, e.g. from :func:`box_planes` or
        :func:`cylinder_planes`.
    tol : float
        Sliver thickness, see :func:`split_by_plane`: an overlap thinner than ``tol`` is not
        excavated and an outside sliver is removed with the region.
    tag : int
        ``face_tag`` of the faces made on the excavation surface.

    Returns
    -------
    pieces : list of ConvexPolyhedron
        Convex pieces of the block outside the region, in the order of the region planes
        that cut them off.
    removed : float
        Volume removed (0.0 if the block does not overlap the region).
    """
    tol = _check_tol(tol)
    N, D = _region_planes(region)
    active = _active_planes(poly, N, D, tol)
    if active is None:
        return [_tagged(poly)], 0.0
    pieces = []
    rest = _tagged(poly)
    for i in active:
        inside, outside = split_by_plane(rest, N[i], D[i], tol, tag)
        if outside is not None:
            pieces.append(outside)
        rest = inside
        if rest is None:
            return pieces, 0.0
    return pieces, float(rest.volume)


def excavate_blocks(
    polys: Sequence[ConvexPolyhedron], region: Region, tol: float = 0.0, tag: int = UNTAGGED
) -> tuple[list[ConvexPolyhedron], np.ndarray, np.ndarray]:
    """Apply :func:`excavate` to every block.

    Returns
    -------
    pieces : list of ConvexPolyhedron
        For each parent in order, its pieces outside the region.
    parent : (len(pieces),) int64
        Index into ``polys`` of each piece's parent.
    removed : (len(polys),) float64
        Volume removed from each parent.
    """
    pieces, parent, removed = [], [], np.zeros(len(polys))
    for i, poly in enumerate(polys):
        out, removed[i] = excavate(poly, region, tol, tag)
        pieces.extend(out)
        parent.extend([i] * len(out))
    return pieces, np.array(parent, dtype=np.int64), removed
