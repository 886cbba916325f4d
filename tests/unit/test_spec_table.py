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
