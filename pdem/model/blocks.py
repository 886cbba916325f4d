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

# the dtype of the vertex rows inside faces and edges (``face_verts``, ``edges``): a rank
# holds far fewer than 2**31 vertices (int32: 8 bytes a vertex id less, ~220 a cube)
VERT_ROW = np.int32

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

    @classmethod
    def catalogue(cls, arrays: dict[str, np.ndarray]) -> BlockStore:
        """A store of the given per-block fields only (no others allocated, no geometry):
        the scene's fields every rank keeps for every block (pdem.selection.CATALOGUE)."""
        store = cls.__new__(cls)
        store.__dict__.update(arrays)
        return store

    @property
    def n(self) -> int:
        # the scene's store after set-up keeps no gid column (its rows are the gids) but
        # always ``fixed`` (pdem.selection.RUN_CATALOGUE)
        column = self.__dict__.get("gid")
        return len(column if column is not None else self.fixed)

    @property
    def n_pieces(self) -> int:
        return len(self.piece_block)

    def fields(self) -> dict[str, np.ndarray]:
        """The per-block arrays by field name (views, not copies)."""
        return {f.name: getattr(self, f.name) for f in BLOCK}

    def geometry(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in GEOMETRY}

    @property
    def has_geometry(self) -> bool:
        return "verts_local" in self.__dict__

    def keep_fields(self, names) -> None:
        """Drop the per-block fields not in ``names`` (the scene's store after set-up)."""
        for f in BLOCK:
            if f.name not in names:
                self.__dict__.pop(f.name, None)

    def clear(self) -> None:
        """Drop every array (a store no longer used: its memory goes back at once)."""
        self.__dict__.clear()

    def drop_geometry(self) -> None:
        """Keep the per-block fields only: the scene's store after set-up, when each rank
        holds the geometry of its own blocks and ghosts (pdem.parallel.migrate)."""
        for k in GEOMETRY:
            self.__dict__.pop(k, None)

    def shapes(self) -> Shapes:
        return Shapes(self.piece_block, self.piece_x, self.vert_start, self.verts_world,
                      self.face_start, self.normals_local, self.edir_start, self.edirs_local,
                      self.point_area)


# geometry recomputed from the pose (pdem.dynamics.kinematics.refresh_pose): not sent with a
# block, allocated where it arrives
SCRATCH_GEOMETRY = ("piece_x", "piece_lo", "piece_hi", "verts_world")
# CSR starts and the arrays they index: (start, indexed arrays, what the entries count)
_CSR = (("piece_start", (), "piece"), ("vert_start", ("verts_local",), "vert"),
        ("face_start", ("face_tag", "normals_local", "offsets_local"), "face"),
        ("fvert_start", ("face_verts",), "fvert"), ("edge_start", ("edges",), "edge"),
        ("edir_start", ("edirs_local",), "edir"))


def _rows(src: BlockStore, rows: np.ndarray, names, scratch: bool):
    """Per-block fields ``names`` and the geometry of rows ``rows`` of ``src``, in that order
    (fancy indexing: copies); the scratch geometry zeroed, or left out (``scratch`` False)."""
    per_block = {name: getattr(src, name)[rows] for name in names}
    pidx, piece_start = csr.take(src.piece_start, rows)
    vidx, vert_start = csr.take(src.vert_start, pidx)
    fidx, face_start = csr.take(src.face_start, pidx)
    fvidx, fvert_start = csr.take(src.fvert_start, fidx)
    eidx, edge_start = csr.take(src.edge_start, pidx)
    didx, edir_start = csr.take(src.edir_start, pidx)
    # vertex ids inside faces and edges are rows of src's vertices: renumber to the new rows
    vmap = np.full(len(src.verts_local), -1, VERT_ROW)
    vmap[vidx] = np.arange(len(vidx))
    n_pieces, n_verts = len(pidx), len(vidx)
    geometry = dict(
        piece_start=piece_start,
        piece_block=np.repeat(np.arange(len(rows)), np.diff(piece_start)),
        piece_gid=src.piece_gid[pidx],
        piece_center=src.piece_center[pidx],
        piece_x=None, piece_lo=None, piece_hi=None,
        vert_start=vert_start,
        verts_local=src.verts_local[vidx],
        verts_world=None,
        face_start=face_start,
        fvert_start=fvert_start,
        face_tag=src.face_tag[fidx],
        face_verts=vmap[src.face_verts[fvidx]],
        normals_local=src.normals_local[fidx],
        offsets_local=src.offsets_local[fidx],
        edge_start=edge_start,
        edges=vmap[src.edges[eidx]],
        edir_start=edir_start,
        edirs_local=src.edirs_local[didx],
    )
    del vmap
    for k, n in (("piece_x", n_pieces), ("piece_lo", n_pieces), ("piece_hi", n_pieces),
                 ("verts_world", n_verts)):
        if scratch:
            geometry[k] = np.zeros((n, 3))
        else:
            del geometry[k]
    return per_block, geometry


def take_rows(src: BlockStore, rows: np.ndarray, owned: np.ndarray) -> BlockStore:
    """A store holding rows ``rows`` of ``src`` (any store: the scene's, where row == gid, or
    a rank's), in that order; per-block fields copied, scratch geometry zeroed (callers
    refresh it from the pose, pdem.dynamics.kinematics.refresh_pose)."""
    rows = np.asarray(rows, np.int64)
    per_block, geometry = _rows(src, rows, [f.name for f in BLOCK], scratch=True)
    per_block["owned"] = np.asarray(owned, np.uint8)
    return BlockStore(per_block, geometry)


def pack(src: BlockStore, rows: np.ndarray) -> dict[str, np.ndarray]:
    """Rows ``rows`` of ``src`` as a message: the static per-block fields and the body-frame
    geometry, what a rank needs to hold a block it did not have (pdem.parallel.migrate).
    The dynamic fields travel separately (MIGRATE), scratch is rebuilt where it arrives.
    Only what the message holds is copied (a rebuild's peak: no whole store of the rows)."""
    per_block, geometry = _rows(src, np.asarray(rows, np.int64),
                                [f.name for f in BLOCK if f.static], scratch=False)
    return {**per_block, **geometry}


def whole_message(src: BlockStore) -> dict[str, np.ndarray]:
    """Every row of ``src`` as a :func:`pack` message, without copying: its arrays are
    ``src``'s own (the caller drops ``src`` after; what ``pack(src, arange(n))`` gives)."""
    msg = {f.name: getattr(src, f.name) for f in BLOCK if f.static}
    msg.update({k: v for k, v in src.geometry().items() if k not in SCRATCH_GEOMETRY})
    return msg


def unpack(parts: list[dict[str, np.ndarray]], owned: np.ndarray) -> BlockStore:
    """One store of the blocks of several :func:`pack` messages, in message order; CSR
    starts and vertex ids are offset to the concatenated rows."""
    if not parts:
        raise ValueError("unpack: no messages (pack zero rows for an empty store)")
    per_block = {f.name: np.concatenate([p[f.name] for p in parts]) for f in BLOCK if f.static}
    per_block["owned"] = np.asarray(owned, np.uint8)
    geometry: dict[str, np.ndarray] = {}
    base = {"block": 0, "piece": 0, "vert": 0, "face": 0, "fvert": 0, "edge": 0, "edir": 0}
    chunks: dict[str, list[np.ndarray]] = {}
    for p in parts:
        for start, _, unit in _CSR:
            chunks.setdefault(start, []).append(p[start][:-1] + base[unit])
        chunks.setdefault("piece_block", []).append(
            np.repeat(np.arange(len(p["gid"])), np.diff(p["piece_start"])) + base["block"])
        chunks.setdefault("face_verts", []).append(p["face_verts"] + base["vert"])
        chunks.setdefault("edges", []).append(p["edges"] + base["vert"])
        for k in ("piece_gid", "piece_center", "verts_local", "face_tag", "normals_local",
                  "offsets_local", "edirs_local"):
            chunks.setdefault(k, []).append(p[k])
        base["block"] += len(p["gid"])
        for start, _, unit in _CSR:
            base[unit] += int(p[start][-1])
    for start, _, unit in _CSR:
        geometry[start] = np.concatenate(chunks[start] + [np.array([base[unit]], np.int64)])
    for k in ("piece_block", "face_verts", "edges", "piece_gid", "piece_center", "verts_local",
              "face_tag", "normals_local", "offsets_local", "edirs_local"):
        geometry[k] = np.concatenate(chunks[k])
    n_pieces, n_verts = base["piece"], base["vert"]
    for k, n in (("piece_x", n_pieces), ("piece_lo", n_pieces), ("piece_hi", n_pieces),
                 ("verts_world", n_verts)):
        geometry[k] = np.zeros((n, 3))
    return BlockStore(per_block, geometry)
