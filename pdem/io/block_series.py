"""The block series of the run output: the per-block snapshot rows (``time``, ``step``,
``stage``, ``blocks/*``) and the block surfaces (``surface/connectivity``, ``block_id``,
``points``), each rank writing its gid range (:class:`pdem.io.h5core.H5Core`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import h5py
import numpy as np

from ..dynamics.kinematics import rotation_matrices
from ..jit import kernel
from ..model.fields import OUTPUT, row_width
from .h5core import H5Core
from .surfaces import BodyMesh

__all__ = ["BlockSeries", "ROW_COLS", "COLS", "cols", "quat_to_matrix", "fan_triangulate"]

# a snapshot row: the block fields declared with an output name (pdem.model.fields)
ROW_COLS = row_width(OUTPUT)
COLS: dict[str, tuple[int, int]] = {}
_SHAPES = {f.output: f.shape for f in OUTPUT}
_c = 0
for _f in OUTPUT:
    COLS[_f.output] = (_c, _f.width)
    _c += _f.width
# output fields a caller may leave out (zero): a block's removal code
_OPTIONAL = ("removed", "stage_origin")


def cols(rows: np.ndarray, name: str) -> np.ndarray:
    """The columns of output field ``name`` in snapshot rows."""
    col, w = COLS[name]
    return rows[:, col:col + w]


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` of unit quaternions ``(n, 4)`` ``(w, x, y, z)``.

    Element-wise per block, so a block's matrix does not depend on how many blocks are
    converted together: the output is bitwise independent of the rank count.
    """
    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 4)
    R = np.empty((len(q), 3, 3))
    rotation_matrices(q, R)
    return R


@kernel
def surface_points(centroid, R, vblock, verts, out):
    """``out[k] = c + R v`` of each vertex ``k`` (body frame ``verts[k]``) of block
    ``vblock[k]`` (``centroid``, ``R``: per block). Explicit sums in a fixed order, so the
    bits do not depend on the partition; no per-vertex copy of the matrices (a snapshot of
    64,000 cubes on 2 ranks held ~36 MB of them a rank)."""
    for k in range(verts.shape[0]):
        b = vblock[k]
        for i in range(3):
            out[k, i] = centroid[b, i] + (R[b, i, 0] * verts[k, 0] + R[b, i, 1] * verts[k, 1]
                                          + R[b, i, 2] * verts[k, 2])


def fan_triangulate(mesh: BodyMesh) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate every face: global connectivity ``(n_tri, 3)`` and block of each
    (int32: a block of this rank's range).

    Face ``(v0, v1, ..., vk)`` gives ``(v0, v1, v2), (v0, v2, v3), ...``: counter-clockwise
    faces give counter-clockwise triangles, so normals still point out of the block.
    """
    face_len = np.ascontiguousarray(mesh.face_len, np.int64)
    n_tri = int((face_len - 2).sum())
    conn = np.empty((n_tri, 3), np.int64)
    tri_block = np.empty(n_tri, np.int32)
    fan_triangles(face_len, np.ascontiguousarray(mesh.face_verts, np.int64),
                  np.ascontiguousarray(mesh.face_block, np.int64),
                  np.ascontiguousarray(mesh.vert_start, np.int64), conn, tri_block)
    return conn, tri_block


@kernel
def fan_triangles(face_len, face_verts, face_block, vert_start, conn, tri_block):
    """The fans of :func:`fan_triangulate`, face after face, written in place: no per-corner
    temporaries (64,000 cubes on 2 ranks: ~30 MB a rank at the writer's construction)."""
    t = 0
    k = 0
    for f in range(face_len.shape[0]):
        b = face_block[f]
        base = vert_start[b]
        n = face_len[f]
        for j in range(n - 2):
            conn[t, 0] = base + face_verts[k]
            conn[t, 1] = base + face_verts[k + 1 + j]
            conn[t, 2] = base + face_verts[k + 2 + j]
            tri_block[t] = b
            t += 1
        k += n


def _local_mesh(n: int, lo: int, hi: int, body_vertices, body_faces,
                body_mesh: BodyMesh | None) -> BodyMesh:
    """The surfaces of gids ``[lo, hi)`` from every block's lists, every block's mesh or this
    rank's range's mesh (``ValueError`` on a mismatch)."""
    if body_mesh is None:
        if len(body_vertices) != n or len(body_faces) != n:
            raise ValueError(
                f"OutputWriter: {n} block names, {len(body_vertices)} vertex arrays, "
                f"{len(body_faces)} face lists"
            )
        body_mesh = BodyMesh.from_lists(body_vertices, body_faces)
    if len(body_mesh.vert_start) == n + 1:  # every block's surface: keep this rank's
        body_mesh = body_mesh.blocks(lo, hi)
    elif len(body_mesh.vert_start) != hi - lo + 1:
        raise ValueError(f"OutputWriter: a body mesh of {len(body_mesh.vert_start) - 1} "
                         f"blocks, neither the scene's {n} nor this rank's {hi - lo} "
                         f"(writer_range)")
    return body_mesh


class BlockSeries:
    """``time``, ``step``, ``stage``, ``blocks/*`` and ``surface/{connectivity, block_id,
    points}``: the snapshot rows of this rank's gid range and its blocks' surfaces.

    Construction is collective (the vertex and triangle counts of the ranks before this one).
    ``zoned``: the zoned blocks' surfaces (:class:`pdem.io.zone_surfaces.ZoneSurfaces`), whose
    triangles replace their blocks' and whose vertices take the gridpoints' positions given
    with each snapshot; None without zoned blocks.
    """

    def __init__(self, core: H5Core, n: int, body_vertices, body_faces,
                 body_mesh: BodyMesh | None, zoned=None) -> None:
        self.core = core
        lo, hi, comm = core.lo, core.hi, core.comm
        body_mesh = _local_mesh(n, lo, hi, body_vertices, body_faces, body_mesh)
        self.zoned_rows = np.zeros(0, np.int64)  # my_verts rows that are zoned gridpoints
        if zoned is not None:
            body_mesh, self.zoned_rows = zoned.replace(body_mesh, lo)
        # this rank's vertices and triangles, and where they go in the whole surface: the
        # counts of the ranks before it (rank order = gid order)
        conn, tri_block = fan_triangulate(body_mesh)
        counts = np.array(comm.allgather((len(body_mesh.verts), len(conn))), np.int64)
        before = counts[:comm.rank].sum(axis=0)
        self.vlo, self.tlo = int(before[0]), int(before[1])
        self.vhi, self.thi = self.vlo + len(body_mesh.verts), self.tlo + len(conn)
        self.conn, self.my_tblock = conn + self.vlo, tri_block
        self.n_blocks, self.n_points = n, int(counts[:, 0].sum())
        self.n_tri = int(counts[:, 1].sum())
        # a copy only of a view (every block's mesh cut to this range): the mesh given for this
        # range alone is kept as it is, not copied beside itself while the writer is built
        verts = body_mesh.verts
        self.my_verts = verts.copy() if verts.base is not None else verts
        # int32: blocks of this rank's range (kept for the run: 4 bytes a vertex, a triangle)
        self.my_vblock = np.repeat(np.arange(hi - lo, dtype=np.int32),
                                   np.diff(body_mesh.vert_start))

    def create(self, block_names: Sequence[str], block_parents: Sequence[str] | None) -> None:
        """The series and the static block and surface data (IO ranks, collective)."""
        core, f, n = self.core, self.core.f, self.n_blocks
        core.series("time", (), np.float64, 1024).attrs["units"] = "s"
        core.series("step", (), np.int64, 1024)
        core.series("stage", (), np.int32, 1024)  # index in `stages:` (0 without)
        g = f.create_group("blocks")
        for key, texts in (("name", block_names), ("parent", block_parents or block_names)):
            core.write_texts(g, key, texts)
        # gid and block_id from the rank's rows alone: an arange of every block was the
        # writer's one O(N) array on every rank (8 bytes a block)
        lo, hi = core.share(n)
        core.write(g.create_dataset("gid", (n,), dtype=np.int64), (lo,), np.arange(lo, hi))
        series = {fd.output: core.series(f"blocks/{fd.output}", (n, *fd.shape), fd.dtype)
                  for fd in OUTPUT}
        for fd in OUTPUT:
            series[fd.output].attrs["units"] = (
                "1 (unit quaternion w, x, y, z; body to world)" if fd.name == "q" else fd.units)
        s = f.create_group("surface")
        core.write(s.create_dataset("connectivity", (self.n_tri, 3), np.int64), (self.tlo, 0),
                   self.conn if len(self.conn) else None)
        self.conn = None  # written once (24 bytes a triangle)
        self.write_triangles(s.create_dataset("block_id", (self.n_tri,), np.int64),
                             np.arange(core.lo, core.hi), core.lo)
        core.series("surface/points", (self.n_points, 3), np.float64).attrs["units"] = "m"

    def pack(self, gids, fields: dict[str, Any]) -> tuple[str | None, np.ndarray, np.ndarray]:
        """This rank's snapshot rows: ``(error, gids, rows)``, no rows after an error."""
        try:
            gids = np.asarray(gids, dtype=np.int64).reshape(-1)
            k = len(gids)
            rows = np.empty((k, ROW_COLS))
            for name, (col, w) in COLS.items():
                if name not in fields and name not in _OPTIONAL:
                    raise ValueError(f"write_snapshot: no {name} rows")
                default = np.zeros((k, w))
                if name == "stage_origin":  # no stages: measured from the start, filled in
                    default = np.full((k, 3), np.nan)  # by the rows' writer (fill_origin)
                a = np.asarray(fields.get(name, default), dtype=np.float64)
                if a.size != k * w:
                    raise ValueError(f"write_snapshot: {name} has shape {a.shape}, need ({k}, {w})")
                rows[:, col : col + w] = a.reshape(k, w)
            if k and (gids.min() < 0 or gids.max() >= self.n_blocks):
                raise ValueError(f"write_snapshot: gids outside [0, {self.n_blocks})")
        except ValueError as e:
            return str(e), np.zeros(0, np.int64), np.zeros((0, ROW_COLS))
        return None, gids, rows

    def assemble(self, packed: list) -> np.ndarray:
        """Send each row of ``packed`` = ``[gids, rows]`` (:meth:`pack`'s, emptied here: the
        passed rows are freed once sent) to the rank whose gid range holds it; return this
        rank's range."""
        core = self.core
        gids, rows = packed
        packed.clear()
        dest = np.searchsorted(core.bounds, gids, side="right") - 1
        (rg,) = core.exchange(dest, gids)
        del gids
        (rr,) = core.exchange(dest, rows)
        del rows, dest  # the sent rows, the received ones' copy is assembled below
        lo, hi = core.lo, core.hi
        hits = np.bincount(rg - lo, minlength=hi - lo)
        msg = None
        if len(rg) != hi - lo or np.any(hits != 1):
            missing = np.flatnonzero(hits == 0)[:5] + lo
            dup = np.flatnonzero(hits > 1)[:5] + lo
            msg = (
                "write_snapshot: every gid must be owned by exactly one rank "
                f"(missing e.g. {missing.tolist()}, duplicated e.g. {dup.tolist()})"
            )
        core.raise_if_any(msg)
        out = np.empty((hi - lo, ROW_COLS))
        out[rg - lo] = rr
        return out

    def write(self, i: int, mine: np.ndarray, step: int, time: float, stage: int,
              zoned_points: np.ndarray | None = None) -> None:
        """Snapshot ``i`` of the series from this rank's assembled rows (IO ranks);
        ``zoned_points``: the positions of the vertices ``zoned_rows`` (the zoned blocks'
        boundary gridpoints, :meth:`pdem.io.zone_surfaces.ZoneSurfaces.points`)."""
        core, f = self.core, self.core.f
        paths = ("time", "step", "stage", "surface/points", *(f"blocks/{n}" for n in COLS))
        for path in paths:
            f[path].resize(i + 1, axis=0)
        root = core.comm.rank == 0
        core.write_row(f["time"], i, np.array([time], np.float64) if root else None)
        core.write_row(f["step"], i, np.array([step], np.int64) if root else None)
        core.write_row(f["stage"], i, np.array([stage], np.int32) if root else None)
        for name, (col, w) in COLS.items():
            rows_out = mine[:, col : col + w].reshape(-1, *_SHAPES[name])
            core.write_row(f[f"blocks/{name}"], i, rows_out, core.lo)
        pts = self.world_points(cols(mine, "centroid"), cols(mine, "orientation"))
        if len(self.zoned_rows):
            pts[self.zoned_rows] = zoned_points
        core.write_row(f["surface/points"], i, pts, self.vlo)

    def world_points(self, centroid: np.ndarray, quat: np.ndarray) -> np.ndarray:
        """World positions ``c + R(q) v`` of the vertices of this rank's gid range."""
        out = np.empty((len(self.my_verts), 3))
        surface_points(centroid, quat_to_matrix(quat), self.my_vblock, self.my_verts, out)
        return out

    def write_triangles(self, dset: h5py.Dataset, per_block: np.ndarray, first: int = 0) -> None:
        """A static per-triangle dataset from per-block values (gid order, from gid ``first``:
        every block's, or this rank's range's): each rank writes the triangles of its range."""
        mine = np.asarray(per_block)[self.core.lo - first + self.my_tblock]
        self.core.write(dset, (self.tlo,) + (0,) * (mine.ndim - 1), mine if len(mine) else None)
