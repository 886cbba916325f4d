"""Boundary-condition kinds are registry entries (pdem.boundary.BOUNDARY_KINDS): each kind
owns how a condition is put on its blocks, what it does before a step, and whether set-up
keeps every block's geometry for it. Every kind is reachable from the scene (its key is a
field of ``boundary:`` and of a stage), and a kind's hooks are all the run calls: a recording
kind put in the registry in place of ``stress`` is called as the real one is."""

from __future__ import annotations

import pytest

from pdem.boundary import BOUNDARY_KINDS, Boundary, BoundaryKind, needs_every_block
from pdem.cases import make_simulation
from pdem.config import ConfigError, parse_scene
from pdem.config.schema import BoundaryConditions, Stage

SCENE = """
gravity: [0, 0, -9.81]
materials: {rock: {density: 2500.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}, material: rock}
boundary:
  stress:
    - {names: [cube], pressure: 1.0e5}
solve: {steps: 5}
"""


def test_every_kind_is_a_key_of_the_boundary_and_of_a_stage():
    assert set(BOUNDARY_KINDS) == {"velocity", "stress"}
    for key in BOUNDARY_KINDS:
        assert key in BoundaryConditions.model_fields and key in Stage.model_fields


def test_whole_scene_kinds_decide_what_set_up_keeps():
    with_stress = parse_scene(SCENE)
    without = parse_scene(SCENE.replace("boundary:\n  stress:\n    - {names: [cube], "
                                        "pressure: 1.0e5}\n", ""))
    assert needs_every_block(with_stress) and not needs_every_block(without)
    assert not needs_every_block(with_stress, stages_only=True)


@pytest.fixture
def recording_stress():
    """The ``stress`` entry replaced by one that records its calls (then put back)."""
    calls = []
    real = BOUNDARY_KINDS.unregister("stress")

    def add(boundary, s, cond, gids, t0, motion_too):
        calls.append(("add", tuple(int(g) for g in gids), t0))
        boundary.recorded = True
        return None

    BOUNDARY_KINDS.register("stress", BoundaryKind(
        add, lambda b: getattr(b, "recorded", False),
        lambda b, s: calls.append(("step", s.step)),
        at_start=lambda b, s: calls.append(("start", s.step))))
    yield calls
    BOUNDARY_KINDS.unregister("stress")
    BOUNDARY_KINDS.register("stress", real)


def test_a_kind_is_called_through_its_entry(recording_stress):
    sim = make_simulation(SCENE)
    sim.run()
    calls = recording_stress
    assert calls[0] == ("add", (1,), 0.0)  # the cube, from the scene's boundary: at t = 0
    assert calls[1] == ("start", 0)
    assert [c for c in calls[2:]] == [("step", k) for k in range(5)]  # before every step
    assert isinstance(sim.state.boundary, Boundary) and sim.state.boundary.active


def test_a_condition_that_cannot_act_is_refused_with_its_key_path(recording_stress):
    nowhere = SCENE.replace("names: [cube]", "range: {box: {min: [5, 5, 5], max: [6, 6, 6]}}")
    with pytest.raises(ConfigError, match=r"boundary\.stress\[0\] \(line 10\): selects no block"):
        make_simulation(nowhere)
    # what a kind's ``add`` says it cannot do is the message, under the condition's key path
    kind = BOUNDARY_KINDS["stress"]
    BOUNDARY_KINDS.unregister("stress")
    BOUNDARY_KINDS.register("stress", BoundaryKind(lambda *a: "no exposed face here",
                                                   kind.active, kind.before_step))
    with pytest.raises(ConfigError, match=r"boundary\.stress\[0\] \(line 10\): no exposed face here"):
        make_simulation(SCENE)
