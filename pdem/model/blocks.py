"""BlockStore: the struct of arrays holding every block a rank knows (owned or ghost).

Per-block arrays are the fields declared in :mod:`pdem.model.fields` (``BLOCK``), each an
attribute of the store; geometry is ragged, kept as CSR in the body frame (``GEOMETRY``).

A block is one rigid body made of one or more convex *pieces* (3DEC's joined blocks: a concave
block is several convex pieces moving as one). Contacts are detected between pieces, forces act
on bodies. Most blocks have one piece; then piece row == block row and the piece centre is the
block centroid exactly.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from . import csr
from .fields import BLOCK, allocate

# name: meaning. ``piece_start`` indexes pieces by block (n+1,); the other CSR starts index
# pieces (P+1,); the vertex ids inside faces and edges are rows of verts_local in this store.
GEOMETRY = {
    "piece_start": "(n+1,) into the pieces",
    "piece_block": "(P,) block row of each piece (local)",
    "piece_gid": "(P,) global piece id (pieces numbered block by block in gid order)",
    "piece_center": "(P, 3) piece centroid in the body frame (zero for a one-piece block)",
    "piece_x": "(P, 3) piece centroid in the world (scratch)",
    "piece_lo": "(P, 3) piece envelope lower corner (scratch)",
    "piece_hi": "(P, 3) piece envelope upper corner (scratch)",
    "vert_start": "(P+1,) into verts_local / verts_world",
    "verts_local": "(V, 3) vertices in the body frame",
    "verts_world": "(V, 3) vertices in the world, refreshed from the pose (scratch)",
    "face_start": "(P+1,) into the faces",
    "face_tag": "(F,) the cut that made each face (index in ``cuts:``), -1 for none",
    "fvert_start": "(F+1,) into face_verts",
    "face_verts": "vertex rows of each face, counter-clockwise from outside",
    "normals_local": "(F, 3) outward face normals, body frame",
    "offsets_local": "(F,) face plane offsets, body frame",
    "edge_start": "(P+1,) into edges",
    "edges": "(E, 2) vertex rows",
    "edir_start": "(P+1,) into edirs_local",
    "edirs_local": "unique edge directions (body frame), for the fast common plane",
}

# What the contact-geometry kernels read of the shapes (a record, not 10 positionals).
Shapes = namedtuple("Shapes", "piece_block piece_x vert_start verts_world face_start "
                              "normals_local edir_start edirs_local point_area")


class BlockStore:
    """Blocks as flat arrays: one attribute per declared field, plus the CSR geometry."""

    def __init__(self, arrays: dict[str, np.ndarray], geometry: dict[str, np.ndarray]):
        missing = [f.name for f in BLOCK if f.name not in arrays]
        n = len(arrays["gid"])
        for name, arr in allocate(tuple(f for f in BLOCK if f.name in missing), n).items():
            arrays[name] = arr
        self.__dict__.update(arrays)
        self.__dict__.update(geometry)

    @property
    def n(self) -> int:
        return len(self.gid)

    @property
    def n_pieces(self) -> int:
        return len(self.piece_block)

    def fields(self) -> dict[str, np.ndarray]:
        """The per-block arrays by field name (views, not copies)."""
        return {f.name: getattr(self, f.name) for f in BLOCK}

    def geometry(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in GEOMETRY}

    def shapes(self) -> Shapes:
        return Shapes(self.piece_block, self.piece_x, self.vert_start, self.verts_world,
                      self.face_start, self.normals_local, self.edir_start, self.edirs_local,
                      self.point_area)


def take_rows(glob: BlockStore, gids: np.ndarray, owned: np.ndarray) -> BlockStore:
    """A local store holding blocks ``gids`` of the global (static) store; scratch zeroed.

    Non-static fields come from ``glob`` too; callers overwrite them with migrated state."""
    gids = np.asarray(gids, np.int64)
    per_block = {f.name: getattr(glob, f.name)[gids].copy() for f in BLOCK}
    per_block["owned"] = np.asarray(owned, np.uint8)
    pidx, piece_start = csr.take(glob.piece_start, gids)
    vidx, vert_start = csr.take(glob.vert_start, pidx)
    fidx, face_start = csr.take(glob.face_start, pidx)
    fvidx, fvert_start = csr.take(glob.fvert_start, fidx)
    eidx, edge_start = csr.take(glob.edge_start, pidx)
    didx, edir_start = csr.take(glob.edir_start, pidx)
    # vertex ids inside faces and edges are global vertex rows: renumber to local rows
    vmap = np.full(len(glob.verts_local), -1, np.int64)
    vmap[vidx] = np.arange(len(vidx))
    return BlockStore(per_block, dict(
        piece_start=piece_start,
        piece_block=np.repeat(np.arange(len(gids)), np.diff(piece_start)),
        piece_gid=pidx,
        piece_center=glob.piece_center[pidx],
        piece_x=glob.piece_x[pidx].copy(),
        piece_lo=glob.piece_lo[pidx].copy(),
        piece_hi=glob.piece_hi[pidx].copy(),
        vert_start=vert_start,
        verts_local=glob.verts_local[vidx],
        verts_world=glob.verts_world[vidx].copy(),
        face_start=face_start,
        fvert_start=fvert_start,
        face_tag=glob.face_tag[fidx],
        face_verts=vmap[glob.face_verts[fvidx]],
        normals_local=glob.normals_local[fidx],
        offsets_local=glob.offsets_local[fidx],
        edge_start=edge_start,
        edges=vmap[glob.edges[eidx]],
        edir_start=edir_start,
        edirs_local=glob.edirs_local[didx],
    ))
