"""Scene ``mesh:`` entries -> blocks: one convex block per 3D cell of a volume mesh, cells
sharing a ``cell_data_group`` value joined into one (concave) block.

The reading and the convexity check are pdem.geometry.mesh_import's; here cells become
BlockSpecs with their names, groups and materials.
"""

from __future__ import annotations

from ..config import ConfigError
from ..geometry import GeometryError
from ..geometry.mesh_import import read_mesh_cells
from ..parallel.mpi import shared_work
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
    """The blocks of ``scene.blocks[entry]`` (a ``mesh:`` entry), in cell order (a joined
    block where its first cell is). ``comm``: the ranks share making the cells' polyhedra
    and each gets them all (collective, pdem.parallel.mpi.shared_work)."""
    from .build import BlockSpec

    m = block.mesh
    where = scene.at("blocks", entry, "mesh")
    select = None
    if m.select:
        select = {k: (v if isinstance(v, list) else [v]) for k, v in m.select.items()}
    try:
        cells = read_mesh_cells(m.file, select=select,
                                share_work=lambda w, work: shared_work(comm, w, work))
    except GeometryError as exc:
        raise ConfigError([f"{where}: {exc}"]) from None
    if not cells:
        raise ConfigError([f"{where}: no cell of {m.file} is selected"])
    groups: dict[str, list] = {}
    for k, cell in enumerate(cells):
        key = _value(scene, where, cell, m.cell_data_group) if m.cell_data_group else str(k)
        groups.setdefault(key, []).append(cell)
    out, errors = [], []
    for key, members in groups.items():
        first = members[0]
        group = _value(scene, where, first, m.group_data) if m.group_data else None
        material = _value(scene, where, first, m.material_data) if m.material_data else None
        if material is not None and material not in scene.materials:
            errors.append(f"{where}: cell {first.index} has {m.material_data} = {material!r}, "
                          f"not a material (defined: {', '.join(sorted(scene.materials))})")
        for cell in members[1:]:
            for data, mine in ((m.group_data, group), (m.material_data, material)):
                if data and _value(scene, where, cell, data) != mine:
                    errors.append(f"{where}: cells {first.index} and {cell.index} join into "
                                  f"block {block.name}[{key}] but differ in {data!r}")
        pieces = [c.poly for c in members]
        if len(components(pieces)) > 1:
            errors.append(f"{where}: the cells with {m.cell_data_group} = {key} do not all touch "
                          "face to face (a joined block must be one connected body)")
        name = f"{block.name}[{key}]"
        out.append(BlockSpec(name, entry, pieces, block, parent=name, group_name=group,
                             material_name=material))
    if errors:
        raise ConfigError(errors[:10])
    return out
