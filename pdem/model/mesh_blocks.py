"""Scene ``mesh:`` entries -> blocks: one convex block per 3D cell of a volume mesh, cells
sharing a ``cell_data_group`` value joined into one (concave) block.

The reading and the convexity check are pdem.geometry.mesh_import's; here cells become
BlockSpecs with their names, groups and materials.
"""

from __future__ import annotations

from ..config import ConfigError
from ..geometry import GeometryError
from ..geometry.mesh_import import read_mesh_cells
from ..parallel.mpi import LOCAL, allgather, run_together, weighted_share
from .rockmass import components


def _label(value) -> str:
    """A cell data value as a name: integral floats without the ``.0``."""
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


def _value(scene, where, cell, key):
    if key not in cell.data:
        raise ConfigError([f"{where}: the mesh has no scalar cell data {key!r} (it has: "
                           f"{', '.join(sorted(cell.data)) or 'none'})"])
    return _label(cell.data[key])


def mesh_blocks(scene, entry: int, block, comm=None) -> list:
    """This rank's blocks of ``scene.blocks[entry]`` (a ``mesh:`` entry), in cell order (a
    joined block where its first cell is), collective: each rank makes the polyhedra of its
    share of the cells and the blocks whose first cell is in it, asking the other ranks for
    the cells joined to them that it lacks. In rank order the ranks' blocks are the list one
    process makes (``comm`` None: this process makes them all); an error is raised on every
    rank, the same messages in the same order."""
    from .build import BlockSpec
    from .spread import Spread

    comm = LOCAL if comm is None else comm
    m = block.mesh
    where = scene.at("blocks", entry, "mesh")
    select = None
    if m.select:
        select = {k: (v if isinstance(v, list) else [v]) for k, v in m.select.items()}
    share = [0, 0]

    def own_share(weights, work):
        """The polyhedra of this rank's share of the cells, None for the others' cells."""
        lo, hi = share[:] = weighted_share(comm.rank, comm.size, weights)
        mine = run_together(comm, lambda: work(lo, hi))
        return [None] * lo + list(mine) + [None] * (len(weights) - hi)

    try:
        # (every rank reads the same file alike; a bad cell in a share is raised on every
        # rank by own_share)
        cells = read_mesh_cells(m.file, select=select, share_work=own_share)
    except GeometryError as exc:
        raise ConfigError([f"{where}: {exc}"]) from None
    if not cells:
        raise ConfigError([f"{where}: no cell of {m.file} is selected"])
    groups: dict[str, list] = {}
    for k, cell in enumerate(cells):
        key = _value(scene, where, cell, m.cell_data_group) if m.cell_data_group else str(k)
        groups.setdefault(key, []).append(k)
    # the cells' polyhedra spread as the shares made them; this rank's groups (their first
    # cell in its share) fetch the others
    lo, hi = share
    polys = Spread(comm, [c.poly for c in cells[lo:hi]])
    mine = {key: members for key, members in groups.items() if lo <= members[0] < hi}
    fetched = polys.fetch([k for members in mine.values() for k in members
                           if not lo <= k < hi])

    def make():
        out, errors = [], []
        for key, members in mine.items():
            first = cells[members[0]]
            group = _value(scene, where, first, m.group_data) if m.group_data else None
            material = _value(scene, where, first, m.material_data) if m.material_data \
                else None
            if material is not None and material not in scene.materials:
                errors.append(f"{where}: cell {first.index} has {m.material_data} = "
                              f"{material!r}, not a material (defined: "
                              f"{', '.join(sorted(scene.materials))})")
            for k in members[1:]:
                cell = cells[k]
                for data, value in ((m.group_data, group), (m.material_data, material)):
                    if data and _value(scene, where, cell, data) != value:
                        errors.append(f"{where}: cells {first.index} and {cell.index} join "
                                      f"into block {block.name}[{key}] but differ in "
                                      f"{data!r}")
            pieces = [cells[k].poly if lo <= k < hi else fetched[k] for k in members]
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
