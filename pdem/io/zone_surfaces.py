"""The zoned blocks' deformed surfaces in ``run.xdmf``: a zoned block's triangles in
``surface/`` are its grid's boundary (the tet faces used once, pdem.deformable.mesh.
boundary_triangles) at the current gridpoint positions, beside the rigid blocks' surfaces.

``surface/`` is written by gid range (rank ``r`` writes the vertices and triangles of the gids
``[lo, hi)``, pdem.io.block_series), while a zoned block's gridpoints are on the rank that owns
it. So the owners send, once, each zoned block's boundary triangles to the rank whose gid range
holds it (its vertices are then the block's boundary gridpoints, ascending, in place of its
build-time polyhedron's), and with every snapshot those gridpoints' positions (one
``Alltoallv``). The rows land by gid alone, so the file does not depend on the rank count; the
positions are copies of ``zones/points``, bitwise.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..deformable.mesh import boundary_triangles
from .h5core import H5Core
from .surfaces import BodyMesh

__all__ = ["ZoneSurfaces", "boundary_of"]


def boundary_of(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A zoned block's exposed surface: its boundary gridpoints (ascending ids) and its boundary
    triangles as rows of those (``(k, 3)``, CCW seen from outside)."""
    tris = boundary_triangles(tets)
    nodes = np.unique(tris)
    return nodes, np.searchsorted(nodes, tris).astype(np.int64)


class ZoneSurfaces:
    """Where the zoned blocks' boundary gridpoints go in ``surface/points``.

    Construction is collective: ``zones`` are this rank's ``(gid, body)`` pairs (already
    checked, pdem.io.zone_series), each rank learns the boundary triangles of the zoned blocks
    in its gid range.
    """

    def __init__(self, core: H5Core, zones: Sequence[tuple[int, Any]] | None) -> None:
        self.core = core
        comm = core.comm
        # boundary gridpoints of the zoned blocks this rank owns or owned (a zoned block
        # migrates with its grid: its new owner finds them at its first snapshot there)
        self._nodes: dict[int, np.ndarray] = {}
        send: list[list] = [[] for _ in range(comm.size)]
        for gid, body in ([] if zones is None else zones):
            nodes, tris = boundary_of(body.tets)
            self._nodes[int(gid)] = nodes
            send[self._dest(np.array([gid]))[0]].append((int(gid), len(nodes), tris))
        # static, once: the triangles of every zoned block of this rank's gid range, by gid
        self.ranged = dict(sorted((it[0], it[1:]) for part in comm.alltoall(send)
                                  for it in part))

    def _dest(self, gids: np.ndarray) -> np.ndarray:
        """The rank whose gid range holds each gid (rank 0 for all in the fallback)."""
        return np.searchsorted(self.core.bounds, gids, side="right") - 1

    def replace(self, mesh: BodyMesh, lo: int) -> tuple[BodyMesh, np.ndarray]:
        """``mesh`` (gids ``lo ..``) with each zoned block's faces and vertices replaced by its
        boundary triangles and boundary gridpoints (placeholders at the origin: their positions
        come with each snapshot), and the rows of those vertices in the new mesh, blocks by gid,
        gridpoints ascending."""
        nb = len(mesh.vert_start) - 1
        if not self.ranged:
            return mesh, np.zeros(0, np.int64)
        zk = np.array(list(self.ranged), np.int64) - lo  # local block ids, ascending
        zn = np.array([n for n, _ in self.ranged.values()], np.int64)
        tris = [t for _, t in self.ranged.values()]
        zoned = np.zeros(nb, bool)
        zoned[zk] = True
        nv = np.diff(mesh.vert_start)
        new_nv = nv.copy()
        new_nv[zk] = zn
        vert_start = np.zeros(nb + 1, np.int64)
        np.cumsum(new_nv, out=vert_start[1:])
        verts = np.zeros((int(vert_start[-1]), 3))
        vblock = np.repeat(np.arange(nb), nv)
        keep = ~zoned[vblock]
        local = np.arange(len(vblock)) - mesh.vert_start[vblock]
        verts[(vert_start[vblock] + local)[keep]] = mesh.verts[keep]
        # faces: the kept blocks' as they were, the zoned blocks' triangles, then all by block
        # (stable: each block's faces keep their order)
        fkeep = ~zoned[mesh.face_block]
        flen = np.concatenate([mesh.face_len[fkeep], np.full(sum(map(len, tris)), 3)])
        fblock = np.concatenate([mesh.face_block[fkeep],
                                 np.repeat(zk, [len(t) for t in tris])])
        fverts = np.concatenate([mesh.face_verts[np.repeat(fkeep, mesh.face_len)],
                                 *(t.ravel() for t in tris)]).astype(np.int64)
        order = np.argsort(fblock, kind="stable")
        fstart = np.zeros(len(flen), np.int64)
        np.cumsum(flen[:-1], out=fstart[1:])
        ramp = np.arange(int(flen.sum())) - np.repeat(np.cumsum(flen[order]) - flen[order],
                                                      flen[order])
        fverts = fverts[np.repeat(fstart[order], flen[order]) + ramp]
        rows = np.concatenate([np.arange(vert_start[k], vert_start[k + 1]) for k in zk])
        return BodyMesh(vert_start, verts, flen[order], fblock[order].astype(np.int64),
                        fverts), rows

    def points(self, zones: Sequence[tuple[int, Any]], items: list) -> np.ndarray:
        """The boundary gridpoints' positions of the zoned blocks of this rank's gid range,
        blocks by gid, gridpoints ascending (collective): ``zones`` are the ``(gid, body)``
        pairs this rank owns, ``items`` their snapshot values ``(gid, values)`` in the same
        order (pdem.io.zones.zone_values)."""
        for (_, body), (g, _) in zip(zones, items, strict=True):
            if g not in self._nodes:  # a zoned block that came to this rank
                self._nodes[g] = boundary_of(body.tets)[0]
        gids = [np.full(len(self._nodes[g]), g, np.int64) for g, _ in items]
        rows = [np.asarray(v["points"], np.float64)[self._nodes[g]] for g, v in items]
        gids = np.concatenate(gids) if gids else np.zeros(0, np.int64)
        rows = np.concatenate(rows) if rows else np.zeros((0, 3))
        got_gid, got = self.core.exchange(self._dest(gids), gids, rows)
        # each gid's rows come from one rank, in its order: a stable sort by gid lines them up
        return got[np.argsort(got_gid, kind="stable")]
