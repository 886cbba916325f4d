"""Reinforcement in the output (docs/reinforcement.md, docs/output.md): each snapshot's cables
and bolts under ``reinforcement/<i>/`` of the run's HDF5 file, and the sidecar
``<run>-reinforcement.xdmf`` that shows them in ParaView as polylines (one line cell a
segment) coloured by their axial force.

Per snapshot ``i`` (every rank holds the elements alike; the writing ranks write the same
values): ``points`` (N, 3) node positions, ``slip`` (N,) the grout's plastic slip (m),
``segments`` (S, 2) node rows, ``axial`` (S,) force (N, tension positive), ``shear`` (S,) a
rock bolt's dowel force at a joint crossing (N), ``state`` (S,) bits (1: yielded in tension
or compression, 2: grout slipping at a node of it, 4: broken, 8: a dowel at its strength),
``element`` (S,) the element (line) of each segment, whose entry names are the group's
``entries`` attribute (an element's row in it).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

# segment state bits
YIELDED, SLIPPING, BROKEN, DOWEL_YIELDED = 1, 2, 4, 8

_FIELDS = (("axial", "Cell", "N"), ("shear", "Cell", "N"), ("state", "Cell", "1"),
           ("element", "Cell", "1"), ("slip", "Node", "m"))


def elements_path(h5_path: str | os.PathLike) -> Path:
    p = Path(h5_path)
    return p.with_name(p.stem + "-reinforcement.xdmf")


def write_snapshot_elements(f, i: int, data: dict[str, np.ndarray], entries: list[str]) -> None:
    """Snapshot ``i``'s elements into the open file ``f`` (collective on a parallel file:
    every writing rank passes the same ``data``)."""
    g = f.require_group("reinforcement")
    g.attrs["entries"] = ",".join(entries)
    s = g.create_group(f"{i:06d}")
    for k, v in data.items():
        s.create_dataset(k, data=v)


def write_elements_xdmf(h5_path: str | os.PathLike, snaps: list[tuple[int, float, int, int]]) -> None:
    """The XDMF of the snapshots that hold elements: ``(i, time, nodes, segments)`` each."""
    h5 = Path(h5_path).name
    out = ['<?xml version="1.0" ?>', '<Xdmf Version="3.0">', "<Domain>",
           '<Grid Name="reinforcement" GridType="Collection" CollectionType="Temporal">']
    for i, t, n, m in snaps:
        at = f"{h5}:/reinforcement/{i:06d}"
        out += [f'<Grid Name="r{i}" GridType="Uniform">', f'<Time Value="{t!r}"/>',
                f'<Topology TopologyType="Polyline" NodesPerElement="2" NumberOfElements="{m}">',
                f'<DataItem Dimensions="{m} 2" NumberType="Int" Precision="8" Format="HDF">'
                f"{at}/segments</DataItem></Topology>",
                '<Geometry GeometryType="XYZ">',
                f'<DataItem Dimensions="{n} 3" NumberType="Float" Precision="8" Format="HDF">'
                f"{at}/points</DataItem></Geometry>"]
        for name, centre, _ in _FIELDS:
            size = m if centre == "Cell" else n
            kind = "Float" if name in ("axial", "shear", "slip") else "Int"
            out += [f'<Attribute Name="{name}" AttributeType="Scalar" Center="{centre}">',
                    f'<DataItem Dimensions="{size}" NumberType="{kind}" Precision="8" '
                    f'Format="HDF">{at}/{name}</DataItem></Attribute>']
        out.append("</Grid>")
    out += ["</Grid>", "</Domain>", "</Xdmf>"]
    path = elements_path(h5_path)
    tmp = path.with_suffix(".xdmf.tmp")
    tmp.write_text("\n".join(out) + "\n")
    os.replace(tmp, path)
