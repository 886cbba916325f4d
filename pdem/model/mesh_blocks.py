"""Scene ``mesh:`` entries -> blocks: one convex block per 3D cell of a volume mesh, cells
sharing a ``cell_data_group`` value joined into one (concave) block.

The reading and the convexity check are pdem.geometry.mesh_import's; here cells become
BlockSpecs with their names, groups and materials.
"""

from __future__ import annotations

import numpy as np

from ..config import ConfigError
from ..geometry import GeometryError
from ..geometry.mesh_import import read_cell_table, read_mesh
from ..mpi import LOCAL, allgather, on_root, run_together, weighted_share
from .rockmass import components
from .spec import BlockSpec
from .spread import Spread


def _label(value) -> str:
    """A cell data value as a name: integral floats without the ``.0``."""
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


def _missing(where, table, key) -> ConfigError:
    return ConfigError([f"{where}: the mesh has no scalar cell data {key!r} (it has: "
                        f"{', '.join(sorted(table.data)) or 'none'})"])


def mesh_blocks(scene, entry: int, block, comm=None) -> list:
    """This rank's blocks of ``scene.blocks[entry]`` (a ``mesh:`` entry), in cell order (a
    joined block where its first cell is), collective: each rank makes the polyhedra of its
    share of the cells and the blocks whose first cell is in it, asking the other ranks for
    the cells joined to them that it lacks. In rank order the ranks' blocks are the list one
    process makes (``comm`` None: this process makes them all); an error is raised on every
    rank, the same messages in the same order. One rank reads the file and sends the mesh to
    the others; what a rank keeps of every cell is columns
    (pdem.geometry.mesh_import.CellTable), no object a cell."""
    comm = LOCAL if comm is None else comm
    m = block.mesh
    where = scene.at("blocks", entry, "mesh")
    select = None
    if m.select:
        select = {k: (v if isinstance(v, list) else [v]) for k, v in m.select.items()}
    try:
        # one rank reads the file, every rank gets the mesh (a refusal raised on every rank)
        table = read_cell_table(m.file, select=select,
                                read=lambda path: on_root(comm, lambda: read_mesh(path)))
    except GeometryError as exc:
        raise ConfigError([f"{where}: {exc}"]) from None
    if not len(table):
        raise ConfigError([f"{where}: no cell of {m.file} is selected"])
    for key in (m.cell_data_group, m.group_data, m.material_data):
        if key and key not in table.data:
            raise _missing(where, table, key)
    lo, hi = weighted_share(comm.rank, comm.size, np.ones(len(table)))

    def make_polyhedra():
        try:
            return table.polyhedra(lo, hi)
        except GeometryError as exc:
            raise ConfigError([f"{where}: {exc}"]) from None

    # (a bad cell in a share is raised on every rank)
    polys = Spread(comm, run_together(comm, make_polyhedra))
    # the joined blocks: cells of one label of cell_data_group (else each cell alone), a
    # block's cells in mesh order, the blocks by their first cell
    if m.cell_data_group:
        code, keys = table.codes(m.cell_data_group, _label)
        order = np.argsort(code, kind="stable")
        cuts = np.flatnonzero(np.diff(code[order])) + 1
        groups = sorted(np.split(order, cuts), key=lambda members: members[0])
        mine = [(keys[code[g[0]]], g.tolist()) for g in groups if lo <= g[0] < hi]
    else:
        mine = [(str(k), [k]) for k in range(lo, hi)]
    fetched = polys.fetch([k for _, members in mine for k in members if not lo <= k < hi])

    def label(key, k):
        return _label(table.value(key, k))

    def make():
        out, errors = [], []
        for key, members in mine:
            first = members[0]
            index = int(table.index[first])
            group = label(m.group_data, first) if m.group_data else None
            material = label(m.material_data, first) if m.material_data else None
            if material is not None and material not in scene.materials:
                errors.append(f"{where}: cell {index} has {m.material_data} = "
                              f"{material!r}, not a material (defined: "
                              f"{', '.join(sorted(scene.materials))})")
            for k in members[1:]:
                for data, value in ((m.group_data, group), (m.material_data, material)):
                    if data and label(data, k) != value:
                        errors.append(f"{where}: cells {index} and {int(table.index[k])} "
                                      f"join into block {block.name}[{key}] but differ in "
                                      f"{data!r}")
            pieces = [polys.local[k - lo] if lo <= k < hi else fetched[k] for k in members]
            if len(components(pieces)) > 1:
                errors.append(f"{where}: the cells with {m.cell_data_group} = {key} do not "
                              "all touch face to face (a joined block must be one connected "
                              "body)")
            name = f"{block.name}[{key}]"
            out.append(BlockSpec(name, entry, pieces, block, parent=name, group_name=group,
                                 material_name=material))
        return out, errors

    out, errors = run_together(comm, make)
    errors = [e for part in allgather(comm, errors) for e in part]
    if errors:
        raise ConfigError(errors[:10])
    return out
