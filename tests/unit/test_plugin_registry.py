"""Run plugins register themselves (pdem.plugins.PLUGINS): a scene gets every registered
plugin whose entry makes one for it, in the entries' order; a plugin from outside pdem's
tree is one class and one registration."""

from __future__ import annotations

import pytest

from pdem.cases import make_simulation
from pdem.cases.stacks import cube_stack_scene
from pdem.plugins import PLUGINS, Plugin, PluginEntry

SCENE = cube_stack_scene(1, "fast")  # one cube on a floor


class StepCounter(Plugin):
    """Counts the steps it saw (every step: it declares no horizon)."""

    name = "step-counter"

    def __init__(self, state):
        self.state = state
        self.steps: list[int] = []

    def after_step(self, run):
        self.steps.append(self.state.step)


@pytest.fixture
def counter_registered():
    PLUGINS.register("step-counter", PluginEntry(
        75, lambda state, output, made: StepCounter(state)))
    yield
    PLUGINS.unregister("step-counter")


def test_the_shipped_plugins_in_their_order():
    names = list(PLUGINS)
    order = sorted(names, key=lambda n: PLUGINS[n].order)
    assert order == ["stages", "excavations", "checkpoints", "snapshots", "load-report",
                     "histories", "energy", "no-progress", "progress"]
    sim = make_simulation(SCENE)  # no output, no stages, no excavation, no checkpoint
    assert [p.name for p in sim.runner.plugins] == ["energy", "progress"]


def test_a_plugin_from_outside_the_tree(counter_registered):
    sim = make_simulation(SCENE)
    assert [p.name for p in sim.runner.plugins] == ["energy", "step-counter", "progress"]
    sim.run(steps=7)
    assert sim.runner.plugin("step-counter").steps == list(range(1, 8))


def test_unregistered_plugins_are_gone():
    assert "step-counter" not in PLUGINS
    assert "step-counter" not in [p.name for p in make_simulation(SCENE).runner.plugins]
