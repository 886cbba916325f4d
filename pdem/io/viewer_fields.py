"""The viewer fields of the run output: static ``blocks/{group, fixed, initial_centroid}``,
``surface/{group, fixed}``, the per-triangle series ``surface/<CELL_FIELDS>`` and each
snapshot's ``/xdmf`` views of the block series (:mod:`pdem.io.xdmf`)."""

from __future__ import annotations

import numpy as np

from .block_series import BlockSeries, cols
from .h5core import CHUNK_ROWS, H5Core, add_view
from .xdmf import CELL_FIELDS, VIEWED_SERIES

__all__ = ["ViewerFields", "block_fields"]


def block_fields(centroid, x0, velocity, omega, removed, stage_origin) -> dict[str, np.ndarray]:
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


class ViewerFields:
    """The block quantities ParaView shows on the surfaces, of this rank's gid range.

    ``initial_centroid``, ``group``, ``group_names``, ``fixed``, ``ranged``: as
    :class:`pdem.io.writer.OutputWriter`'s arguments (``ValueError`` if bad).
    """

    def __init__(self, core: H5Core, blocks: BlockSeries, initial_centroid, group,
                 group_names, fixed, ranged: bool) -> None:
        """Check the static per-block data of the viewer fields: every block's, or with
        ``ranged`` this rank's gid range's only (``[lo, hi)``, writer_range)."""
        self.core, self.blocks = core, blocks
        lo, hi = core.lo, core.hi
        n = hi - lo if ranged else blocks.n_blocks
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
        # written (create), the initial centroids for the displacements (None: the first
        # snapshot's); every rank keeping every block's would be 32 bytes a block
        rows = slice(None) if ranged else slice(lo, hi)
        self.group_names = names
        self.group, self.fixed = group[rows].astype(np.int32), fixed[rows].astype(np.int32)
        self.x0: np.ndarray | None = None if x0 is None else x0[rows].copy()

    def create(self) -> None:
        """Static per-block and per-triangle data, and the per-triangle series (IO ranks)."""
        core, f = self.core, self.core.f
        n, nt = self.blocks.n_blocks, self.blocks.n_tri
        grp = f["blocks"].create_dataset("group", (n,), np.int32)
        grp.attrs["names"] = self.group_names
        core.write_range(grp, self.group)
        core.write_range(f["blocks"].create_dataset("fixed", (n,), np.int32), self.fixed)
        x0 = f["blocks"].create_dataset("initial_centroid", (n, 3), np.float64)
        x0.attrs["units"] = "m"
        if self.x0 is not None:
            core.write_range(x0, self.x0)
        for name, values in (("group", self.group), ("fixed", self.fixed)):
            self.blocks.write_triangles(f["surface"].create_dataset(name, (nt,), np.int32),
                                        values, core.lo)
        self.group = self.fixed = None  # written
        for name, width, units in CELL_FIELDS:
            tail = (nt, width) if width > 1 else (nt,)
            chunk = (1, min(max(nt, 1), CHUNK_ROWS), *tail[1:])
            # A block's value repeats on each of its triangles: deflate takes most of that back
            # (parallel HDF5 writes filtered datasets collectively, as all writes here are).
            d = f.create_dataset(
                f"surface/{name}", (0, *tail), maxshape=(None, *tail), chunks=chunk, dtype=np.float32,
                compression="gzip", compression_opts=4, shuffle=True,
            )
            d.attrs["units"] = units

    def fill_origin(self, mine: np.ndarray) -> None:
        """Rows written without a stage origin (NaN): the initial centroids (the first
        snapshot's when none were given), as without stages."""
        origin = cols(mine, "stage_origin")
        unset = np.isnan(origin[:, 0])
        origin[unset] = (self.x0 if self.x0 is not None else cols(mine, "centroid"))[unset]

    def write(self, i: int, mine: np.ndarray) -> None:
        """Snapshot ``i`` of the per-triangle series, and its ``/xdmf`` views (collective)."""
        core, f, blocks = self.core, self.core.f, self.blocks
        if self.x0 is None:  # first snapshot: fix the displacement reference
            self.x0 = cols(mine, "centroid").copy()
            core.write(f["blocks/initial_centroid"], (core.lo, 0), self.x0)
        values = block_fields(cols(mine, "centroid"), self.x0, cols(mine, "velocity"),
                              cols(mine, "angular_velocity"), cols(mine, "removed")[:, 0],
                              cols(mine, "stage_origin"))
        for name, _, _ in CELL_FIELDS:  # each field's values dropped once written
            d = f[f"surface/{name}"]
            d.resize(i + 1, axis=0)
            # stored as float32: each block's value converted once, then repeated on its
            # triangles (the same bits as converting every triangle's; no float64 copy of the
            # triangles' values, 24 bytes a triangle for a vector)
            per_block = np.asarray(values.pop(name), np.float32)
            core.write_row(d, i, per_block[blocks.my_tblock], blocks.tlo)
            del per_block
        for path in VIEWED_SERIES:
            add_view(f, path, i)
