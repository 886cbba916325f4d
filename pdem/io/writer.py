"""Run output: one HDF5 file per run, written collectively (mpio) or gathered on rank 0.

:class:`OutputWriter` is the façade: the file and its communicator are a
:class:`pdem.io.h5core.H5Core`, and each output section has its writer: the block series
(:mod:`pdem.io.block_series`), the viewer fields (:mod:`pdem.io.viewer_fields`), the contacts
(:mod:`pdem.io.contact_series`), the zoned blocks (:mod:`pdem.io.zone_series`), and the
histories and results (:mod:`pdem.io.histories`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np
from mpi4py import MPI

from ..memory import mapping_large_blocks, return_freed_memory
from .block_series import BlockSeries, quat_to_matrix
from .contact_series import ContactSeries
from .elements import write_elements_xdmf, write_snapshot_elements
from .h5core import REOPEN_EVERY, H5Core
from .histories import HistoryWriter
from .surfaces import BodyMesh
from .viewer_fields import ViewerFields
from .xdmf import write_xdmf
from .zone_series import ZoneSeries
from .zone_surfaces import ZoneSurfaces
from .zones import ZoneLayout

__all__ = ["OutputWriter", "FORMAT_VERSION", "quat_to_matrix"]

# 2: per-triangle colouring fields, blocks/group|fixed|initial_centroid, /xdmf views
FORMAT_VERSION = 2


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
        snapshot then takes the zoned blocks (see :meth:`write_snapshot`). Their triangles in
        ``surface/`` (``run.xdmf``) are their grids' boundaries at the snapshot's gridpoint
        positions (:mod:`pdem.io.zone_surfaces`), not their build-time polyhedra.
    zone_fields
        The zone series written besides the gridpoint positions (``output.zones.fields``,
        names of :data:`pdem.io.zones.ZONE_FIELDS`); None: all of them.

    Notes
    -----
    The file layout depends only on the scene, never on the rank count. In parallel mode
    every snapshot's rows are first redistributed (one ``Alltoallv``) so that rank ``r`` holds
    a contiguous gid range; every rank then writes one hyperslab per dataset with collective
    I/O, a rank with an empty range taking part with an empty selection. The contacts go the
    same way in rounds (a part of every rank's gid range each), so that no rank holds more
    than a round's contacts (``pdem.io.contact_series.ROUND_ROWS`` rows) at once.
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
        zone_fields: Sequence[str] | None = None,
    ) -> None:

        self._core = core = H5Core(path, comm, len(block_names), parallel)
        self.path = core.path
        self.xdmf_path = self.path.with_suffix(".xdmf") if xdmf else None
        self._element_snaps: list[tuple[int, float, int, int]] = []  # (pdem.io.elements)
        self.comm = comm
        self.parallel = core.parallel
        # collective, before the file opens; first: the zoned blocks' surfaces replace their
        # polyhedra's in the block surfaces
        self._zones = ZoneSeries(core, len(block_names), zones, zone_fields)
        self.zone_layout: ZoneLayout | None = self._zones.layout
        self._zone_surfaces = None if self.zone_layout is None else ZoneSurfaces(core, zones)
        self._blocks = BlockSeries(core, len(block_names), body_vertices, body_faces, body_mesh,
                                   self._zone_surfaces)
        self.n_blocks, self.n_points = self._blocks.n_blocks, self._blocks.n_points
        self.n_tri = self._blocks.n_tri
        self.n_snap = 0
        self._extra_cells: list[tuple[str, str]] = []  # static results on the surfaces
        self._times: list[float] = []
        self._histories = HistoryWriter(core)
        self._fields = ViewerFields(core, self._blocks, initial_centroid, group, group_names,
                                    fixed, ranged)
        self.contacts = bool(contacts)
        self._contacts = ContactSeries(core, self.n_blocks) if self.contacts else None
        self._closed = False
        if not core.io:
            return
        core.open({"pdem_format": "output", "format_version": FORMAT_VERSION, **(attrs or {}),
                   "scene": scene_yaml})
        self._blocks.create(block_names, block_parents)
        self._histories.create()
        self._fields.create()
        if self.contacts:
            self._contacts.create(joint_names)
        if self.zone_layout is not None:
            self._zones.create()

    # ------------------------------------------------------------------ internals tests read
    @property
    def _f(self):
        """The open ``h5py.File`` (``None`` on a rank that does not write, or once closed)."""
        return self._core.f

    @property
    def _lo(self) -> int:
        return self._core.lo

    @property
    def _hi(self) -> int:
        return self._core.hi

    @property
    def _group(self):
        return self._fields.group

    @property
    def _fixed(self):
        return self._fields.fixed

    @property
    def _x0(self):
        return self._fields.x0

    def _write_runs(self, dset, lead, starts, counts, data) -> None:
        self._core.write_runs(dset, lead, starts, counts, data)

    # ------------------------------------------------------------------ snapshots
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
        contacts this rank writes, each contact passed by exactly one rank, in any order: a
        :class:`pdem.io.contact_series.ContactSource` that makes them a round at a time (the
        writer streams them to the file in rounds of ``ROUND_ROWS`` rows), or a
        dict of per-contact ``piece`` (k, 2) piece gids A < B, ``block`` (k, 2), ``joint``
        (k,), ``point`` (k, 3), ``normal`` (k, 3), ``n_sub`` (k,) and, for their sub-contacts
        in contact order, ``sub`` = dict of ``point`` (m, 3) world, ``area``, ``overlap``,
        ``normal_force``, ``shear_force`` (m, 3), ``shear_displacement`` (m, 3), ``state``.

        ``zones`` (writers made with zoned blocks): the zoned blocks this rank owns, ``(gid,
        body)`` pairs as at construction (``body`` with ``nodes``, ``nodes0``, ``vel``, ``stress``
        (m, 6) and ``plastic``), each zoned block passed by exactly one rank. Their boundary
        gridpoints are also the vertices of their triangles in ``surface/points``.
        """
        self._core.check_open()
        # the snapshot's arrays are mapped, each returned to the system when freed (pdem.memory)
        with mapping_large_blocks():
            self._write_snapshot(step, time, gids, fields, contacts, stage, zones)
        # the snapshot's small objects and HDF5's buffers back to the system: glibc keeps freed
        # blocks for reuse, and each snapshot's peak otherwise came on top of the last one's
        return_freed_memory()

    def _write_snapshot(self, step, time, gids, fields, contacts, stage, zones) -> None:
        core = self._core
        msg, gids, rows = self._blocks.pack(gids, fields)
        source = None
        if self.contacts:
            try:
                source = self._contacts.prepare(contacts)
            except ValueError as e:
                msg = msg or str(e)
        zone_items = None
        if self.zone_layout is not None:
            zmsg, zone_items = self._zones.snapshot(zones)
            msg = msg or zmsg
        core.raise_if_any(msg)
        packed = [gids, rows]  # handed over: assemble frees the passed rows once sent
        del gids, rows
        mine = self._blocks.assemble(packed)
        if "stage_origin" not in fields:
            self._fields.fill_origin(mine)
        zoned_points = None
        if self.zone_layout is not None:
            owned, zone_items = zone_items, self._zones.gather(zone_items)
            zoned_points = self._zone_surfaces.points(zones or [], owned)
            del owned
        i = self.n_snap
        self.n_snap += 1
        self._times.append(float(time))
        if core.io:
            self._blocks.write(i, mine, step, time, stage, zoned_points)
            self._fields.write(i, mine)
            if self.zone_layout is not None:
                self._zones.write(i, zone_items)
        # the block rows are written: not held while the contacts' rounds are made
        del mine, zone_items, zoned_points
        if self.contacts:  # every rank: the contacts are streamed in rounds
            self._contacts.write(i, source)
            del source
        if core.io:
            if self.parallel and (i + 1) % REOPEN_EVERY == 0:
                core.reopen()
            core.f.flush()
        if self.xdmf_path is not None and self.comm.rank == 0:
            self._write_xdmf()

    def _write_xdmf(self) -> None:
        c, lay = self._contacts, self.zone_layout
        write_xdmf(
            self.path, self.xdmf_path, self.n_snap, self._times,
            self.n_tri, self.n_points, self.n_blocks,
            contacts=(c.n_contacts, c.n_subs) if self.contacts else None,
            extra_cells=self._extra_cells,
            zones=None if lay is None else (lay.n_points, lay.n_zones, self._zones.names),
        )

    def write_elements(self, data: dict[str, np.ndarray], entries: list[str]) -> None:
        """The reinforcement of the last snapshot written (collective; every rank passes the
        same ``data``, :mod:`pdem.io.elements`) and the ``-reinforcement.xdmf`` sidecar."""
        self._core.check_open()
        i = self.n_snap - 1
        self._element_snaps.append((i, self._times[-1], len(data["points"]),
                                    len(data["segments"])))
        if self._core.io:
            write_snapshot_elements(self._core.f, i, data, entries)
            self._core.f.flush()
        if self.xdmf_path is not None and self.comm.rank == 0:
            write_elements_xdmf(self.path, self._element_snaps)

    # ------------------------------------------------------------------ histories, results
    def add_history(self, name: str, ncols: int, attrs: dict[str, Any] | None = None) -> None:
        """Create ``histories/<name>/{time, value}`` (collective; same arguments everywhere).

        ``value`` has shape (n, ``ncols``); ``attrs`` (e.g. ``block``, ``quantity``,
        ``units``, ``columns``) go on the ``histories/<name>`` group.
        """
        self._core.check_open()
        self._histories.add(name, ncols, attrs)

    def write_history(self, name: str, time, values: np.ndarray | None) -> None:
        """Append rows to a history (collective).

        Exactly one rank, the owner of the monitored block, passes ``values``: one row
        (``ncols``,) at scalar ``time``, or a batch (k, ``ncols``) at times (k,) -- the solver
        buffers samples and writes them in batches; the others pass ``None``.
        """
        self._core.check_open()
        self._histories.write(name, time, values)

    def write_result(self, group: str, attrs: dict[str, Any],
                     datasets: dict[str, np.ndarray], surface: tuple[str, ...] = ()) -> None:
        """A result every rank holds whole (e.g. a factor-of-safety search): root attributes
        ``attrs`` and static datasets ``group/<name>`` (collective; replaced if present).
        ``surface``: per-block datasets also shown on the block surfaces (XDMF cell fields,
        ``group/surface_<name>``)."""
        self._core.check_open()
        for name in surface:
            if (name, f"/{group}/surface_{name}") not in self._extra_cells:
                self._extra_cells.append((name, f"/{group}/surface_{name}"))
        if not self._core.io:
            return
        self._histories.write_result(group, attrs, datasets, surface, self.n_tri,
                                     self._blocks.write_triangles)
        self._core.f.flush()
        if surface and self.xdmf_path is not None and self.comm.rank == 0:
            self._write_xdmf()

    # ------------------------------------------------------------------ file
    def flush(self) -> None:
        """Flush the HDF5 file to disk (collective)."""
        self._core.flush()

    def close(self) -> None:
        """Close the file and write the final XDMF (collective; idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._core.close()
        if self.xdmf_path is not None and self.comm.rank == 0:
            self._write_xdmf()
        self.comm.Barrier()  # the file and its sidecar are complete when close returns

    def __enter__(self) -> OutputWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
