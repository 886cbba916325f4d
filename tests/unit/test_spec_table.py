"""After set-up the specs are columns (pdem.model.build.SpecTable): each view reads as the
released spec it came from, and a run keeps no shapes in them."""

from __future__ import annotations

import pytest
from mpi4py import MPI

from pdem.cases.rock_mass import l_on_stack_scene
from pdem.config import parse_scene
from pdem.model.build import SpecTable, expand_blocks
from pdem.simulation import Simulation

FIELDS = ("name", "entry", "parent", "group", "material", "volume", "surface", "n_pieces",
          "excavate_at", "excavate_stage")


def test_views_read_as_the_released_specs():
    """The L block (two pieces, joined) on a cut stack with a block excavated at a time."""
    scene = parse_scene(l_on_stack_scene())
    specs = expand_blocks(scene, 10**6)
    for sp in specs:
        sp.release()
    table = SpecTable(specs, scene.blocks)
    assert len(table) == len(specs)
    assert any(sp.n_pieces == 2 for sp in specs) and any(sp.excavate_at for sp in specs)
    for g, (view, sp) in enumerate(zip(table, specs, strict=True)):
        for k in FIELDS:
            assert getattr(view, k) == getattr(sp, k), (g, k)
        assert view.spec is sp.spec and table[g].pieces is None


def test_a_run_keeps_names_not_shapes():
    """A simulation's specs after set-up are the table; a released spec's shapes are gone and
    asking a released spec for them says so (not a silent empty list)."""
    sim = Simulation(parse_scene(l_on_stack_scene()), MPI.COMM_SELF, output=False)
    assert isinstance(sim.specs, SpecTable)
    assert not sim.state.glob.has_geometry
    assert sim.specs[0].name and sim.specs[0].pieces is None
    spec = expand_blocks(parse_scene(l_on_stack_scene()), 10**6)[0]
    spec.release()
    with pytest.raises(ValueError):
        spec.shape  # noqa: B018


def test_string_column_reads_back_every_string():
    """Names are one UTF-8 buffer with offsets: each reads back as given (empty, non-ASCII,
    negative index), iteration and positions agree, out-of-range is an IndexError."""
    from pdem.model.strings import StringColumn

    texts = ["stack_0_0_0", "", "Blöck ∆", "b[1]", "stack_0_0_0"]
    col = StringColumn(texts)
    assert len(col) == 5 and list(col) == texts
    assert [col[i] for i in range(5)] == texts and col[-3] == "Blöck ∆"
    assert col.lengths().tolist() == [11, 0, 10, 4, 11] and col.max_bytes == 11
    assert col.positions(["stack_0_0_0", "b[1]", "absent"]) == {"stack_0_0_0": 0, "b[1]": 3}
    assert col == StringColumn(texts) and col == texts and col != texts[:4]
    assert col != StringColumn(texts[::-1])
    with pytest.raises(IndexError):
        col[5]  # noqa: B018
    assert len(StringColumn([])) == 0 and StringColumn([]).max_bytes == 0


def test_names_take_their_bytes_not_python_objects():
    """64,000 array blocks: the table keeps ~the names' bytes and an offset each, and no
    parent names (every block is its own parent)."""
    from pdem.cases.stacks import cube_stack_scene

    scene = parse_scene(cube_stack_scene(40, "fast"))
    specs = expand_blocks(scene, 10**7)
    table = SpecTable(specs, scene.blocks, {k: None for k in ("volume", "surface", "max_face",
                                                               "n_pieces")})
    n = len(specs)
    assert n == 64001 and table.parents == [] and (table.parent == -1).all()
    assert table.names.nbytes < n * (8 + max(len(sp.name) for sp in specs))
    assert table.excavate_at is None and table[7].excavate_at is None
    assert [table[g].name for g in (0, 1, n - 1)] == [specs[g].name for g in (0, 1, n - 1)]
    assert table.parent_names()[n - 1] == specs[n - 1].parent == specs[n - 1].name
