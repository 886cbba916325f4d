"""Run output: one HDF5 file per run, written collectively (mpio) or gathered on rank 0."""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from h5py import h5fd, h5p, h5s, h5t
from mpi4py import MPI

from ..dynamics.kinematics import rotation_matrices
from ..model.fields import OUTPUT, row_width
from . import joints
from . import layout as row_layout
from .layout import even_share
from .surfaces import BodyMesh
from .xdmf import CELL_FIELDS, CONTACT_VIEWED, SUB_VIEWED, VIEWED_SERIES, view_path, write_xdmf
from .zones import POINT_SERIES, ZONE_SERIES, ZONE_VIEWED, ZoneLayout, zone_layout, zone_values

__all__ = ["OutputWriter", "FORMAT_VERSION", "quat_to_matrix"]

log = logging.getLogger(__name__)

# 2: per-triangle colouring fields, blocks/group|fixed|initial_centroid, /xdmf views
FORMAT_VERSION = 2
# a snapshot row: the block fields declared with an output name (pdem.model.fields)
_ROW_COLS = row_width(OUTPUT)
_COLS = {}
_SHAPES = {f.output: f.shape for f in OUTPUT}
_c = 0
for _f in OUTPUT:
    _COLS[_f.output] = (_c, _f.width)
    _c += _f.width
# output fields a caller may leave out (zero): a block's removal code
_OPTIONAL = ("removed", "stage_origin")
# Parallel HDF5 duplicates the file's communicator for every virtual dataset that names the
# file itself as its source, and frees them only when the file closes: MPICH allows ~2048
# communicators, i.e. ~220 snapshots of views. So the file is closed and reopened every this
# many snapshots (collective; measured: 3000 views, no leak).
_REOPEN_EVERY = 32  # 10 views per snapshot, 24 with contacts, 34 with zones: 1088 at most
_CONTACT_CHUNK = 1024  # rows per chunk of the flat contact and sub-contact datasets
_CHUNK_ROWS = 1 << 16  # rows per chunk along the block/vertex axis (1.5 MiB for 3 doubles)
_POINT_NAMES = {s[0] for s in POINT_SERIES}  # zone output series per gridpoint (else per zone)


def _cols(rows: np.ndarray, name: str) -> np.ndarray:
    """The columns of output field ``name`` in snapshot rows."""
    col, w = _COLS[name]
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


def _fan_triangulate(mesh: BodyMesh) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate every face: global connectivity ``(n_tri, 3)`` and block of each.

    Face ``(v0, v1, ..., vk)`` gives ``(v0, v1, v2), (v0, v2, v3), ...``: counter-clockwise
    faces give counter-clockwise triangles, so normals still point out of the block.
    """
    face_len = mesh.face_len
    flat = mesh.face_verts + mesh.vert_start[np.repeat(mesh.face_block, face_len)]
    fstart = _starts(face_len)
    n_fan = face_len - 2
    tri_face = np.repeat(np.arange(len(face_len)), n_fan)
    j = np.arange(len(tri_face)) - np.repeat(_starts(n_fan), n_fan)
    first = fstart[tri_face]
    conn = np.stack([flat[first], flat[first + 1 + j], flat[first + 2 + j]], axis=1)
    return conn.reshape(-1, 3), mesh.face_block[tri_face].astype(np.int64)


def _starts(counts: np.ndarray) -> np.ndarray:
    """Exclusive prefix sums: where each run starts (empty for no runs: a rank whose gid range
    is empty has no faces)."""
    out = np.zeros(len(counts), np.int64)
    np.cumsum(counts[:-1], out=out[1:])
    return out


def _block_fields(centroid, x0, velocity, omega, removed, stage_origin) -> dict[str, np.ndarray]:
    """Per-block values of the CELL_FIELDS.

    Explicit element-wise sums (no BLAS, no reductions over blocks), so a block's values do not
    depend on how the blocks are partitioned: bitwise the same whatever the rank count.
    """
    def norm(a):
        return np.sqrt(a[:, 0] * a[:, 0] + a[:, 1] * a[:, 1] + a[:, 2] * a[:, 2])

    d = centroid - x0
    return {"displacement": d, "displacement_magnitude": norm(d), "velocity": velocity,
            "speed": norm(velocity), "angular_velocity": omega, "removed": removed,
            "stage_displacement": centroid - stage_origin}


def _add_view(f: h5py.File, path: str, i: int) -> None:
    """Virtual dataset ``view_path(path, i)`` = snapshot ``i`` of the series ``path``.

    ParaView's XDMF readers disagree on how to select one snapshot of a series (the Xdmf3 readers
    cannot read HyperSlab items, the legacy one cannot read ``|``-slabs), but all read a plain
    dataset: the view is one, with no data copied. The source file is ``"."`` (this file), so
    the view survives moving the file. Creating it is collective (metadata only).
    """
    src = f[path]
    layout = h5py.VirtualLayout(shape=src.shape[1:], dtype=src.dtype)
    layout[...] = h5py.VirtualSource(".", path, shape=src.shape, dtype=src.dtype)[i]
    f.create_virtual_dataset(view_path(path, i), layout)


def _add_range_view(f: h5py.File, path: str, view: str, lo: int, hi: int) -> None:
    """Virtual dataset ``view`` = rows ``lo .. hi-1`` of the flat dataset ``path`` (one
    snapshot's contacts); ``hi > lo``."""
    src = f[path]
    layout = h5py.VirtualLayout(shape=(hi - lo, *src.shape[1:]), dtype=src.dtype)
    layout[...] = h5py.VirtualSource(".", path, shape=src.shape, dtype=src.dtype)[lo:hi]
    f.create_virtual_dataset(view, layout)


class OutputWriter:
    """The HDF5 output of one run; every method is collective over ``comm``.

    Parameters
    ----------
    path
        The ``.h5`` file (overwritten). The XDMF sidecars are ``path`` with suffix ``.xdmf``
        (surfaces) and ``-centroids.xdmf`` (centroid cloud).
    comm
        mpi4py communicator of the ranks that run the model.
    block_names, body_vertices, body_faces
        Per block in gid order, identical on every rank: name, vertices ``(nv, 3)`` in the
        body frame (origin at the centroid), faces as counter-clockwise vertex-id lists.
    body_mesh
        The same surfaces flat (:class:`BodyMesh`), instead of the two lists.
    scene_yaml
        The resolved scene, stored as the root attribute ``scene``.
    attrs
        Extra root attributes (``pdem_version``, ``run_id``, ``n_ranks``, ...), identical on
        every rank; str, int, float or small arrays.
    parallel
        ``True``: write with the ``mpio`` driver (error if h5py lacks MPI); ``False``: gather
        the rows on rank 0, which writes alone; ``None``: ``mpio`` if h5py has MPI, else the
        fallback with a warning.
    xdmf
        Refresh the XDMF sidecar (rank 0) after every snapshot and on close.
    initial_centroid, group, group_names, fixed
        Per block in gid order, identical on every rank: the reference centroids ``(n, 3)`` of
        ``displacement`` (default: the first snapshot's), the group index into ``group_names``
        (default: all 0, named ``"default"``), and whether the block is fixed (default: no).
    ranged
        ``initial_centroid``, ``group`` and ``fixed`` hold the rows of this rank's gid range
        only (:func:`writer_range`): no rank needs every block's.
    contacts, joint_names
        Store the joint state (``contacts/``, ``subcontacts/``, sidecars ``-contacts.xdmf``
        and ``-subcontacts.xdmf``): every snapshot then takes the contacts (see
        :meth:`write_snapshot`); ``joint_names`` go to the root attribute ``joint_names``.
    zones
        The zoned (deformable) blocks this rank owns, ``(gid, body)`` pairs (``body``: a
        :class:`pdem.deformable.body.DeformableBody`, or anything with ``nodes0`` and ``tets``),
        possibly none; ``None`` on every rank for a scene without zoned blocks. Their tetrahedral
        grids go to ``zones/`` and the sidecar ``-zones.xdmf`` (:mod:`pdem.io.zones`); every
        snapshot then takes the zoned blocks (see :meth:`write_snapshot`).

    Notes
    -----
    The file layout depends only on the scene, never on the rank count. In parallel mode
    every snapshot's rows are first redistributed (one ``Alltoallv``) so that rank ``r`` holds
    a contiguous gid range; every rank then writes one hyperslab per dataset with collective
    I/O, a rank with an empty range taking part with an empty selection.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        comm: MPI.Comm,
        *,
        block_names: Sequence[str],
        body_vertices: Sequence[np.ndarray] | None = None,
        body_faces: Sequence[Sequence[Sequence[int]]] | None = None,
        scene_yaml: str = "",
        body_mesh: BodyMesh | None = None,
        attrs: dict[str, Any] | None = None,
        parallel: bool | None = None,
        xdmf: bool = True,
        initial_centroid: np.ndarray | None = None,
        group: Sequence[int] | None = None,
        group_names: Sequence[str] | None = None,
        fixed: Sequence[bool] | None = None,
        block_parents: Sequence[str] | None = None,
        contacts: bool = False,
        joint_names: Sequence[str] | None = None,
        zones: Sequence[tuple[int, Any]] | None = None,
        ranged: bool = False,
    ) -> None:
        self.path = Path(path)
        self.xdmf_path = self.path.with_suffix(".xdmf") if xdmf else None
        self.comm = comm
        rank, size = comm.rank, comm.size
        has_mpi = row_layout.h5py_has_mpi()
        if parallel is None:
            parallel = has_mpi
            if not has_mpi and rank == 0:
                warnings.warn(
                    "h5py was built without MPI: output is gathered on rank 0, which writes "
                    "it alone (install h5py with HDF5_MPI=ON for parallel output)",
                    RuntimeWarning,
                    stacklevel=2,
                )
        elif parallel and not has_mpi:
            raise RuntimeError("OutputWriter(parallel=True): h5py was built without MPI")
        self.parallel = bool(parallel)
        self._io = self.parallel or rank == 0  # does this rank touch the file?

        n = len(block_names)
        if n == 0:
            raise ValueError("OutputWriter: the scene has no blocks")
        # Rank r assembles and writes gids [bounds[r], bounds[r+1]); in the fallback, rank 0
        # holds them all.
        if self.parallel:
            self._bounds = np.array([even_share(r, size, n)[0] for r in range(size)] + [n])
        else:
            self._bounds = np.array([0] + [n] * size)
        self._lo, self._hi = int(self._bounds[rank]), int(self._bounds[rank + 1])
        lo, hi = self._lo, self._hi
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
        # this rank's vertices and triangles, and where they go in the whole surface: the
        # counts of the ranks before it (rank order = gid order)
        conn, tri_block = _fan_triangulate(body_mesh)
        counts = np.array(comm.allgather((len(body_mesh.verts), len(conn))), np.int64)
        before = counts[:rank].sum(axis=0)
        self._vlo, self._tlo = int(before[0]), int(before[1])
        self._vhi, self._thi = self._vlo + len(body_mesh.verts), self._tlo + len(conn)
        self._conn, self._my_tblock = conn + self._vlo, tri_block
        self.n_blocks, self.n_points, self.n_tri = n, int(counts[:, 0].sum()), int(counts[:, 1].sum())
        self.n_snap = 0
        self._extra_cells: list[tuple[str, str]] = []  # static results on the surfaces
        self._times: list[float] = []
        self._hist_rows: dict[str, int] = {}
        self._hist_cols: dict[str, int] = {}
        self._my_verts = body_mesh.verts.copy()
        self._my_vblock = np.repeat(np.arange(hi - lo), np.diff(body_mesh.vert_start))
        self._init_fields(initial_centroid, group, group_names, fixed, ranged)
        self.contacts = bool(contacts)
        self._n_contacts: list[int] = []  # per snapshot, contacts and sub-contacts
        self._n_subs: list[int] = []
        self._bases = {"contacts": 0, "subcontacts": 0}  # rows written so far
        self._pool = 0  # length of xdmf/index (0, 1, 2, ...): the grids' Polyvertex ids
        zone_static = self._init_zones(zones)  # collective: before the file is opened

        self._f: h5py.File | None = None
        self._closed = False
        self._dxpl = None
        if not self._io:
            return
        # Format v108 at least: dense attribute storage, so a large scene fits in an attribute.
        if self.parallel:
            self._f = h5py.File(
                self.path, "w", driver="mpio", comm=comm, libver=("v108", "latest")
            )
            self._dxpl = h5p.create(h5p.DATASET_XFER)
            self._dxpl.set_dxpl_mpio(h5fd.MPIO_COLLECTIVE)
        else:
            self._f = h5py.File(self.path, "w", libver=("v108", "latest"))
        f = self._f
        f.attrs["pdem_format"] = "output"
        f.attrs["format_version"] = FORMAT_VERSION
        for key, value in (attrs or {}).items():
            f.attrs[key] = value
        f.attrs["scene"] = scene_yaml

        def series(name: str, tail: tuple[int, ...], dtype, chunk0: int = 1):
            rows = tail[:1]
            chunk = (chunk0, *(min(max(r, 1), _CHUNK_ROWS) for r in rows), *tail[1:])
            return f.create_dataset(
                name, (0, *tail), maxshape=(None, *tail), chunks=chunk, dtype=dtype
            )

        self._t = series("time", (), np.float64, 1024)
        self._t.attrs["units"] = "s"
        self._step = series("step", (), np.int64, 1024)
        self._stage = series("stage", (), np.int32, 1024)  # index in `stages:` (0 without)
        g = f.create_group("blocks")
        for key, texts in (("name", block_names), ("parent", block_parents or block_names)):
            self._write_texts(g, key, texts)
        # gid and block_id from the rank's rows alone: an arange of every block was the
        # writer's one O(N) array on every rank (8 bytes a block)
        lo, hi = even_share(self.comm.rank, self.comm.size, n) if self.parallel else (0, n)
        self._write(g.create_dataset("gid", (n,), dtype=np.int64), (lo,), np.arange(lo, hi))
        self._series = {fd.output: series(f"blocks/{fd.output}", (n, *fd.shape), fd.dtype)
                        for fd in OUTPUT}
        for fd in OUTPUT:
            self._series[fd.output].attrs["units"] = (
                "1 (unit quaternion w, x, y, z; body to world)" if fd.name == "q" else fd.units)
        s = f.create_group("surface")
        self._write(s.create_dataset("connectivity", (self.n_tri, 3), np.int64), (self._tlo, 0),
                    self._conn if len(self._conn) else None)
        self._write_triangles(s.create_dataset("block_id", (self.n_tri,), np.int64),
                              np.arange(self._lo, self._hi), self._lo)
        self._points = series("surface/points", (self.n_points, 3), np.float64)
        self._points.attrs["units"] = "m"
        f.create_group("histories")
        self._create_fields()
        if self.contacts:
            f.attrs["joint_names"] = [str(j) for j in (joint_names or [])] or [""]
            self._create_contacts()
        if self.zone_layout is not None:
            self._create_zones(zone_static)

    # ------------------------------------------------------------------ low-level writes
    def _write(self, dset: h5py.Dataset, start: tuple[int, ...], data: np.ndarray | None):
        """Write ``data`` at ``start`` (collective in parallel mode; ``None``: take part only)."""
        mtype = h5t.py_create(dset.dtype)
        fspace = dset.id.get_space()
        if data is None or data.size == 0:
            fspace.select_none()
            mspace = h5s.create_simple((1,))
            mspace.select_none()
            buf = np.zeros(1, dtype=dset.dtype)
        else:
            buf = np.ascontiguousarray(data, dtype=dset.dtype)
            fspace.select_hyperslab(start, buf.shape)
            mspace = h5s.create_simple(buf.shape)
        dset.id.write(mspace, fspace, buf, mtype=mtype, dxpl=self._dxpl)

    def _write_texts(self, group, key: str, texts: Sequence[str]) -> None:
        """A fixed-width UTF-8 dataset of one text a block (all ranks know its width; each
        encodes only the rows it writes: a name column of 10^6 blocks is not copied whole)."""
        n = len(texts)
        width = getattr(texts, "max_bytes", None)
        if width is None:
            width = max(len(str(t).encode("utf-8")) for t in texts)
        dset = group.create_dataset(key, (n,), dtype=h5py.string_dtype("utf-8", max(1, width)))
        lo, hi = even_share(self.comm.rank, self.comm.size, n) if self.parallel else (0, n)
        mine = np.array([str(texts[i]).encode("utf-8") for i in range(lo, hi)],
                        dtype=f"S{max(1, width)}")
        self._write(dset, (lo,), mine)

    def _write_static(self, dset: h5py.Dataset, data: np.ndarray) -> None:
        """Each rank writes its contiguous share of the rows of a dataset all ranks know."""
        if self.parallel:
            lo, hi = even_share(self.comm.rank, self.comm.size, len(data))
        else:
            lo, hi = 0, len(data)
        self._write(dset, (lo,) + (0,) * (data.ndim - 1), data[lo:hi])

    def _write_range(self, dset: h5py.Dataset, rows: np.ndarray) -> None:
        """Rows of this rank's gid range (``[lo, hi)``) of a per-block dataset."""
        self._write(dset, (self._lo,) + (0,) * (rows.ndim - 1), rows)

    def _fill_origin(self, mine: np.ndarray) -> None:
        """Rows written without a stage origin (NaN): the initial centroids (the first
        snapshot's when none were given), as without stages."""
        col, w = _COLS["stage_origin"]
        origin = mine[:, col : col + w]
        unset = np.isnan(origin[:, 0])
        origin[unset] = (self._x0 if self._x0 is not None else _cols(mine, "centroid"))[unset]

    def _write_triangles(self, dset: h5py.Dataset, per_block: np.ndarray, first: int = 0) -> None:
        """A static per-triangle dataset from per-block values (gid order, from gid ``first``:
        every block's, or this rank's range's): each rank writes the triangles of its range."""
        mine = np.asarray(per_block)[self._lo - first + self._my_tblock]
        self._write(dset, (self._tlo,) + (0,) * (mine.ndim - 1), mine if len(mine) else None)

    def _write_row(
        self, dset: h5py.Dataset, i: int, data: np.ndarray | None, first: int = 0
    ) -> None:
        """Snapshot ``i``: ``data`` holds rows ``first, first + 1, ...`` (or is ``None``)."""
        ndim = len(dset.shape)
        if data is None or ndim == 1:
            self._write(dset, (i,), None if data is None else data.reshape(1))
        else:
            self._write(dset, (i, first) + (0,) * (ndim - 2), data.reshape((1, *data.shape)))

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"OutputWriter({self.path}): the file is closed")

    def _raise_if_any(self, message: str | None) -> None:
        """Raise ``ValueError`` on every rank if any rank has a message (no lone raise: hangs)."""
        if self.comm.allreduce(int(message is not None), op=MPI.SUM):
            # rare path: every rank raises the same, first, message
            first = next(m for m in self.comm.allgather(message) if m is not None)
            raise ValueError(first)

    # ------------------------------------------------------------------ snapshots
    def _assemble(self, gids: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Send each row to the rank whose gid range holds it; return this rank's range."""
        comm, size = self.comm, self.comm.size
        dest = np.searchsorted(self._bounds, gids, side="right") - 1
        order = np.argsort(dest, kind="stable")
        send_n = np.bincount(dest, minlength=size).astype(np.int64)
        recv_n = np.empty(size, dtype=np.int64)
        comm.Alltoall(send_n, recv_n)
        sdispl = np.concatenate([[0], np.cumsum(send_n)[:-1]])
        rdispl = np.concatenate([[0], np.cumsum(recv_n)[:-1]])
        total = int(recv_n.sum())
        rg = np.empty(total, dtype=np.int64)
        rr = np.empty((total, _ROW_COLS), dtype=np.float64)
        comm.Alltoallv(
            [np.ascontiguousarray(gids[order]), (send_n, sdispl), MPI.INT64_T],
            [rg, (recv_n, rdispl), MPI.INT64_T],
        )
        c = _ROW_COLS
        comm.Alltoallv(
            [np.ascontiguousarray(rows[order]), (send_n * c, sdispl * c), MPI.DOUBLE],
            [rr, (recv_n * c, rdispl * c), MPI.DOUBLE],
        )
        lo, hi = self._lo, self._hi
        hits = np.bincount(rg - lo, minlength=hi - lo)
        msg = None
        if total != hi - lo or np.any(hits != 1):
            missing = np.flatnonzero(hits == 0)[:5] + lo
            dup = np.flatnonzero(hits > 1)[:5] + lo
            msg = (
                "write_snapshot: every gid must be owned by exactly one rank "
                f"(missing e.g. {missing.tolist()}, duplicated e.g. {dup.tolist()})"
            )
        self._raise_if_any(msg)
        out = np.empty((hi - lo, _ROW_COLS))
        out[rg - lo] = rr
        return out

    def write_snapshot(self, step: int, time: float, gids: np.ndarray,
                       fields: dict[str, np.ndarray], contacts: dict | None = None,
                       stage: int = 0, zones: Sequence[tuple[int, Any]] | None = None) -> None:
        """Append one snapshot (collective). Each rank passes the rows of the blocks it owns.

        ``gids`` (k,) in any order; ``fields`` maps every output name (``centroid``,
        ``orientation``, ``velocity``, ``angular_velocity``: the fields of pdem.model.fields
        with an output name) to its (k, ...) rows; ``k`` may be 0. Every gid must be passed
        by exactly one rank (``ValueError`` on every rank otherwise). ``step`` and ``time``
        are taken from rank 0.

        ``contacts`` (writers made with ``contacts=True``; ``None``: none on this rank): the
        contacts this rank writes, each contact passed by exactly one rank, in any order, a
        dict of per-contact ``piece`` (k, 2) piece gids A < B, ``block`` (k, 2), ``joint``
        (k,), ``point`` (k, 3), ``normal`` (k, 3), ``n_sub`` (k,) and, for their sub-contacts
        in contact order, ``sub`` = dict of ``point`` (m, 3) world, ``area``, ``overlap``,
        ``normal_force``, ``shear_force`` (m, 3), ``shear_displacement`` (m, 3), ``state``.

        ``zones`` (writers made with zoned blocks): the zoned blocks this rank owns, ``(gid,
        body)`` pairs as at construction (``body`` with ``nodes``, ``nodes0``, ``vel``, ``stress``
        (m, 6) and ``plastic``), each zoned block passed by exactly one rank.
        """
        self._check_open()
        msg = None
        try:
            gids = np.asarray(gids, dtype=np.int64).reshape(-1)
            k = len(gids)
            rows = np.empty((k, _ROW_COLS))
            for name, (col, w) in _COLS.items():
                if name not in fields and name not in _OPTIONAL:
                    raise ValueError(f"write_snapshot: no {name} rows")
                default = np.zeros((k, w))
                if name == "stage_origin":  # no stages: measured from the start, filled in
                    default = np.full((k, 3), np.nan)  # by the rows' writer (_fill_origin)
                a = np.asarray(fields.get(name, default), dtype=np.float64)
                if a.size != k * w:
                    raise ValueError(f"write_snapshot: {name} has shape {a.shape}, need ({k}, {w})")
                rows[:, col : col + w] = a.reshape(k, w)
            if k and (gids.min() < 0 or gids.max() >= self.n_blocks):
                raise ValueError(f"write_snapshot: gids outside [0, {self.n_blocks})")
        except ValueError as e:
            msg, gids, rows = str(e), np.zeros(0, np.int64), np.zeros((0, _ROW_COLS))
        crows = srows = None
        if self.contacts:
            try:
                crows, srows = self._pack_contacts(contacts)
            except ValueError as e:
                msg = msg or str(e)
        zone_items = None
        if self.zone_layout is not None:
            zmsg, zone_items = self._zone_snapshot(zones)
            msg = msg or zmsg
        self._raise_if_any(msg)
        mine = self._assemble(gids, rows)
        if "stage_origin" not in fields:
            self._fill_origin(mine)
        if self.contacts:
            crows, srows = self._assemble_contacts(crows, srows)
        if self.zone_layout is not None:
            zone_items = self._gather_zones(zone_items)
        i = self.n_snap
        self.n_snap += 1
        self._times.append(float(time))
        if self._io:
            for d in (self._t, self._step, self._stage, self._points, *self._series.values()):
                d.resize(self.n_snap, axis=0)
            root = self.comm.rank == 0
            self._write_row(self._t, i, np.array([time], np.float64) if root else None)
            self._write_row(self._step, i, np.array([step], np.int64) if root else None)
            self._write_row(self._stage, i, np.array([stage], np.int32) if root else None)
            for name, (col, w) in _COLS.items():
                rows_out = mine[:, col : col + w].reshape(-1, *_SHAPES[name])
                self._write_row(self._series[name], i, rows_out, self._lo)
            pts = self._world_points(_cols(mine, "centroid"), _cols(mine, "orientation"))
            self._write_row(self._points, i, pts, self._vlo)
            if self.contacts:
                self._write_contacts(i, crows, srows)
            if self.zone_layout is not None:
                self._write_zones(i, zone_items)
            self._write_fields(i, mine)
            self._f.flush()
        elif self.contacts:
            self._count_contacts(crows, srows)
        if self.xdmf_path is not None and self.comm.rank == 0:
            self._write_xdmf()

    # ------------------------------------------------------------------ viewer fields
    def _init_fields(self, initial_centroid, group, group_names, fixed, ranged: bool) -> None:
        """Check the static per-block data of the viewer fields: every block's, or with
        ``ranged`` this rank's gid range's only (``[lo, hi)``, writer_range)."""
        lo, hi = self._lo, self._hi
        n = hi - lo if ranged else self.n_blocks
        group = np.zeros(n, np.int32) if group is None else np.asarray(group, np.int64).reshape(-1)
        names = ["default"] if group_names is None else [str(g) for g in group_names]
        fixed = np.zeros(n, bool) if fixed is None else np.asarray(fixed, bool).reshape(-1)
        x0 = None if initial_centroid is None else np.asarray(initial_centroid, np.float64)
        if len(group) != n or len(fixed) != n or (x0 is not None and x0.shape != (n, 3)):
            raise ValueError(f"OutputWriter: group, fixed and initial_centroid need {n} rows"
                             + (" (this rank's range)" if ranged else ""))
        if len(group) and (group.min() < 0 or group.max() >= len(names)):
            raise ValueError(f"OutputWriter: group ids outside [0, {len(names)}) (group_names)")
        # of every block, only this rank's gid range is kept: group and fixed until they are
        # written (_create_fields), the initial centroids for the displacements (None: the
        # first snapshot's); every rank keeping every block's would be 32 bytes a block
        rows = slice(None) if ranged else slice(lo, hi)
        self._group_names = names
        self._group, self._fixed = group[rows].astype(np.int32), fixed[rows].astype(np.int32)
        self._x0: np.ndarray | None = None if x0 is None else x0[rows].copy()

    def _create_fields(self) -> None:
        """Static per-block and per-triangle data, and the per-triangle series (IO ranks)."""
        f, n, nt = self._f, self.n_blocks, self.n_tri
        grp = f["blocks"].create_dataset("group", (n,), np.int32)
        grp.attrs["names"] = self._group_names
        self._write_range(grp, self._group)
        self._write_range(f["blocks"].create_dataset("fixed", (n,), np.int32), self._fixed)
        x0 = f["blocks"].create_dataset("initial_centroid", (n, 3), np.float64)
        x0.attrs["units"] = "m"
        if self._x0 is not None:
            self._write_range(x0, self._x0)
        for name, values in (("group", self._group), ("fixed", self._fixed)):
            self._write_triangles(f["surface"].create_dataset(name, (nt,), np.int32), values,
                                  self._lo)
        self._group = self._fixed = None  # written
        self._cells = {}
        for name, width, units in CELL_FIELDS:
            tail = (nt, width) if width > 1 else (nt,)
            chunk = (1, min(max(nt, 1), _CHUNK_ROWS), *tail[1:])
            # A block's value repeats on each of its triangles: deflate takes most of that back
            # (parallel HDF5 writes filtered datasets collectively, as all writes here are).
            d = f.create_dataset(
                f"surface/{name}", (0, *tail), maxshape=(None, *tail), chunks=chunk, dtype=np.float32,
                compression="gzip", compression_opts=4, shuffle=True,
            )
            d.attrs["units"] = units
            self._cells[name] = d

    def _write_fields(self, i: int, mine: np.ndarray) -> None:
        """Snapshot ``i`` of the per-triangle series, and its ``/xdmf`` views (collective)."""
        if self._x0 is None:  # first snapshot: fix the displacement reference
            self._x0 = _cols(mine, "centroid").copy()
            self._write(self._f["blocks/initial_centroid"], (self._lo, 0), self._x0)
        values = _block_fields(_cols(mine, "centroid"), self._x0, _cols(mine, "velocity"),
                               _cols(mine, "angular_velocity"), _cols(mine, "removed")[:, 0],
                               _cols(mine, "stage_origin"))
        for name, d in self._cells.items():
            d.resize(self.n_snap, axis=0)
            self._write_row(d, i, values[name][self._my_tblock], self._tlo)
        for path in VIEWED_SERIES:
            _add_view(self._f, path, i)
        if self.parallel and (i + 1) % _REOPEN_EVERY == 0:
            self._reopen()

    def _reopen(self) -> None:
        """Close and reopen the file (collective), rebinding the datasets kept open."""
        self._f.close()
        self._f = h5py.File(self.path, "r+", driver="mpio", comm=self.comm)
        f = self._f
        self._t, self._step, self._points = f["time"], f["step"], f["surface/points"]
        self._stage = f["stage"]
        self._series = {name: f[f"blocks/{name}"] for name in self._series}
        self._cells = {name: f[f"surface/{name}"] for name in self._cells}

    def _world_points(self, centroid: np.ndarray, quat: np.ndarray) -> np.ndarray:
        """World positions ``c + R(q) v`` of the vertices of this rank's gid range."""
        R = quat_to_matrix(quat)[self._my_vblock]
        c = centroid[self._my_vblock]
        v = self._my_verts
        # Explicit sums, fixed order: bitwise the same whatever the partition.
        return c + (
            R[:, :, 0] * v[:, 0:1] + R[:, :, 1] * v[:, 1:2] + R[:, :, 2] * v[:, 2:3]
        )

    def _write_xdmf(self) -> None:
        write_xdmf(
            self.path, self.xdmf_path, self.n_snap, self._times,
            self.n_tri, self.n_points, self.n_blocks,
            contacts=(self._n_contacts, self._n_subs) if self.contacts else None,
            extra_cells=self._extra_cells,
            zones=None if self.zone_layout is None
            else (self.zone_layout.n_points, self.zone_layout.n_zones),
        )

    # ------------------------------------------------------------------ contacts
    def _create_contacts(self) -> None:
        """The flat contact and sub-contact series and their snapshot offsets (IO ranks)."""
        f = self._f
        for group, series in (("contacts", joints.CONTACT_SERIES),
                              ("subcontacts", joints.SUB_SERIES)):
            off = f.create_dataset(f"{group}/offset", (1,), maxshape=(None,), chunks=(1024,),
                                   dtype=np.int64)
            self._write(off, (0,), np.zeros(1, np.int64) if self.comm.rank == 0 else None)
            off.attrs["doc"] = f"snapshot i is rows offset[i] .. offset[i+1]-1 of {group}/*"
            for name, tail, dtype, units, doc in series:
                d = f.create_dataset(
                    f"{group}/{name}", (0, *tail), maxshape=(None, *tail),
                    chunks=(_CONTACT_CHUNK, *tail), dtype=dtype, compression="gzip",
                    compression_opts=4, shuffle=True)
                d.attrs["units"] = units
                d.attrs["doc"] = doc
        f["contacts/state"].attrs["names"] = list(joints.STATE_NAMES)
        f.create_dataset("xdmf/index", (0,), maxshape=(None,), chunks=(_CONTACT_CHUNK,),
                         dtype=np.int64)

    def _pack_contacts(self, contacts: dict | None) -> tuple[np.ndarray, np.ndarray]:
        """This rank's contacts and sub-contacts as float64 rows (``ValueError`` if bad)."""
        if contacts is None:
            return np.zeros((0, joints.C_WIDTH)), np.zeros((0, joints.S_WIDTH))
        crows = joints.pack(contacts, joints.CONTACT_COLS, joints.C_AT, joints.C_WIDTH)
        srows = joints.pack(contacts["sub"], joints.SUB_COLS, joints.S_AT, joints.S_WIDTH)
        nsub = joints.col(crows, joints.C_AT, "n_sub")
        if (nsub < 0).any() or nsub.sum() != len(srows):
            raise ValueError(f"write_snapshot: contacts n_sub sums to {nsub.sum()}, "
                             f"{len(srows)} sub-contacts given")
        block = joints.col(crows, joints.C_AT, "block")
        if len(block) and (block.min() < 0 or block.max() >= self.n_blocks):
            raise ValueError(f"write_snapshot: contact blocks outside [0, {self.n_blocks})")
        return crows, srows

    def _exchange(self, dest: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Rows to rank ``dest`` (stable: received in source-rank order, then row order)."""
        comm, size, c = self.comm, self.comm.size, rows.shape[1]
        order = np.argsort(dest, kind="stable")
        send_n = np.bincount(dest, minlength=size).astype(np.int64)
        recv_n = np.empty(size, dtype=np.int64)
        comm.Alltoall(send_n, recv_n)
        sdispl = np.concatenate([[0], np.cumsum(send_n)[:-1]])
        rdispl = np.concatenate([[0], np.cumsum(recv_n)[:-1]])
        out = np.empty((int(recv_n.sum()), c))
        comm.Alltoallv(
            [np.ascontiguousarray(rows[order]), (send_n * c, sdispl * c), MPI.DOUBLE],
            [out, (recv_n * c, rdispl * c), MPI.DOUBLE],
        )
        return out

    def _assemble_contacts(self, crows, srows) -> tuple[np.ndarray, np.ndarray]:
        """Each contact (and its sub-contacts) to the rank whose gid range holds block A: piece
        gids are numbered block by block, so rank r's keys all precede rank r+1's; then sorted
        by key. Raises ``ValueError`` on every rank if a contact came twice."""
        ga = joints.col(crows, joints.C_AT, "block")[:, 0].astype(np.int64)
        dest = np.searchsorted(self._bounds, ga, side="right") - 1
        nsub = joints.col(crows, joints.C_AT, "n_sub").astype(np.int64)
        crows = self._exchange(dest, crows)
        srows = self._exchange(np.repeat(dest, nsub), srows)
        crows, srows = joints.sort_contacts(crows, srows)
        piece = joints.col(crows, joints.C_AT, "piece")
        msg = None
        if len(piece) > 1:
            same = np.flatnonzero((piece[1:] == piece[:-1]).all(axis=1))
            if len(same):
                msg = (f"write_snapshot: contact {piece[same[0]].astype(int).tolist()} passed "
                       "twice (each contact must be passed by exactly one rank)")
        self._raise_if_any(msg)
        return crows, srows

    def _count_contacts(self, crows, srows) -> tuple[int, int, int, int]:
        """Totals over the ranks and this rank's offsets: (n_c, n_s, off_c, off_s)."""
        counts = np.array([len(crows), len(srows)], np.int64)
        every = np.array(self.comm.allgather(counts)).reshape(-1, 2)
        before = every[: self.comm.rank].sum(axis=0)
        tot = every.sum(axis=0)
        self._n_contacts.append(int(tot[0]))
        self._n_subs.append(int(tot[1]))
        return int(tot[0]), int(tot[1]), int(before[0]), int(before[1])

    def _write_contacts(self, i: int, crows: np.ndarray, srows: np.ndarray) -> None:
        """Snapshot ``i``'s contacts: this rank's sorted slab of the flat series (collective),
        the offsets, and the views of the contact sidecars."""
        f = self._f
        n_c, n_s, off_c, off_s = self._count_contacts(crows, srows)
        cvals, svals = joints.reduce_contacts(crows, srows)
        root = self.comm.rank == 0
        for group, series, values, n, off in (
                ("contacts", joints.CONTACT_SERIES, cvals, n_c, off_c),
                ("subcontacts", joints.SUB_SERIES, svals, n_s, off_s)):
            offset = f[f"{group}/offset"]
            base = self._bases[group]
            offset.resize(i + 2, axis=0)
            self._write(offset, (i + 1,), np.array([base + n], np.int64) if root else None)
            for name, tail, dtype, _, _ in series:
                d = f[f"{group}/{name}"]
                d.resize(base + n, axis=0)
                data = np.asarray(values[name]).reshape(-1, *tail).astype(dtype)
                self._write(d, (base + off,) + (0,) * len(tail), data)
            self._bases[group] = base + n
        need = max(n_c, n_s)
        if need > self._pool:
            pool = f["xdmf/index"]
            pool.resize(need, axis=0)
            lo, hi = even_share(self.comm.rank, self.comm.size, need - self._pool) if self.parallel \
                else (0, need - self._pool)
            self._write(pool, (self._pool + lo,), np.arange(self._pool + lo, self._pool + hi))
            self._pool = need
        for group, viewed, n in (("contacts", CONTACT_VIEWED, n_c),
                                 ("subcontacts", SUB_VIEWED, n_s)):
            if n == 0:
                continue
            hi = self._bases[group]
            for name in viewed:
                _add_range_view(f, f"/{group}/{name}", view_path(f"/{group}/{name}", i),
                                hi - n, hi)
            _add_range_view(f, "/xdmf/index", view_path(f"/{group}/index", i), 0, n)

    # ------------------------------------------------------------------ zoned blocks
    def _init_zones(self, zones) -> list | None:
        """The zoned blocks' layout from every rank's (gid, gridpoints, zones) (collective):
        ``self.zone_layout``, ``None`` without zoned blocks. Returns what this rank writes of
        the static grid: ``(gid, {initial_points, tets})`` by gid (rank 0 all of them in the
        fallback)."""
        msg, counts, static = None, np.zeros((0, 3), np.int64), []
        try:
            for gid, body in ([] if zones is None else zones):
                tets = np.asarray(body.tets, np.int64)
                x0 = np.asarray(body.nodes0, np.float64)
                if x0.ndim != 2 or x0.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4 \
                        or (tets.size and (tets.min() < 0 or tets.max() >= len(x0))):
                    raise ValueError(f"OutputWriter: zoned block {gid}: nodes0 {x0.shape}, "
                                     f"tets {tets.shape} (need (n, 3) and (m, 4) ids < n)")
                if not 0 <= int(gid) < self.n_blocks:
                    raise ValueError(f"OutputWriter: zoned block gid {gid} outside "
                                     f"[0, {self.n_blocks})")
                static.append((int(gid), {"initial_points": x0, "tets": tets}))
            counts = np.array([(g, len(v["initial_points"]), len(v["tets"])) for g, v in static],
                              np.int64).reshape(-1, 3)
        except (TypeError, ValueError, AttributeError) as e:
            msg, counts, static = str(e), np.zeros((0, 3), np.int64), []
        self._raise_if_any(msg)
        layout = zone_layout(self.comm.allgather(counts))  # the same ValueError on every rank
        self.zone_layout: ZoneLayout | None = layout if len(layout.gid) else None
        if self.zone_layout is None:
            return None
        return self._zone_writers(static)

    def _zone_writers(self, items: list) -> list:
        """``(gid, values)`` items to the ranks that write them, sorted by gid: each its own
        in parallel mode; in the fallback, all of them to rank 0."""
        if not self.parallel and self.comm.size > 1:
            every = self.comm.gather(items, root=0)
            items = [it for part in every for it in part] if self.comm.rank == 0 else []
        return sorted(items, key=lambda it: it[0])

    def _zone_snapshot(self, zones) -> tuple[str | None, list]:
        """This rank's zoned blocks' snapshot values, checked against the layout: (error, items)."""
        lay = self.zone_layout
        items = []
        try:
            for gid, body in ([] if zones is None else zones):
                k = int(np.searchsorted(lay.gid, int(gid)))
                if k == len(lay.gid) or lay.gid[k] != int(gid):
                    raise ValueError(f"write_snapshot: block {gid} is not a zoned block")
                v = zone_values(body)
                for name, w, *_ in POINT_SERIES + ZONE_SERIES:
                    start = lay.point_start if name in _POINT_NAMES else lay.zone_start
                    n = start[k + 1] - start[k]
                    if v[name].size != n * w:
                        raise ValueError(f"write_snapshot: zoned block {gid}: {name} has shape "
                                         f"{np.shape(v[name])}, need ({n}, {w})")
                items.append((int(gid), v))
        except (TypeError, ValueError, AttributeError) as e:
            return str(e), []
        return None, items

    def _gather_zones(self, items: list) -> list:
        """Check that every zoned block was passed by exactly one rank (``ValueError`` on every
        rank otherwise), then send the items to their writers (collective)."""
        got = np.sort(np.concatenate([np.asarray(g, np.int64) for g in
                                      self.comm.allgather([gid for gid, _ in items])]))
        if not np.array_equal(got, self.zone_layout.gid):
            missing = np.setdiff1d(self.zone_layout.gid, got)[:5]
            dup = got[1:][np.diff(got) == 0][:5] if len(got) > 1 else got[:0]
            raise ValueError("write_snapshot: every zoned block must be passed by exactly one "
                             f"rank (missing e.g. {missing.tolist()}, duplicated e.g. "
                             f"{dup.tolist()})")
        return self._zone_writers(items)

    def _write_runs(self, dset: h5py.Dataset, lead: tuple[int, ...], starts, counts,
                    data: np.ndarray | None) -> None:
        """Rows ``starts[k] .. starts[k] + counts[k] - 1`` (ascending, disjoint) of ``dset``
        after the leading indices ``lead`` (``(i,)``: snapshot ``i``), from ``data``, the runs'
        rows one after the other: one write whose selection is the union of the runs
        (collective in parallel mode; HDF5 walks a union in file order, so the runs' rows
        follow in ``data`` as in the file)."""
        if data is None or len(data) == 0:
            self._write(dset, (0,) * len(dset.shape), None)
            return
        tail = dset.shape[len(lead) + 1:]
        buf = np.ascontiguousarray(data, dtype=dset.dtype).reshape(-1, *tail)
        fspace = dset.id.get_space()
        fspace.select_none()
        for s, c in zip(starts, counts, strict=True):
            fspace.select_hyperslab((*lead, int(s), *(0,) * len(tail)),
                                    (*(1,) * len(lead), int(c), *tail), op=h5s.SELECT_OR)
        dset.id.write(h5s.create_simple(buf.shape), fspace, buf,
                      mtype=h5t.py_create(dset.dtype), dxpl=self._dxpl)

    def _create_zones(self, static: list) -> None:
        """The group ``zones/``: static grid and empty series (IO ranks, collective)."""
        f, lay = self._f, self.zone_layout
        npt, nz = lay.n_points, lay.n_zones
        g = f.create_group("zones")
        g.attrs["doc"] = ("zoned (deformable) blocks as one tetrahedral grid, blocks by gid: block "
                          "k's gridpoints are rows point_start[k] .. point_start[k+1]-1, its "
                          "zones zone_start[k] .. zone_start[k+1]-1")
        for name, data in (("block", lay.gid), ("point_start", lay.point_start),
                           ("zone_start", lay.zone_start)):
            self._write_static(g.create_dataset(name, (len(data),), np.int64), data)
        g["block"].attrs["doc"] = "gids of the zoned blocks, ascending"
        gids = np.array([gid for gid, _ in static], np.int64)
        p0, pn, z0, zn = lay.runs(gids)

        def cat(rows, tail=()):
            return np.concatenate(rows) if rows else np.zeros((0, *tail))
        conn = cat([v["tets"] + p for (_, v), p in zip(static, p0, strict=True)], (4,))
        x0 = cat([v["initial_points"] for _, v in static], (3,))
        for name, shape, dtype, data, per_point, units, doc in (
                ("connectivity", (nz, 4), np.int64, conn, False, "",
                 "the zones' 4 gridpoints, rows of the zones/points series"),
                ("zone_block", (nz,), np.int64, np.repeat(gids, zn), False, "",
                 "gid of each zone's block"),
                ("point_block", (npt,), np.int64, np.repeat(gids, pn), True, "",
                 "gid of each gridpoint's block"),
                ("initial_points", (npt, 3), np.float64, x0, True, "m",
                 "gridpoint positions at the start (reference of displacement)")):
            d = g.create_dataset(name, shape, dtype)
            self._write_runs(d, (), p0 if per_point else z0, pn if per_point else zn, data)
            d.attrs["doc"] = doc
            if units:
                d.attrs["units"] = units
        for series, n in ((POINT_SERIES, npt), (ZONE_SERIES, nz)):
            for name, w, dtype, units, doc in series:
                tail = (n, w) if w > 1 else (n,)
                d = f.create_dataset(f"zones/{name}", (0, *tail), maxshape=(None, *tail),
                                     chunks=(1, min(max(n, 1), _CHUNK_ROWS), *tail[1:]),
                                     dtype=dtype)
                d.attrs["units"] = units
                d.attrs["doc"] = doc

    def _write_zones(self, i: int, items: list) -> None:
        """Snapshot ``i`` of the zone series and its ``/xdmf`` views (IO ranks, collective)."""
        f = self._f
        gids = np.array([gid for gid, _ in items], np.int64)
        p0, pn, z0, zn = self.zone_layout.runs(gids)
        for series, starts, counts in ((POINT_SERIES, p0, pn), (ZONE_SERIES, z0, zn)):
            for name, *_ in series:
                d = f[f"zones/{name}"]
                d.resize(self.n_snap, axis=0)
                data = np.concatenate([v[name] for _, v in items]) if items else None
                self._write_runs(d, (i,), starts, counts, data)
        for path in ZONE_VIEWED:
            _add_view(f, path, i)

    # ------------------------------------------------------------------ histories
    def add_history(self, name: str, ncols: int, attrs: dict[str, Any] | None = None) -> None:
        """Create ``histories/<name>/{time, value}`` (collective; same arguments everywhere).

        ``value`` has shape (n, ``ncols``); ``attrs`` (e.g. ``block``, ``quantity``,
        ``units``, ``columns``) go on the ``histories/<name>`` group.
        """
        self._check_open()
        if not name or "/" in name or name in self._hist_rows:
            raise ValueError(f"add_history: bad or duplicate history name {name!r}")
        if int(ncols) < 1:
            raise ValueError(f"add_history({name!r}): ncols must be >= 1 (got {ncols})")
        self._hist_rows[name] = 0
        self._hist_cols[name] = int(ncols)
        if not self._io:
            return
        g = self._f["histories"].create_group(name)
        for key, value in (attrs or {}).items():
            g.attrs[key] = value
        g.create_dataset("time", (0,), maxshape=(None,), chunks=(1024,), dtype=np.float64)
        g.create_dataset(
            "value", (0, int(ncols)), maxshape=(None, int(ncols)), chunks=(1024, int(ncols)),
            dtype=np.float64,
        )

    def write_history(self, name: str, time, values: np.ndarray | None) -> None:
        """Append rows to a history (collective).

        Exactly one rank, the owner of the monitored block, passes ``values``: one row
        (``ncols``,) at scalar ``time``, or a batch (k, ``ncols``) at times (k,) -- the solver
        buffers samples and writes them in batches; the others pass ``None``.
        """
        self._check_open()
        if name not in self._hist_rows:
            raise ValueError(f"write_history: no history {name!r} (call add_history first)")
        ncols = self._hist_cols[name]
        rows = None
        invalid = 0
        if values is not None:
            v = np.asarray(values, dtype=np.float64)
            t = np.atleast_1d(np.asarray(time, dtype=np.float64))
            v = v.reshape(len(t), ncols) if v.size == len(t) * ncols else None
            if v is not None:
                rows = np.column_stack([t, v])
            else:
                invalid = 1
        k = 0 if rows is None else len(rows)
        flags = np.array([rows is not None, invalid, (self.comm.rank + 1) * (rows is not None), k])
        self.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.SUM)
        if flags[1] or flags[0] != 1:
            raise ValueError(
                f"write_history({name!r}): exactly one rank must pass {ncols} values per row "
                f"({int(flags[0])} valid, {int(flags[1])} of the wrong size)"
            )
        owner = int(flags[2]) - 1
        k = int(flags[3])
        if not self.parallel and owner != 0:
            if self.comm.rank == owner:
                self.comm.Send(np.ascontiguousarray(rows), dest=0, tag=77)
            elif self.comm.rank == 0:
                rows = np.empty((k, ncols + 1))
                self.comm.Recv(rows, source=owner, tag=77)
        i = self._hist_rows[name]
        self._hist_rows[name] = i + k
        if not self._io or k == 0:
            return
        g = self._f["histories"][name]
        g["time"].resize(i + k, axis=0)
        g["value"].resize(i + k, axis=0)
        mine = rows is not None
        self._write(g["time"], (i,), np.ascontiguousarray(rows[:, 0]) if mine else None)
        self._write(g["value"], (i, 0), np.ascontiguousarray(rows[:, 1:]) if mine else None)

    # ------------------------------------------------------------------ file
    def write_result(self, group: str, attrs: dict[str, Any],
                     datasets: dict[str, np.ndarray], surface: tuple[str, ...] = ()) -> None:
        """A result every rank holds whole (e.g. a factor-of-safety search): root attributes
        ``attrs`` and static datasets ``group/<name>`` (collective; replaced if present).
        ``surface``: per-block datasets also shown on the block surfaces (XDMF cell fields,
        ``group/surface_<name>``)."""
        self._check_open()
        for name in surface:
            if (name, f"/{group}/surface_{name}") not in self._extra_cells:
                self._extra_cells.append((name, f"/{group}/surface_{name}"))
        if not self._io:
            return
        f = self._f
        for key, value in attrs.items():
            f.attrs[key] = value
        g = f.require_group(group)
        for name, data in datasets.items():
            data = np.ascontiguousarray(data)
            if name in g:
                del g[name]
            self._write_static(g.create_dataset(name, data.shape, data.dtype), data)
        for name in surface:
            key = f"surface_{name}"
            if key in g:
                del g[key]
            self._write_triangles(g.create_dataset(key, (self.n_tri,), np.float32),
                                  np.asarray(datasets[name], np.float32))
        f.flush()
        if surface and self.xdmf_path is not None and self.comm.rank == 0:
            self._write_xdmf()

    def flush(self) -> None:
        """Flush the HDF5 file to disk (collective)."""
        if self._f is not None:
            self._f.flush()

    def close(self) -> None:
        """Close the file and write the final XDMF (collective; idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self._f is not None:
            self._f.close()
            self._f = None
        if self.xdmf_path is not None and self.comm.rank == 0:
            self._write_xdmf()
        self.comm.Barrier()  # the file and its sidecar are complete when close returns

    def __enter__(self) -> OutputWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
