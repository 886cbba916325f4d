"""``pdem export FILE.h5 --format vtu``: the block surfaces of a pdem output file as one mesh file
per snapshot, for tools that do not read XDMF (written by meshio)."""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np

from ..errors import UserError, writing
from .xdmf import CELL_FIELDS
from .zones import POINT_SERIES, ZONE_SERIES

__all__ = ["FORMATS", "export"]

# meshio formats that write triangles with every cell array under its own name and read them
# back equal (checked with meshio 5.3). Left out: formats that drop cell data (stl, ply, obj,
# off, abaqus, nastran, ...), rename it (tecplot splits vectors into x_0, x_1, x_2; avsucd makes
# the first integer array its "material") or fail on this mesh (exodus needs netCDF4; cgns, h5m,
# su2, ugrid).
FORMATS = {"vtu": ".vtu", "vtk": ".vtk", "xdmf": ".xdmf", "gmsh": ".msh", "med": ".med",
           "hmf": ".hmf"}
# A collection file listing the files with their model times, so ParaView opens them as one time
# series: a .pvd for vtu; ParaView 5.11's .pvd reader refuses legacy .vtk files ("Could not
# determine the data type for the first dataset"), so vtk gets its JSON file-series format.
_COLLECTION = {"vtu": ".pvd", "vtk": ".vtk.series"}
_STATIC = ("block_id", "group", "fixed")  # per-triangle arrays that do not change in time
_SERIES = tuple(name for name, _, _ in CELL_FIELDS)
# the zoned blocks' series (pdem.io.zones), as point and cell arrays of their tetrahedra
_ZONE_POINT = tuple(c.name for c in POINT_SERIES if c.name != "points")
_ZONE_CELL = tuple(c.name for c in ZONE_SERIES)


def export(path: str | os.PathLike, fmt: str, out: str | os.PathLike | None = None,
           every: int = 1) -> list[str]:
    """Write snapshots ``0, every, 2 every, ...`` of the output file ``path`` in format ``fmt``.

    Files are ``<stem>-<i:06d><ext>`` (``i`` = snapshot index in the HDF5 file). ``out`` is a
    directory (existing, or ending with a separator) or a path stem; by default the files go
    beside ``path`` with its stem. Returns the files written, each series followed by the
    collection that ParaView opens as one time series (``<stem>.pvd`` for vtu,
    ``<stem>.vtk.series`` for vtk). A file with zoned blocks gives a second series, their
    tetrahedra, ``<stem>-zones-<i:06d><ext>`` (and ``<stem>-zones.pvd``, ...).
    Raises :class:`UserError` for a missing or non-pdem file, an unknown format, or an output
    without snapshots.
    """
    fmt = fmt.lower()
    if fmt not in FORMATS:
        raise UserError(f"unknown format {fmt!r}; supported: {', '.join(FORMATS)}")
    if every < 1:
        raise UserError(f"--every must be at least 1, not {every}")
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: no such file")
    if not h5py.is_hdf5(path):
        raise UserError(f"{path}: not an HDF5 file")
    import meshio  # here, not at module level: only export needs it

    directory, stem = _target(path, out)
    written = []
    with h5py.File(path, "r") as f:
        times = _check_output(f, path)
        indices = range(0, len(times), every)
        cells = [("triangle", f["surface/connectivity"][()])]
        # format 1 files lack the viewer fields: export what the file has
        static = {k: [f[f"surface/{k}"][()]] for k in _STATIC if f"surface/{k}" in f}
        series = [k for k in _SERIES if f"surface/{k}" in f]

        def surface(i):
            cell_data = dict(static)
            cell_data.update({k: [f[f"surface/{k}"][i]] for k in series})
            return meshio.Mesh(f["surface/points"][i], cells, cell_data=cell_data)
        written += _series(meshio, surface, directory, stem, fmt, indices, times)
        if "zones" in f:  # the zoned blocks' tetrahedra, a series of their own
            z = f["zones"]
            tets = [("tetra", z["connectivity"][()])]
            n = min(len(times), z["points"].shape[0])

            cell_names = [k for k in _ZONE_CELL if k in z]  # output.zones.fields: those chosen
            point_names = [k for k in _ZONE_POINT if k in z]

            def zones(i):
                cell = {k: z[k][i] for k in cell_names}
                if "plastic" in cell:  # meshio's xdmf: no uint8
                    cell["plastic"] = cell["plastic"].astype(np.int32)
                if fmt == "gmsh" and "stress" in cell:  # 1, 3 or 9 components: the full tensor, row by row
                    cell["stress"] = cell["stress"][:, [0, 3, 5, 3, 1, 4, 5, 4, 2]]
                return meshio.Mesh(
                    z["points"][i], tets,
                    point_data={"block_id": z["point_block"][()],
                                **{k: z[k][i] for k in point_names}},
                    cell_data={"block_id": [z["zone_block"][()]],
                               **{k: [v] for k, v in cell.items()}})
            written += _series(meshio, zones, directory, f"{stem}-zones", fmt,
                               [i for i in indices if i < n], times)
    return written


def _series(meshio, mesh_of, directory: Path, stem: str, fmt: str, indices, times) -> list[str]:
    """Snapshots ``indices`` (``mesh_of(i)``) as ``<stem>-<i:06d><ext>``, then their collection
    (vtu, vtk); the files written."""
    written = []
    for i in indices:
        name = directory / f"{stem}-{i:06d}{FORMATS[fmt]}"
        mesh = mesh_of(i)
        with writing(name):
            _write(meshio, name, mesh, fmt)
        written.append(str(name))
    if fmt in _COLLECTION:
        coll = directory / f"{stem}{_COLLECTION[fmt]}"
        # names relative to the collection, so the set of files can be moved together
        entries = [(float(times[i]), Path(w).name) for i, w in zip(indices, written, strict=True)]
        with writing(coll):
            (_write_pvd if fmt == "vtu" else _write_series)(coll, entries)
        written.append(str(coll))
    return written


def _write(meshio, name: Path, mesh, fmt: str) -> None:
    if fmt == "xdmf":
        # inline XML data: each snapshot is one self-contained file (meshio's default writes an
        # .h5 beside every .xdmf). meshio's TimeSeriesWriter is not used: it stores the points
        # once, and the blocks move.
        meshio.xdmf.write(name, mesh, data_format="XML")
    elif fmt == "vtk":
        # legacy VTK 4.2: meshio's default 5.1 names integer arrays "vtktypeint32", which
        # ParaView 5.11 does not read ("Unsupported data type"), and older tools know only 4.2
        meshio.write(name, mesh, file_format="vtk42")
    else:
        meshio.write(name, mesh, file_format=fmt)


def _target(path: Path, out) -> tuple[Path, str]:
    """Directory and file stem of the exported files, the directory created if missing."""
    if out is None:
        return path.parent, path.stem
    out_s = os.fspath(out)
    if os.path.isdir(out_s) or out_s.endswith(("/", os.sep)):
        directory, stem = Path(out_s), path.stem
    else:
        directory, stem = Path(out_s).parent, Path(out_s).name
    with writing(directory):
        directory.mkdir(parents=True, exist_ok=True)
    return directory, stem


def _check_output(f: h5py.File, path: Path) -> np.ndarray:
    """The snapshot times of a pdem output file with surfaces, or a UserError saying why not."""
    kind = f.attrs.get("pdem_format")
    if isinstance(kind, bytes):
        kind = kind.decode()
    if kind != "output":
        what = "no 'pdem_format' attribute" if kind is None else f"a pdem {kind} file"
        raise UserError(f"{path}: not a pdem output file ({what})")
    for key in ("time", "surface/points", "surface/connectivity"):
        if key not in f:
            raise UserError(f"{path}: not a complete pdem output file (no {key})")
    # a killed run may have flushed one series a snapshot further than another
    n = min(len(f["time"]), f["surface/points"].shape[0])
    if n == 0:
        raise UserError(f"{path}: the output has no snapshots")
    return f["time"][:n]


def _write_pvd(pvd: Path, entries: list[tuple[float, str]]) -> None:
    """ParaView's XML collection of (time, file name)."""
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    coll = ET.SubElement(root, "Collection")
    for t, name in entries:
        ET.SubElement(coll, "DataSet", timestep=repr(t), group="", part="0", file=name)
    ET.indent(root)
    ET.ElementTree(root).write(pvd, encoding="utf-8", xml_declaration=True)


def _write_series(path: Path, entries: list[tuple[float, str]]) -> None:
    """ParaView's JSON file series (``<file>.series``) of (time, file name)."""
    files = [{"name": name, "time": t} for t, name in entries]
    path.write_text(json.dumps({"file-series-version": "1.0", "files": files}, indent=1) + "\n")
