"""``ConvexPolyhedron``: the immutable geometry record of one convex block."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pdem.geometry.errors import GeometryError
from pdem.geometry.mass import fan_triangles, mass_properties
from pdem.geometry.topology import build_half_edges, cut_piece_edges

from .vector import cross


def _readonly(a: np.ndarray, dtype) -> np.ndarray:
    # Always copy: never freeze (or alias) an array the caller still owns.
    out = np.array(a, dtype=dtype, order="C", copy=True)
    out.flags.writeable = False
    return out


def newell_normal(points: np.ndarray) -> np.ndarray:
    """Area vector of a planar polygon (Newell's method): ``2 * area * unit normal``.

    Parameters
    ----------
    points : (k, 3) float64
        Polygon vertices in order.

    Returns
    -------
    (3,) float64
        Sum of ``p_i x p_{i+1}`` taken about the polygon's mean (for round-off).
    """
    p = points - points.mean(axis=0)
    return cross(p, np.roll(p, -1, axis=0)).sum(axis=0)


def face_area_vectors(v: np.ndarray, face_start: np.ndarray, face_verts: np.ndarray):
    """``2 * area * unit normal`` of every face, from its triangle fan (vectorised Newell)."""
    tri = fan_triangles(face_start, face_verts)
    a = v[tri[:, 0]]
    cr = cross(v[tri[:, 1]] - a, v[tri[:, 2]] - a)
    face_of_tri = np.repeat(np.arange(len(face_start) - 1), np.diff(face_start) - 2)
    out = np.zeros((len(face_start) - 1, 3))
    np.add.at(out, face_of_tri, cr)
    return out


_EYE = np.eye(3)


def _is_rotation(R: np.ndarray, tol: float = 1e-9) -> bool:
    """``np.allclose(R @ R.T, I, atol=tol)`` (its default ``rtol`` 1e-5 on the diagonal) and a
    positive determinant; without allclose's and LAPACK's overhead (~50 us a call; every
    piece of a joined block is moved into its body frame through here). The determinant's
    sign is that of the triple product for an orthonormal R."""
    err = np.abs(R @ R.T - _EYE)
    if not (err <= tol + 1e-5 * _EYE).all():  # (NaN fails too)
        return False
    a, b, c = R.tolist()
    return a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2]) \
        + a[2] * (b[0] * c[1] - b[1] * c[0]) > 0.0


@dataclass(frozen=True, eq=False)
class ConvexPolyhedron:
    """A closed convex polyhedron with planar polygon faces and half-edge connectivity.

    Build instances with :meth:`from_faces` or the builders in :mod:`pdem.geometry.builders`;
    the derived fields (normals, edges, half-edges, mass properties) are filled in there.
    Arrays are read-only.

    Attributes
    ----------
    vertices : (nv, 3) float64
        Vertex coordinates.
    face_start : (nf+1,) int64
        CSR offsets into ``face_verts``.
    face_verts : (sum,) int64
        Vertex ids of each face, counter-clockwise seen from outside (right-hand rule gives
        the outward normal). Half-edge ``h`` leaves ``face_verts[h]``.
    normals : (nf, 3) float64
        Unit outward face normals.
    offsets : (nf,) float64
        Plane offsets, ``normals[f] . x = offsets[f]`` on face ``f``; inside is ``<=``.
    edges : (ne, 2) int64
        Unique edges ``(i, j)`` with ``i < j``, sorted lexicographically.
    he_origin, he_twin, he_next, he_face : (sum,) int64
        Half-edge start vertex, opposite half-edge, next half-edge around the same face, face
        (properties: made on first use and kept; a rock mass holds every cut piece on every
        rank at set-up, and their five arrays were ~40 % of a piece).
    vert_he : (nv,) int64
        One outgoing half-edge per vertex; ``he_next[he_twin[h]]`` is the next outgoing
        half-edge around the vertex, so faces/edges at a vertex cost O(degree).
    volume : float
        Enclosed volume.
    centroid : (3,) float64
        Centre of volume.
    inertia : (3, 3) float64
        Inertia tensor about the centroid per unit density (multiply by density for mass
        moments).
    face_tag : (nf,) int64 or None
        Optional per-face integer label recording where each face came from (e.g. the joint
        set whose cut made it, see :mod:`pdem.geometry.cutting`); ``None`` if never set.
        Rigid transforms keep it, since they keep the face order.
    """

    vertices: np.ndarray
    face_start: np.ndarray
    face_verts: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    edges: np.ndarray
    volume: float
    centroid: np.ndarray
    inertia: np.ndarray
    face_tag: np.ndarray | None = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_faces(
        cls,
        vertices: np.ndarray,
        faces: list[np.ndarray] | list[list[int]],
        normals: np.ndarray | None = None,
        offsets: np.ndarray | None = None,
    ) -> ConvexPolyhedron:
        """Build from vertices and face polygons, computing every derived field.

        Parameters
        ----------
        vertices : (nv, 3) array_like
            Vertex coordinates; every vertex must be used by some face.
        faces : sequence of int sequences
            Each face's vertex ids, counter-clockwise seen from outside.
        normals, offsets : optional
            Known exact face planes (e.g. the cutting planes a block came from). By default
            the normal is the normalised Newell area vector and the offset the mean of
            ``n . x`` over the face's vertices.

        Returns
        -------
        ConvexPolyhedron

        Raises
        ------
        GeometryError
            If the faces are not a closed, outward-oriented manifold or the volume is not
            positive. Convexity itself is not re-checked here (the hull guarantees it).
        """
        v = np.asarray(vertices, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise GeometryError(f"vertices must have shape (nv, 3), got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise GeometryError("vertices contain NaN or inf")
        counts = np.array([len(f) for f in faces], dtype=np.int64)
        face_start = np.zeros(len(faces) + 1, dtype=np.int64)
        np.cumsum(counts, out=face_start[1:])
        face_verts = (
            np.concatenate([np.asarray(f, dtype=np.int64) for f in faces])
            if faces
            else np.empty(0, dtype=np.int64)
        )
        return cls.from_csr(v, face_start, face_verts, normals, offsets)

    @classmethod
    def from_csr(cls, v, face_start, face_verts, normals=None, offsets=None,
                 face_tag=None, fresh: bool = False) -> ConvexPolyhedron:
        """:meth:`from_faces` with the faces in CSR form (``face_start``, ``face_verts``,
        int64) and ``v`` a finite (nv, 3) float64 array; ``face_tag``: one int64 per face
        (:meth:`with_face_tag` without the copy). ``fresh``: the arrays given were made for
        this polyhedron (float64 and int64) and nobody else holds them: copied into one
        buffer instead of nine arrays."""
        return _from_csr(v, face_start, face_verts, normals, offsets, face_tag, fresh)

    def with_face_tag(self, face_tag) -> ConvexPolyhedron:
        """Copy of the polyhedron carrying the per-face labels ``face_tag``.

        Parameters
        ----------
        face_tag : (nf,) array_like of int
            One label per face, in face order.

        Returns
        -------
        ConvexPolyhedron
            Same geometry (arrays shared), ``face_tag`` set (read-only int64).
        """
        tag = np.asarray(face_tag)
        if tag.shape != (self.n_faces,) or (tag.size and not np.issubdtype(tag.dtype, np.integer)):
            raise GeometryError(f"face_tag must be {self.n_faces} integers, got {tag.dtype} {tag.shape}")
        return dataclasses.replace(self, face_tag=_readonly(tag, np.int64))

    def moved(self, **fields) -> ConvexPolyhedron:
        """Copy with the given fields replaced, as ``dataclasses.replace`` (no check), for a
        builder that computed them from this polyhedron by a rigid motion (read-only arrays it
        owns): a fraction of ``replace``'s time, for the members of a large array."""
        new = object.__new__(ConvexPolyhedron)
        d = new.__dict__
        d.update(self.__dict__)
        d.pop("_face_areas", None)  # the cache is the moved shape's own
        d.update(fields)
        return new

    # ------------------------------------------------------------------ pickling
    def __reduce_ex__(self, protocol):
        """Pickled as one buffer of its arrays' bytes and their sizes, not nine arrays: the
        ranks that share a rock mass's build send each other pieces (its slices moved and
        neighbours fetched, pdem.model.spread), and pickling nine small arrays a piece cost
        ~3x the pickle's size in the heap; unpickled, the arrays are read-only views of that
        one buffer. Caches (half-edges, face areas) are not sent: they are made again,
        alike, on first use."""
        floats = (self.vertices, self.normals, self.offsets, self.centroid, self.inertia)
        ints = (self.face_start, self.face_verts, self.edges) + (
            () if self.face_tag is None else (self.face_tag,))
        if any(a.dtype != np.float64 for a in floats) or any(a.dtype != np.int64 for a in ints):
            return super().__reduce_ex__(protocol)
        blob = b"".join([a.tobytes() for a in floats + ints])
        return _unpacked, (blob, self.n_vertices, self.n_faces, len(self.face_verts),
                           self.n_edges, self.face_tag is not None, self.volume)

    # ------------------------------------------------------------------ sizes
    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        """Number of faces."""
        return len(self.face_start) - 1

    @property
    def n_edges(self) -> int:
        """Number of (undirected) edges."""
        return len(self.edges)

    # ------------------------------------------------------------------ queries
    def face_vertex_ids(self, f: int) -> np.ndarray:
        """Vertex ids of face ``f``, counter-clockwise seen from outside."""
        return self.face_verts[self.face_start[f] : self.face_start[f + 1]]

    def face_polygon(self, f: int) -> np.ndarray:
        """Vertex coordinates ``(k, 3)`` of face ``f``, counter-clockwise seen from outside."""
        return self.vertices[self.face_vertex_ids(f)]

    def face_area(self, f: int) -> float:
        """Area of face ``f``."""
        return 0.5 * float(np.linalg.norm(newell_normal(self.face_polygon(f))))

    def face_areas(self) -> np.ndarray:
        """Area of every face (read-only), bitwise equal to :meth:`face_area`; computed once."""
        areas = self.__dict__.get("_face_areas")
        if areas is None:
            face_areas([self])
            areas = self.__dict__["_face_areas"]
        return areas

    # ------------------------------------------------------------------ half-edges
    def _half_edges(self):
        he = self.__dict__.get("_he")
        if he is None:  # checked when the polyhedron was made: the same arrays again
            he = build_half_edges(self.n_vertices, self.face_start, self.face_verts)
            for a in (he.origin, he.twin, he.next, he.face, he.vert_he):
                a.flags.writeable = False
            self.__dict__["_he"] = he
        return he

    @property
    def he_origin(self) -> np.ndarray:
        return self._half_edges().origin

    @property
    def he_twin(self) -> np.ndarray:
        return self._half_edges().twin

    @property
    def he_next(self) -> np.ndarray:
        return self._half_edges().next

    @property
    def he_face(self) -> np.ndarray:
        return self._half_edges().face

    @property
    def vert_he(self) -> np.ndarray:
        return self._half_edges().vert_he

    def vertex_half_edges(self, v: int) -> np.ndarray:
        """Outgoing half-edges of vertex ``v``, walking clockwise seen from outside."""
        h0 = int(self.vert_he[v])
        out = [h0]
        h = int(self.he_next[self.he_twin[h0]])
        while h != h0:
            out.append(h)
            h = int(self.he_next[self.he_twin[h]])
        return np.array(out, dtype=np.int64)

    def vertex_faces(self, v: int) -> np.ndarray:
        """Faces incident to vertex ``v`` (O(degree), by walking half-edges)."""
        return self.he_face[self.vertex_half_edges(v)]

    def vertex_neighbors(self, v: int) -> np.ndarray:
        """Vertices joined to ``v`` by an edge (O(degree))."""
        return self.he_origin[self.he_next[self.vertex_half_edges(v)]]

    def radius(self) -> float:
        """Largest distance from the centroid to a vertex."""
        return float(np.sqrt(((self.vertices - self.centroid) ** 2).sum(axis=1).max()))

    # ------------------------------------------------------------------ transforms
    def transformed(self, R: np.ndarray, t: np.ndarray) -> ConvexPolyhedron:
        """Rigidly move the polyhedron: ``x' = R x + t``.

        Parameters
        ----------
        R : (3, 3) array_like
            Proper rotation matrix (orthonormal, det = +1). Reflections are rejected because
            they would turn the faces inside out.
        t : (3,) array_like
            Translation.

        Returns
        -------
        ConvexPolyhedron
            New polyhedron; topology shared, normals rotated, inertia ``R I R^T``.
        """
        return _transformed(self, R, t)

    def principal_frame(self) -> tuple[ConvexPolyhedron, np.ndarray, np.ndarray, np.ndarray]:
        """Express the polyhedron in its principal body frame.

        Returns
        -------
        body : ConvexPolyhedron
            The polyhedron with origin at the centroid and axes along the principal axes;
            its ``centroid`` is exactly zero and its ``inertia`` exactly ``diag(moments)``.
        centroid : (3,) float64
            World position of the body origin.
        R : (3, 3) float64
            Proper rotation (det = +1) whose columns are the principal axes in world
            coordinates: ``world = R @ body + centroid``.
        moments : (3,) float64
            Principal moments per unit density, ascending.
        """
        return _principal_frame(self)


def _from_csr(v, face_start, face_verts, normals, offsets, face_tag, fresh
              ) -> ConvexPolyhedron:
    """:meth:`ConvexPolyhedron.from_csr`: the checks, the derived fields (edges, planes,
    mass properties) and the read-only record."""
    faces = range(len(face_start) - 1)  # the face count, for the offsets below
    if fresh:  # a cut piece: the checks and the edges compiled, in the same order
        edges = cut_piece_edges(len(v), face_start, face_verts)
    else:
        if face_verts.size and (face_verts.min() < 0 or face_verts.max() >= len(v)):
            raise GeometryError("face vertex id out of range")
        edges = build_half_edges(len(v), face_start, face_verts).edges
    if normals is None:
        n = face_area_vectors(v, face_start, face_verts)
        norm = np.linalg.norm(n, axis=1)
        if np.any(norm == 0.0):
            raise GeometryError("a face has zero area")
        n = n / norm[:, None]
    else:
        n = np.asarray(normals, dtype=np.float64)
    if offsets is None:
        # Mean of n . x over each face's vertices (an average absorbs round-off).
        face_of = np.repeat(np.arange(len(faces)), np.diff(face_start))
        d = np.bincount(
            face_of, np.einsum("ij,ij->i", v[face_verts], n[face_of]), len(faces)
        ) / np.diff(face_start)
    else:
        d = np.asarray(offsets, dtype=np.float64)
    volume, centroid, inertia = mass_properties(v, face_start, face_verts)
    if not volume > 0.0:
        raise GeometryError(
            f"polyhedron volume is {volume:g}; faces must be counter-clockwise from outside"
        )
    if fresh:
        # one buffer for all its arrays, laid out as a pickled piece arrives: the arrays
        # the kernels made each carry numba's allocation record (kept, they were ~1.6 KB
        # a piece more than copies)
        return _packed(v, face_start, face_verts, n, d, edges, volume, centroid, inertia,
                       face_tag)
    return ConvexPolyhedron(
        vertices=_readonly(v, np.float64),
        face_start=_readonly(face_start, np.int64),
        face_verts=_readonly(face_verts, np.int64),
        normals=_readonly(n, np.float64),
        offsets=_readonly(d, np.float64),
        edges=_readonly(edges, np.int64),
        volume=volume,
        centroid=_readonly(centroid, np.float64),
        inertia=_readonly(inertia, np.float64),
        face_tag=None if face_tag is None else _readonly(face_tag, np.int64),
    )


def _transformed(p: ConvexPolyhedron, R, t) -> ConvexPolyhedron:
    """:meth:`ConvexPolyhedron.transformed`."""
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64).reshape(3)
    if R.shape != (3, 3) or not _is_rotation(R):
        raise GeometryError("R must be a proper rotation matrix (orthonormal, det = +1)")
    n = p.normals @ R.T
    c = R @ p.centroid + t
    return dataclasses.replace(
        p,
        vertices=_readonly(p.vertices @ R.T + t, np.float64),
        normals=_readonly(n, np.float64),
        offsets=_readonly(p.offsets + n @ t, np.float64),
        centroid=_readonly(c, np.float64),
        inertia=_readonly(R @ p.inertia @ R.T, np.float64),
    )


def _principal_frame(p: ConvexPolyhedron
                     ) -> tuple[ConvexPolyhedron, np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`ConvexPolyhedron.principal_frame`."""
    moments, R = np.linalg.eigh(p.inertia)
    if np.linalg.det(R) < 0.0:
        R[:, 2] = -R[:, 2]  # eigenvectors are defined up to sign: pick a right-handed frame
    c = np.array(p.centroid)
    n = p.normals @ R
    body = dataclasses.replace(
        p,
        vertices=_readonly((p.vertices - c) @ R, np.float64),
        normals=_readonly(n, np.float64),
        offsets=_readonly(p.offsets - p.normals @ c, np.float64),
        centroid=_readonly(np.zeros(3), np.float64),
        inertia=_readonly(np.diag(moments), np.float64),
    )
    return body, c, R, moments


# faces per numpy batch in :func:`face_areas` (bounds the (F, k, 3) polygon stack's memory)
_AREA_CHUNK = 1 << 17


def face_areas(polys) -> list[np.ndarray]:
    """Face areas of every polyhedron of ``polys``, each computed once and kept on it.

    Vectorised over all faces with the same vertex count, with the arithmetic of
    :meth:`ConvexPolyhedron.face_area` in the same order (the polygon's mean, Newell's
    cross products summed over its vertices, the norm as a dot product): the areas are
    bitwise those of the per-face call, which took most of a large model's set-up.
    """
    todo = [p for p in polys if "_face_areas" not in p.__dict__]
    if todo:
        nv = np.array([p.n_vertices for p in todo], np.int64)
        nfv = np.array([len(p.face_verts) for p in todo], np.int64)
        nf = np.array([p.n_faces for p in todo], np.int64)
        verts = np.concatenate([p.vertices for p in todo])
        voff = np.cumsum(nv) - nv
        fverts = np.concatenate([p.face_verts for p in todo]) + np.repeat(voff, nfv)
        # vertices per face: the differences of the concatenated face_start, less the one
        # across each polyhedron's end
        fs = np.concatenate([p.face_start for p in todo])
        ends = np.cumsum(nf + 1) - 1
        counts = np.delete(np.diff(fs), ends[:-1])
        fstart = np.cumsum(counts) - counts
        areas = np.empty(len(counts))
        for k in np.unique(counts):
            faces = np.nonzero(counts == k)[0]
            for c0 in range(0, len(faces), _AREA_CHUNK):
                sel = faces[c0:c0 + _AREA_CHUNK]
                pts = verts[fverts[fstart[sel, None] + np.arange(k)]]  # (F, k, 3) polygons
                pts = pts - pts.mean(axis=1)[:, None, :]
                a = cross(pts, np.roll(pts, -1, axis=1)).sum(axis=1)
                # vector @ vector per face: numpy's dot, as np.linalg.norm of one vector
                areas[sel] = 0.5 * np.sqrt(np.matmul(a[:, None, :], a[:, :, None])[:, 0, 0])
        for p, part in zip(todo, np.split(areas, np.cumsum(nf)[:-1]), strict=True):
            part.flags.writeable = False
            object.__setattr__(p, "_face_areas", part)
    return [p.__dict__["_face_areas"] for p in polys]


def _packed(v, face_start, face_verts, normals, offsets, edges, volume, centroid, inertia,
            face_tag) -> ConvexPolyhedron:
    """A polyhedron whose arrays are read-only views of one buffer (the layout of
    :func:`_unpacked`), copied from the given ones (float64 and int64 already)."""
    nv, nf, nfv, ne = len(v), len(face_start) - 1, len(face_verts), len(edges)
    n_float = 3 * nv + 4 * nf + 12
    n_int = nf + 1 + nfv + 2 * ne + (nf if face_tag is not None else 0)
    buf = np.empty(n_float + n_int)
    f8, i8 = buf[:n_float], buf[n_float:].view(np.int64)
    at = (0, 3 * nv, 3 * nv + 3 * nf, 3 * nv + 4 * nf, 3 * nv + 4 * nf + 3, n_float)
    it = (0, nf + 1, nf + 1 + nfv, nf + 1 + nfv + 2 * ne, n_int)
    for part, a, b in ((v, 0, 1), (normals, 1, 2), (offsets, 2, 3), (centroid, 3, 4),
                       (inertia, 4, 5)):
        f8[at[a]:at[b]] = part.reshape(-1)
    for part, a, b in ((face_start, 0, 1), (face_verts, 1, 2), (edges, 2, 3)):
        i8[it[a]:it[b]] = part.reshape(-1)
    if face_tag is not None:
        i8[it[3]:it[4]] = face_tag
    for a in (buf, f8, i8):  # the views below are read-only too
        a.flags.writeable = False
    return ConvexPolyhedron(
        vertices=f8[at[0]:at[1]].reshape(nv, 3), face_start=i8[it[0]:it[1]],
        face_verts=i8[it[1]:it[2]], normals=f8[at[1]:at[2]].reshape(nf, 3),
        offsets=f8[at[2]:at[3]], edges=i8[it[2]:it[3]].reshape(ne, 2), volume=volume,
        centroid=f8[at[3]:at[4]], inertia=f8[at[4]:at[5]].reshape(3, 3),
        face_tag=i8[it[3]:it[4]] if face_tag is not None else None)


def _unpacked(blob: bytes, nv: int, nf: int, nfv: int, ne: int, tagged: bool, volume: float
              ) -> ConvexPolyhedron:
    """A polyhedron from :meth:`ConvexPolyhedron.__reduce_ex__`'s buffer (read-only views)."""
    n_float = 3 * nv + 4 * nf + 12
    f8 = np.frombuffer(blob, np.float64, count=n_float)
    i8 = np.frombuffer(blob, np.int64, offset=8 * n_float)
    at = np.cumsum([0, 3 * nv, 3 * nf, nf, 3, 9])
    it = np.cumsum([0, nf + 1, nfv, 2 * ne, nf if tagged else 0])
    return ConvexPolyhedron(
        vertices=f8[at[0]:at[1]].reshape(nv, 3), face_start=i8[it[0]:it[1]],
        face_verts=i8[it[1]:it[2]], normals=f8[at[1]:at[2]].reshape(nf, 3),
        offsets=f8[at[2]:at[3]], edges=i8[it[2]:it[3]].reshape(ne, 2), volume=volume,
        centroid=f8[at[3]:at[4]], inertia=f8[at[4]:at[5]].reshape(3, 3),
        face_tag=i8[it[3]:it[4]] if tagged else None)
