"""XDMF sidecar for the HDF5 output: temporal collections every ParaView XDMF reader opens."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..model.fields import BLOCK
from .joints import CONTACT_SERIES, SUB_SERIES, viewer_attributes, xdmf_number
from .zones import ZONE_COLUMNS

__all__ = ["write_xdmf", "read_xdmf", "centroids_path", "contacts_path", "subcontacts_path",
           "zones_path", "CELL_FIELDS", "VIEWED_SERIES", "CONTACT_VIEWED", "SUB_VIEWED",
           "view_path"]

# Block quantities copied onto every triangle of the block's surface, as float32 series
# ``surface/<name>`` (name, components, units). No XDMF construct that ParaView 5.11's readers
# all accept can index a per-block array by triangle (docs/output.md), hence the copies.
CELL_FIELDS = (
    ("displacement", 3, "m"),
    ("displacement_magnitude", 1, "m"),
    ("velocity", 3, "m/s"),
    ("speed", 1, "m/s"),
    ("angular_velocity", 3, "rad/s"),
    ("removed", 1, "1"),  # 0 in the model, 1 frozen, 2 deleted (domain, excavation)
    ("stage_displacement", 3, "m"),  # since the current stage began (stages:)
)
# point attributes of the centroid cloud: the block fields declared ``view`` (name, width)
_BLOCK_SERIES = tuple((f.output, f.width) for f in BLOCK if f.view)

# Time series the sidecar reads one snapshot of, through a virtual dataset per snapshot.
VIEWED_SERIES = (
    "/surface/points",
    *(f"/surface/{name}" for name, _, _ in CELL_FIELDS),
    "/blocks/centroid",
    *(f"/blocks/{name}" for name, _ in _BLOCK_SERIES),
)

# Point attributes of the contact and sub-contact grids (name, components, number type,
# precision), from the series' declarations (pdem.io.joints: the columns with a ``view``):
# each snapshot's rows of the flat contacts/<name>, subcontacts/<name>, read through views
# like the series above. ``point`` is the grids' geometry.
_CONTACT_ATTRS = viewer_attributes(CONTACT_SERIES)
_SUB_ATTRS = viewer_attributes(SUB_SERIES)
# Attributes of the zoned blocks' tetrahedral grid: (name, center, attribute type, components,
# number type, precision), from the zone series' declarations (pdem.io.zones.ZONE_COLUMNS: the
# columns with a ``view``, in their order), each snapshot's zones/<name> read through a view.
_ZONE_ATTRS = tuple((c.name, c.center, c.view, c.width, *xdmf_number(c.dtype))
                    for c in ZONE_COLUMNS if c.view is not None)
CONTACT_VIEWED = ("point", *(a[0] for a in _CONTACT_ATTRS))
SUB_VIEWED = ("point", *(a[0] for a in _SUB_ATTRS))


def view_path(path: str, i: int) -> str:
    """Path of the virtual dataset holding snapshot ``i`` of the series ``path``."""
    return f"/xdmf/{i:06d}{path}"


def _hdf(dims: Sequence[int], number_type: str, h5_name: str, dset: str, precision: int = 8) -> str:
    d = " ".join(str(int(x)) for x in dims)
    return (
        f'<DataItem Dimensions="{d}" NumberType="{number_type}" Precision="{precision}" '
        f'Format="HDF">{h5_name}:{dset}</DataItem>'
    )


def _attribute(name: str, center: str, width: int, item: str) -> str:
    kind = "Vector" if width == 3 else "Scalar"
    return f'<Attribute Name="{name}" AttributeType="{kind}" Center="{center}">{item}</Attribute>'


def _surface_grid(i: int, t: float, h5: str, n_tri: int, n_points: int,
                  extra=()) -> list[str]:
    static = [
        _attribute(name, "Cell", 1, _hdf((n_tri,), "Int", h5, f"/surface/{name}", prec))
        for name, prec in (("block_id", 8), ("group", 4), ("fixed", 4))
    ] + [_attribute(name, "Cell", 1, _hdf((n_tri,), "Float", h5, path, 4))
         for name, path in extra]
    cells = [
        _attribute(
            name, "Cell", w,
            _hdf((n_tri, w) if w > 1 else (n_tri,), "Float", h5, view_path(f"/surface/{name}", i), 4),
        )
        for name, w, _ in CELL_FIELDS
    ]
    return [
        f'<Grid Name="surface_{i:06d}" GridType="Uniform">',
        f'<Time Value="{t!r}"/>',
        f'<Topology TopologyType="Triangle" NumberOfElements="{n_tri}">'
        f'{_hdf((n_tri, 3), "Int", h5, "/surface/connectivity")}</Topology>',
        f'<Geometry GeometryType="XYZ">'
        f'{_hdf((n_points, 3), "Float", h5, view_path("/surface/points", i))}</Geometry>',
        *static,
        *cells,
        "</Grid>",
    ]


def _blocks_grid(i: int, t: float, h5: str, n_blocks: int) -> list[str]:
    gid = _hdf((n_blocks,), "Int", h5, "/blocks/gid")
    static = [
        _attribute(name, "Node", 1, _hdf((n_blocks,), "Int", h5, f"/blocks/{name}", 4))
        for name in ("group", "fixed")
    ]
    series = [
        _attribute(name, "Node", width,
                   _hdf((n_blocks, width) if width > 1 else (n_blocks,), "Float", h5,
                        view_path(f"/blocks/{name}", i)))
        for name, width in _BLOCK_SERIES
    ]
    return [
        f'<Grid Name="blocks_{i:06d}" GridType="Uniform">',
        f'<Time Value="{t!r}"/>',
        f'<Topology TopologyType="Polyvertex" NumberOfElements="{n_blocks}" '
        f'NodesPerElement="1">{gid}</Topology>',
        f'<Geometry GeometryType="XYZ">'
        f'{_hdf((n_blocks, 3), "Float", h5, view_path("/blocks/centroid", i))}</Geometry>',
        _attribute("gid", "Node", 1, gid),
        *static,
        *series,
        "</Grid>",
    ]


def _point_grid(group: str, attrs, i: int, t: float, h5: str, n: int) -> list[str]:
    """Snapshot ``i`` of the contacts (or sub-contacts) as a Polyvertex cloud of ``n`` points."""
    if n == 0:
        # No contact in this snapshot: a grid of no points. The Xdmf3 readers read this form
        # (empty DataItems crash them); the legacy reader crashes on every empty grid tried
        # (docs/output.md).
        return [
            f'<Grid Name="{group}_{i:06d}" GridType="Uniform">',
            f'<Time Value="{t!r}"/>',
            '<Topology TopologyType="Polyvertex" NumberOfElements="0" NodesPerElement="1"/>',
            "</Grid>",
        ]
    else:
        topo = _hdf((n,), "Int", h5, view_path(f"/{group}/index", i))
        geom = _hdf((n, 3), "Float", h5, view_path(f"/{group}/point", i))
        values = [_hdf((n, w) if w > 1 else (n,), kind, h5, view_path(f"/{group}/{name}", i),
                       prec) for name, w, kind, prec in attrs]
    return [
        f'<Grid Name="{group}_{i:06d}" GridType="Uniform">',
        f'<Time Value="{t!r}"/>',
        f'<Topology TopologyType="Polyvertex" NumberOfElements="{n}" '
        f'NodesPerElement="1">{topo}</Topology>',
        f'<Geometry GeometryType="XYZ">{geom}</Geometry>',
        *(_attribute(a[0], "Node", a[1], v) for a, v in zip(attrs, values, strict=True)),
        "</Grid>",
    ]


def _zones_grid(i: int, t: float, h5: str, n_points: int, n_zones: int,
                names: Sequence[str] | None = None) -> list[str]:
    """Snapshot ``i`` of the zoned blocks: one tetrahedral grid of all their zones, with the
    attributes of the series ``names`` (None: all)."""
    static = [f'<Attribute Name="block_id" AttributeType="Scalar" Center="{center}">'
              f'{_hdf((n,), "Int", h5, f"/zones/{path}")}</Attribute>'
              for center, n, path in (("Node", n_points, "point_block"),
                                      ("Cell", n_zones, "zone_block"))]
    # ParaView takes a point and a cell array of one name as two arrays; the cells' gid is the
    # one a Threshold on a block wants, the points' is there for point filters (Glyph)
    values = []
    for name, center, kind, w, number, prec in _ZONE_ATTRS:
        if names is not None and name not in names:
            continue
        n = n_points if center == "Node" else n_zones
        item = _hdf((n, w) if w > 1 else (n,), number, h5, view_path(f"/zones/{name}", i), prec)
        values.append(f'<Attribute Name="{name}" AttributeType="{kind}" Center="{center}">'
                      f'{item}</Attribute>')
    return [
        f'<Grid Name="zones_{i:06d}" GridType="Uniform">',
        f'<Time Value="{t!r}"/>',
        f'<Topology TopologyType="Tetrahedron" NumberOfElements="{n_zones}">'
        f'{_hdf((n_zones, 4), "Int", h5, "/zones/connectivity")}</Topology>',
        f'<Geometry GeometryType="XYZ">'
        f'{_hdf((n_points, 3), "Float", h5, view_path("/zones/points", i))}</Geometry>',
        *static,
        *values,
        "</Grid>",
    ]


def zones_path(xdmf_path: str | os.PathLike) -> Path:
    """The zoned blocks' sidecar: ``run.xdmf`` -> ``run-zones.xdmf``."""
    xdmf_path = Path(xdmf_path)
    return xdmf_path.with_name(xdmf_path.stem + "-zones.xdmf")


def contacts_path(xdmf_path: str | os.PathLike) -> Path:
    """The contacts' sidecar: ``run.xdmf`` -> ``run-contacts.xdmf``."""
    xdmf_path = Path(xdmf_path)
    return xdmf_path.with_name(xdmf_path.stem + "-contacts.xdmf")


def subcontacts_path(xdmf_path: str | os.PathLike) -> Path:
    """The sub-contacts' sidecar: ``run.xdmf`` -> ``run-subcontacts.xdmf``."""
    xdmf_path = Path(xdmf_path)
    return xdmf_path.with_name(xdmf_path.stem + "-subcontacts.xdmf")


def centroids_path(xdmf_path: str | os.PathLike) -> Path:
    """The second sidecar, of the centroid cloud: ``run.xdmf`` -> ``run-centroids.xdmf``."""
    xdmf_path = Path(xdmf_path)
    return xdmf_path.with_name(xdmf_path.stem + "-centroids.xdmf")


def write_xdmf(
    h5_path: str | os.PathLike,
    xdmf_path: str | os.PathLike,
    n_snap: int,
    times: Sequence[float],
    n_tri: int,
    n_points: int,
    n_blocks: int,
    contacts: tuple[Sequence[int], Sequence[int]] | None = None,
    extra_cells: Sequence[tuple[str, str]] = (),
    zones: tuple[int, int] | tuple[int, int, Sequence[str]] | None = None,
) -> None:
    """Write the XDMF 3 description of a pdem output file (plain text, any one process).

    ``xdmf_path`` gets the temporal collection ``surface`` (the triangulated block surfaces, with
    the cell attributes ``block_id``, ``group``, ``fixed`` and the :data:`CELL_FIELDS`);
    :func:`centroids_path` gets ``blocks`` (the block centroids as a Polyvertex cloud with
    ``gid``, ``group``, ``fixed``, ``velocity`` and ``angular_velocity``). One collection per
    file: ParaView's Xdmf3 Reader S joins the top-level grids of a file into one multi-piece
    mesh, which then cannot be coloured by arrays only the surfaces have. Each snapshot reads its
    data from the plain (virtual) datasets ``/xdmf/<i>/...`` the writer makes, the one form the
    Xdmf3 readers (S, T) and the legacy XDMF reader all read. The HDF5 file is referenced by its
    bare name, so the files must stay in the same directory. Each file is written to a
    temporary name and renamed, so a reader never sees half a file.

    ``contacts``: the number of contacts and of sub-contacts of each snapshot, for files with
    the joint state; :func:`contacts_path` then gets ``contacts`` (the contacts at their
    common-plane points, with ``normal_force``, ``shear_force``, ``normal``, ``state``, ...)
    and :func:`subcontacts_path` ``subcontacts`` (sub-contact points and their forces).

    ``zones``: ``(n_points, n_zones[, names])`` of the zoned blocks' grid, for files with zoned
    blocks: :func:`zones_path` then gets ``zones``, their tetrahedra (``Tetrahedron`` topology)
    with the point and cell arrays ``block_id`` and those of the series ``names`` the file has
    (default all: the point arrays ``displacement``, ``velocity`` and the cell arrays ``stress``
    (6 components), ``plastic``, ``mean_stress``, ``von_mises``, ``sigma1`` .. ``sigma3``,
    :mod:`pdem.io.zones`). The zoned blocks' deformed surfaces are part of ``surface``.
    """
    times = [float(t) for t in times]
    if len(times) != n_snap:
        raise ValueError(f"write_xdmf: {len(times)} times for {n_snap} snapshots")
    h5 = Path(h5_path).name
    # ``extra_cells``: (name, dataset) static per-triangle float32 results, e.g. a safety map
    surface = [line for i, t in enumerate(times)
               for line in _surface_grid(i, t, h5, n_tri, n_points, extra_cells)]
    cloud = [line for i, t in enumerate(times) for line in _blocks_grid(i, t, h5, n_blocks)]
    _write_collection(Path(xdmf_path), "surface", surface)
    _write_collection(centroids_path(xdmf_path), "blocks", cloud)
    if contacts is not None:
        for group, attrs, counts, path in (
                ("contacts", _CONTACT_ATTRS, contacts[0], contacts_path(xdmf_path)),
                ("subcontacts", _SUB_ATTRS, contacts[1], subcontacts_path(xdmf_path))):
            grids = [line for i, t in enumerate(times)
                     for line in _point_grid(group, attrs, i, t, h5, int(counts[i]))]
            _write_collection(path, group, grids)
    if zones is not None:
        names = zones[2] if len(zones) > 2 else None
        grids = [line for i, t in enumerate(times)
                 for line in _zones_grid(i, t, h5, int(zones[0]), int(zones[1]), names)]
        _write_collection(zones_path(xdmf_path), "zones", grids)


def _write_collection(path: Path, name: str, grids: list[str]) -> None:
    out = [
        '<?xml version="1.0" encoding="utf-8"?>',
        '<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">',
        "<Domain>",
        f'<Grid Name="{name}" GridType="Collection" CollectionType="Temporal">',
        *grids,
        "</Grid>",
        "</Domain>",
        "</Xdmf>",
        "",
    ]
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("\n".join(out), encoding="utf-8")
    os.replace(tmp, path)


def _dims(item: ET.Element) -> tuple[int, ...]:
    return tuple(int(d) for d in item.get("Dimensions", "").split())


def _resolve(item: ET.Element, base: Path, files: dict) -> np.ndarray:
    """Value of one DataItem (XML, HDF or HyperSlab), checked against its Dimensions."""
    dims = _dims(item)
    if item.get("ItemType") == "HyperSlab":
        sel_item, data_item = list(item)
        sel = _resolve(sel_item, base, files).astype(np.int64)
        data = _resolve(data_item, base, files)
        if sel.shape != (3, data.ndim):
            raise ValueError(f"HyperSlab selection of shape {sel.shape} for a {data.ndim}-d item")
        start, stride, count = sel
        idx = tuple(
            slice(s, s + st * c, st) for s, st, c in zip(start, stride, count, strict=True)
        )
        value = data[idx]
        if value.shape != tuple(count):
            raise ValueError(f"HyperSlab {sel.tolist()} out of range of shape {data.shape}")
    elif item.get("Format") == "HDF":
        fname, _, dset = (item.text or "").strip().partition(":")
        import h5py

        fpath = base / fname
        if fpath not in files:
            files[fpath] = h5py.File(fpath, "r")
        if dset not in files[fpath]:
            raise ValueError(f"{fname}: no dataset {dset}")
        value = files[fpath][dset][()]
    elif item.get("Format", "XML") == "XML":
        value = np.array((item.text or "").split(), dtype=np.float64)
        value = value.reshape(dims) if dims else value
    else:
        raise ValueError(f"unsupported DataItem format {item.get('Format')!r}")
    if dims and value.shape != dims:
        raise ValueError(f"DataItem declares {dims}, holds {value.shape}: {item.text!r}")
    return value


def read_xdmf(xdmf_path: str | os.PathLike) -> dict[str, list[dict]]:
    """Read back an XDMF file written by :func:`write_xdmf` (format 2 views or format 1 HyperSlabs).

    Meant for tests and checks: every DataItem is resolved against the HDF5 file and its
    declared Dimensions verified (``ValueError`` otherwise). Returns, per temporal collection,
    one dict per step: ``time``, ``topology_type``, ``topology``, ``geometry`` (n, 3) and
    ``attributes`` (name -> (center, array)).
    """
    xdmf_path = Path(xdmf_path)
    root = ET.parse(xdmf_path).getroot()
    base = xdmf_path.parent
    files: dict = {}
    result: dict[str, list[dict]] = {}
    try:
        for coll in root.find("Domain").findall("Grid"):
            if coll.get("GridType") != "Collection" or coll.get("CollectionType") != "Temporal":
                raise ValueError(f"grid {coll.get('Name')!r} is not a temporal collection")
            steps = []
            for grid in coll.findall("Grid"):
                topo = grid.find("Topology")
                n_el = int(topo.get("NumberOfElements"))
                if n_el == 0 and topo.find("DataItem") is None:  # an empty contact grid
                    steps.append({"time": float(grid.find("Time").get("Value")),
                                  "topology_type": topo.get("TopologyType"),
                                  "topology": np.zeros((0, 1), np.int64),
                                  "geometry": np.zeros((0, 3)), "attributes": {}})
                    continue
                conn = _resolve(topo.find("DataItem"), base, files).astype(np.int64)
                geom = _resolve(grid.find("Geometry").find("DataItem"), base, files)
                geom = geom.reshape(-1, 3)
                if conn.reshape(n_el, -1).shape[0] != n_el:
                    raise ValueError("topology size does not match NumberOfElements")
                if conn.size and (conn.min() < 0 or conn.max() >= len(geom)):
                    raise ValueError("topology refers to points that do not exist")
                attrs = {}
                for a in grid.findall("Attribute"):
                    val = _resolve(a.find("DataItem"), base, files)
                    n = n_el if a.get("Center") == "Cell" else len(geom)
                    val = val.reshape(n, -1) if a.get("AttributeType") == "Vector" else val
                    if val.reshape(n, -1).shape[0] != n:
                        raise ValueError(f"attribute {a.get('Name')!r} has the wrong length")
                    attrs[a.get("Name")] = (a.get("Center"), val)
                steps.append(
                    {
                        "time": float(grid.find("Time").get("Value")),
                        "topology_type": topo.get("TopologyType"),
                        "topology": conn.reshape(n_el, -1),
                        "geometry": geom,
                        "attributes": attrs,
                    }
                )
            result[coll.get("Name")] = steps
    finally:
        for f in files.values():
            f.close()
    return result
