"""Zoned (deformable) blocks in the output file: group ``zones/`` and the sidecar ``-zones.xdmf``.

A zoned block (``zones:`` in the scene, pdem.deformable) is written as an unstructured grid of
tetrahedra beside the rigid blocks' surfaces: its gridpoints (positions, displacement, velocity)
and its zones (stress, plastic state and a few stress invariants). All zoned blocks form one
grid, numbered block by block in gid order (gridpoints and zones in each block's own order), so
the file does not depend on how many ranks ran the model nor on which rank owned which block.

Each rank passes the zoned blocks it owns; the counts of every zoned block are gathered once, at
the start (the zoning does not change), and give each block its rows. In parallel mode each rank
writes its own blocks' rows, one collective write per dataset whose selection is the union of
its blocks' row ranges; in the fallback (h5py without MPI) the blocks are sent to rank 0, which
writes them all.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

__all__ = ["ZoneLayout", "zone_layout", "zone_values", "ZoneColumn", "ZONE_COLUMNS",
           "ZONE_FIELDS", "zone_columns", "POINT_SERIES", "ZONE_SERIES", "ZONE_VIEWED",
           "PLASTIC_BITS"]


class ZoneColumn(NamedTuple):
    """One time series of ``zones/`` (docs/output.md): per gridpoint (``center`` "Node") or
    per zone ("Cell"), ``width`` values a row, dtype, units, doc, and ``view``: its XDMF
    attribute type in the sidecar ``<run>-zones.xdmf`` (pdem.io.xdmf; the attributes come in
    this table's order), None where it is not an attribute (the gridpoint positions are the
    grid's geometry). A series shown in ParaView is one line here (+ its value in
    :func:`zone_values`)."""

    name: str
    center: str
    width: int
    dtype: type
    units: str
    doc: str
    view: str | None = None


# Time series of the gridpoints and the zones. The positions are the grid's geometry and the
# state a displacement is measured on: float64 (like the rigid blocks' surface/points; float32
# would round a gridpoint 1 km from the origin to 6e-5 m, coarser than an elastic displacement).
# The rest are for the viewer and pdem info, which need no more than float32's 7 digits (the
# exact state is in the checkpoints, pdem.io.checkpoint): the displacement is stored on its own,
# so it keeps its 7 digits however far the grid is from the origin. The stress is a "Matrix" of
# 6 columns, not a "Tensor6": ParaView 5.11's readers disagree on Tensor6 (the Xdmf3 readers
# pass the 6 columns on, the legacy reader expands them to 9 taking them as xx xy xz yy yz zz);
# a 6-column Matrix reaches ParaView as the same 6-component array in all three, which ParaView
# takes as a symmetric tensor XX YY ZZ XY YZ XZ: pdem's order.
ZONE_COLUMNS = (
    ZoneColumn("points", "Node", 3, np.float64, "m", "gridpoint positions, world frame"),
    ZoneColumn("displacement", "Node", 3, np.float32, "m", "points - initial_points",
               view="Vector"),
    ZoneColumn("velocity", "Node", 3, np.float32, "m/s", "gridpoint velocity", view="Vector"),
    ZoneColumn("stress", "Cell", 6, np.float32, "Pa",
               "zone stress xx, yy, zz, xy, yz, zx; tension positive", view="Matrix"),
    ZoneColumn("plastic", "Cell", 1, np.uint8, "1",
               "plastic state bits: 1 shear now, 2 tension now, 4 shear past, 8 tension past",
               view="Scalar"),
    ZoneColumn("mean_stress", "Cell", 1, np.float32, "Pa", "(xx + yy + zz) / 3; tension positive",
               view="Scalar"),
    ZoneColumn("von_mises", "Cell", 1, np.float32, "Pa", "sqrt(3 J2), >= 0", view="Scalar"),
    ZoneColumn("sigma1", "Cell", 1, np.float32, "Pa", "minor principal stress: the most "
               "compressive (smallest, tension positive)", view="Scalar"),
    ZoneColumn("sigma2", "Cell", 1, np.float32, "Pa", "intermediate principal stress",
               view="Scalar"),
    ZoneColumn("sigma3", "Cell", 1, np.float32, "Pa", "major principal stress: the most tensile "
               "(largest)", view="Scalar"),
)
# The fields a scene may choose (output.zones.fields, pdem.config.schema.ZONE_FIELDS: the same
# names); the positions are always written (the grid's geometry, and the deformed surfaces of
# run.xdmf are cut from them).
ZONE_FIELDS = tuple(c.name for c in ZONE_COLUMNS if c.name != "points")
POINT_SERIES = tuple(c for c in ZONE_COLUMNS if c.center == "Node")  # per gridpoint
ZONE_SERIES = tuple(c for c in ZONE_COLUMNS if c.center == "Cell")  # per zone
ZONE_VIEWED = tuple(f"/zones/{c.name}" for c in POINT_SERIES + ZONE_SERIES)


def zone_columns(fields: Sequence[str] | None = None) -> tuple[ZoneColumn, ...]:
    """The columns written: ``points`` and the ``fields`` (None: all of :data:`ZONE_FIELDS`),
    gridpoint columns first, each group in the table's order (``ValueError`` naming an unknown
    field and the valid ones)."""
    if fields is None:
        return POINT_SERIES + ZONE_SERIES
    bad = [f for f in fields if f not in ZONE_FIELDS]
    if bad:
        raise ValueError(f"zone fields {bad}: unknown; valid: {', '.join(ZONE_FIELDS)}")
    chosen = {"points", *fields}
    return tuple(c for c in POINT_SERIES + ZONE_SERIES if c.name in chosen)
# pdem.deformable.constitutive's bits (FLAC3D's convention)
PLASTIC_BITS = ("shear-n", "tension-n", "shear-p", "tension-p")


class ZoneLayout(NamedTuple):
    """Where each zoned block's rows are: blocks by ascending gid; block ``k`` (gid
    ``gid[k]``) has gridpoints ``point_start[k] .. point_start[k+1]-1`` and zones
    ``zone_start[k] .. zone_start[k+1]-1``."""

    gid: np.ndarray
    point_start: np.ndarray
    zone_start: np.ndarray

    @property
    def n_points(self) -> int:
        return int(self.point_start[-1])

    @property
    def n_zones(self) -> int:
        return int(self.zone_start[-1])

    def runs(self, gids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For the blocks ``gids`` (ascending): their first gridpoint, gridpoint count, first
        zone and zone count."""
        k = np.searchsorted(self.gid, gids)
        return (self.point_start[k], self.point_start[k + 1] - self.point_start[k],
                self.zone_start[k], self.zone_start[k + 1] - self.zone_start[k])


def zone_layout(counts: Sequence[np.ndarray]) -> ZoneLayout:
    """The layout from every rank's ``(gid, n_points, n_zones)`` rows (``(k, 3)`` int64 arrays,
    as gathered; any order). ``ValueError`` if a gid comes twice or a count is not positive."""
    rows = np.concatenate([np.asarray(c, np.int64).reshape(-1, 3) for c in counts]) \
        if len(counts) else np.zeros((0, 3), np.int64)
    rows = rows[np.argsort(rows[:, 0], kind="stable")]
    gid = rows[:, 0]
    if len(gid) > 1 and (np.diff(gid) == 0).any():
        dup = int(gid[1:][np.diff(gid) == 0][0])
        raise ValueError(f"zoned block {dup} passed by two ranks (each must pass the ones it owns)")
    if (rows[:, 1:] <= 0).any():
        raise ValueError("a zoned block without gridpoints or zones")
    start = np.zeros((len(rows) + 1, 2), np.int64)
    np.cumsum(rows[:, 1:], axis=0, out=start[1:])
    return ZoneLayout(gid, start[:, 0].copy(), start[:, 1].copy())


def zone_values(body: Any, names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Snapshot values of one zoned block (a :class:`pdem.deformable.body.DeformableBody` or any
    object with ``nodes``, ``nodes0``, ``vel``, ``stress`` and ``plastic``), by series name:
    those in ``names`` (None: every column's).

    Per zone and element-wise (the eigenvalues by one LAPACK call per zone), so a zone's values
    do not depend on which rank computes them or with which other blocks. Full precision: the
    writer rounds to each column's dtype.
    """
    names = set(c.name for c in ZONE_COLUMNS) if names is None else set(names)
    x = np.asarray(body.nodes, np.float64)
    out = {"points": x}
    if "displacement" in names:
        out["displacement"] = x - np.asarray(body.nodes0, np.float64)
    if "velocity" in names:
        out["velocity"] = np.asarray(body.vel, np.float64)
    if "plastic" in names:
        out["plastic"] = np.asarray(body.plastic)
    s = np.asarray(body.stress, np.float64)
    if "stress" in names:
        out["stress"] = s
    xx, yy, zz, xy, yz, zx = (s[:, j] for j in range(6))
    if "mean_stress" in names:
        out["mean_stress"] = (xx + yy + zz) / 3.0
    if "von_mises" in names:
        j2 = ((xx - yy) ** 2 + (yy - zz) ** 2 + (zz - xx) ** 2) / 6.0 + xy * xy + yz * yz \
            + zx * zx
        out["von_mises"] = np.sqrt(3.0 * j2)
    if names & {"sigma1", "sigma2", "sigma3"}:
        full = np.stack([np.stack([xx, xy, zx], -1), np.stack([xy, yy, yz], -1),
                         np.stack([zx, yz, zz], -1)], -2)
        principal = np.linalg.eigvalsh(full) if len(s) else np.zeros((0, 3))  # ascending
        for k in range(3):
            out[f"sigma{k + 1}"] = principal[:, k]
    return {k: v for k, v in out.items() if k == "points" or k in names}
