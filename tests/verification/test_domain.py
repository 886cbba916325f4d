"""The model domain (issue 16, item 5): blocks that fall out of it are deleted or frozen, the
run keeps its speed and its energy budget, and the cell space does not follow them."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.cases import make_simulation
from pdem.cases.collapse import ledge_scene
from pdem.plugins.energy import balance, energy_totals


@pytest.mark.parametrize("action", ["delete", "freeze"])
def test_blocks_leaving_the_domain_are_taken_out_and_the_budget_balances(action):
    """The rock slides off the ledge (gravity tilted 17 deg, friction 10 deg) and falls out of
    the domain; the pebble slides too and the run goes on to its end."""
    sim = make_simulation(ledge_scene(action=action))
    sim.run()
    b = sim.blocks
    rock, pebble = 1, 2
    assert b.out[rock] == (2 if action == "delete" else 1) and b.fixed[rock] == 1
    assert np.all(b.v[rock] == 0.0)
    # it stopped where it left the box (a 2 s fall would take it ~20 m down)
    assert -3.5 < b.x[rock, 2] < -2.5
    assert b.out[pebble] == 0 and b.x[pebble, 0] > -2.3  # the pebble slid, still in the model
    # the cell space stays the size of the domain, not of where the rock would be
    assert np.all(sim.state.cells.hi - sim.state.cells.origin < 20.0)
    t = energy_totals(sim.state)
    err, put_in = balance(t, sim.runner.plugin("energy").e0)
    assert t["removed"] > 0.5 * 2500.0 * 9.81 * 2.0  # it took its fall's energy with it
    assert abs(err) < 0.01 * put_in
    if action == "delete":
        assert not np.any((sim.contacts.ga == rock) | (sim.contacts.gb == rock))
