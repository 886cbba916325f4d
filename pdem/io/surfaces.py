"""Block surfaces in their body frames, flat (the output's block meshes): from per-block lists,
or taken from a store's CSR geometry."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class BodyMesh(NamedTuple):
    """Every block's surface in its body frame, flat: vertices ``verts[vert_start[b]:
    vert_start[b+1]]``; faces in block order, ``face_len`` vertex ids each (block-local,
    counter-clockwise from outside) in ``face_verts``, ``face_block`` the block of each."""

    vert_start: np.ndarray
    verts: np.ndarray
    face_len: np.ndarray
    face_block: np.ndarray
    face_verts: np.ndarray

    @staticmethod
    def from_lists(body_vertices, body_faces) -> BodyMesh:
        """From per-block vertex arrays and face lists (checked: shapes)."""
        verts = [np.asarray(v, dtype=np.float64) for v in body_vertices]
        for b, v in enumerate(verts):
            if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
                raise ValueError(f"body_vertices[{b}]: shape {v.shape}, expected (nv, 3)")
        nv = np.array([len(v) for v in verts], dtype=np.int64)
        face_len = np.array([len(f) for faces in body_faces for f in faces], dtype=np.int64)
        face_block = np.repeat(np.arange(len(body_faces)), [len(faces) for faces in body_faces])
        flat = np.fromiter(
            (i for faces in body_faces for f in faces for i in f), np.int64, int(face_len.sum())
        )
        mesh = BodyMesh(np.concatenate([[0], np.cumsum(nv)]).astype(np.int64),
                        np.concatenate(verts) if verts else np.zeros((0, 3)), face_len,
                        face_block.astype(np.int64), flat)
        bad = mesh.bad_face()
        if bad is not None:
            b = int(face_block[bad])
            k = bad - int(np.searchsorted(face_block, b))
            raise ValueError(f"body_faces[{b}][{k}] = {list(body_faces[b][k])}: need >= 3 "
                             f"vertex ids < {nv[b]}")
        return mesh

    def blocks(self, lo: int, hi: int) -> BodyMesh:
        """The surfaces of blocks ``lo .. hi-1`` (block and vertex ids from 0)."""
        f0, f1 = np.searchsorted(self.face_block, [lo, hi])
        fv = np.concatenate([[0], np.cumsum(self.face_len)])
        v0, v1 = self.vert_start[lo], self.vert_start[hi]
        return BodyMesh(self.vert_start[lo:hi + 1] - v0, self.verts[v0:v1],
                        self.face_len[f0:f1], self.face_block[f0:f1] - lo,
                        self.face_verts[fv[f0]:fv[f1]])

    def bad_face(self) -> int | None:
        """The first face with fewer than 3 vertices or a vertex id outside its block's."""
        nv = np.diff(self.vert_start)
        vert_block = np.repeat(self.face_block, self.face_len)
        bad = self.face_len < 3
        bad_v = (self.face_verts < 0) | (self.face_verts >= nv[vert_block])
        if bad.any() or bad_v.any():
            bad |= np.bincount(np.repeat(np.arange(len(self.face_len)), self.face_len), bad_v,
                               len(bad)) > 0
            return int(np.flatnonzero(bad)[0])
        return None


def body_surfaces(store, lo: int = 0, hi: int | None = None) -> BodyMesh:
    """The surfaces of rows ``lo .. hi-1`` of a store (default: all) in their body frame, flat:
    a joined block's pieces side by side. Vectorised over the store's CSR geometry (a block's
    pieces, vertices and faces are consecutive rows)."""
    hi = store.n if hi is None else hi
    first_piece = store.piece_start[lo:hi + 1]
    vert_start = store.vert_start[first_piece]  # each block's first vertex row (and the end)
    face_start = store.face_start[first_piece]
    face_block = np.repeat(np.arange(hi - lo), np.diff(face_start))
    fv0, fv1 = store.fvert_start[face_start[0]], store.fvert_start[face_start[-1]]
    face_len = np.diff(store.fvert_start[face_start[0]:face_start[-1] + 1])
    vert_of = np.repeat(face_block, face_len)
    return BodyMesh(vert_start - vert_start[0],
                    store.verts_local[vert_start[0]:vert_start[-1]].copy(), face_len,
                    face_block, store.face_verts[fv0:fv1] - vert_start[vert_of])
