"""Boundary-condition kinds are registry entries (pdem.boundary.BOUNDARY_KINDS): each kind
owns its condition model (the scene grammar's ``boundary.<key>`` and a stage's ``<key>``
follow the registry), how a condition is put on its blocks, what it does before a step, and
whether set-up keeps every block's geometry for it. Every kind is reachable from the scene,
and a kind's hooks are all the run calls: a recording kind put in the registry in place of
``stress`` is called as the real one is.

The recipe "a boundary-condition kind" (docs/architecture.md) is done here from outside pdem's
tree, touching no file of it: ``push`` (its own condition model, key and hooks) is registered
by the test, accepted in a scene's ``boundary:`` and in a stage, applied, and unregistered
(the grammar goes back)."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.boundary import BOUNDARY_KINDS, Boundary, BoundaryKind, needs_every_block
from pdem.cases import make_simulation
from pdem.config import ConfigError, parse_scene
from pdem.config.schema import (
    CONDITION_MODELS,
    BoundaryConditions,
    Scene,
    Selection,
    Stage,
    Vec3Force,
)
from pdem.selection import set_block_fields

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
    assert BOUNDARY_KINDS.names() == ("velocity", "stress", "quiet")
    # the grammar's registry follows the kinds: the same keys, each kind's own model
    assert CONDITION_MODELS.names() == BOUNDARY_KINDS.names()
    for key, kind in BOUNDARY_KINDS.items():
        assert CONDITION_MODELS[key] is kind.condition
        for model in (BoundaryConditions, Stage):
            assert model.model_fields[key].annotation == list[kind.condition]
            assert model.model_fields[key].default == []
    # the scene-file contract: the keys where they always were
    assert list(BoundaryConditions.model_fields) == ["velocity", "stress", "quiet"]
    assert list(Stage.model_fields)[4:9] == ["free", "velocity", "stress", "quiet", "force"]


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
        real.condition, add, lambda b: getattr(b, "recorded", False),
        lambda b, s: calls.append(("step", s.step)),
        at_start=lambda b, s: calls.append(("start", s.step))))
    yield calls
    BOUNDARY_KINDS.unregister("stress")
    BOUNDARY_KINDS.register("stress", real)
    # (re-registered last: the kinds after it go back behind it, in the shipped order)
    quiet = BOUNDARY_KINDS.unregister("quiet")
    BOUNDARY_KINDS.register("quiet", quiet)


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
    BOUNDARY_KINDS.register("stress", BoundaryKind(kind.condition,
                                                   lambda *a: "no exposed face here",
                                                   kind.active, kind.before_step))
    with pytest.raises(ConfigError, match=r"boundary\.stress\[0\] \(line 10\): no exposed face here"):
        make_simulation(SCENE)


# ---------------------------------------------------------------- the recipe, from outside


class Push(Selection):
    """The test's kind: a constant force (N) at the centroid of each selected block."""

    force: Vec3Force


def _add_push(boundary, s, cond, gids, t0, motion_too):
    if not any(cond.force):
        return "a push of zero force"
    set_block_fields(s, gids, applied_force=cond.force)
    boundary.pushes = [*getattr(boundary, "pushes", []), (tuple(int(g) for g in gids), t0)]
    return None


def _before_push(boundary, s):
    boundary.push_steps = [*getattr(boundary, "push_steps", []), s.step]


PUSH = BoundaryKind(Push, _add_push, lambda b: bool(getattr(b, "pushes", ())), _before_push)

PUSHED = SCENE.replace("""boundary:
  stress:
    - {names: [cube], pressure: 1.0e5}
""", """boundary:
  push:
    - {names: [cube], force: [2.0e4, 0, 0]}
""")
# the same load by the shipped ``force:`` key of a block: the run must be the same, bit for bit
FORCED = SCENE.replace("""  - {name: cube, box: {min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}, material: rock}
boundary:
  stress:
    - {names: [cube], pressure: 1.0e5}
""", """  - {name: cube, box: {min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}, material: rock,
     force: [2.0e4, 0, 0]}
""")
STAGED = PUSHED.replace("""boundary:
  push:
    - {names: [cube], force: [2.0e4, 0, 0]}
solve: {steps: 5}
""", """solve: {damping: none}
stages:
  - {name: settle, solve: {steps: 3}}
  - name: push
    push: [{names: [cube], force: [2.0e4, 0, 0]}]
    solve: {steps: 4}
""")


@pytest.fixture
def push_kind():
    """``push`` registered from here (no file of pdem changed), unregistered after."""
    BOUNDARY_KINDS.register("push", PUSH)
    yield PUSH
    BOUNDARY_KINDS.unregister("push")


def test_before_it_is_registered_the_key_is_unknown():
    with pytest.raises(ConfigError, match=r"boundary\.push: unknown key; allowed: velocity, "
                                          r"stress, quiet  \[line 9\]"):
        parse_scene(PUSHED)


def test_a_kind_from_outside_extends_the_grammar_and_goes_back(push_kind):
    assert list(BoundaryConditions.model_fields) == ["velocity", "stress", "quiet", "push"]
    assert list(Stage.model_fields)[4:10] == ["free", "velocity", "stress", "quiet", "push",
                                              "force"]
    scene = parse_scene(PUSHED)
    assert scene.boundary.push == [Push(names=["cube"], force=(2.0e4, 0.0, 0.0))]
    assert Scene.model_fields["boundary"].default.push == []
    assert parse_scene(STAGED).stages[1].push[0].force == (2.0e4, 0.0, 0.0)
    # its model's checks, named under its key path; the scene's checks of a selection too
    with pytest.raises(ConfigError, match=r"boundary\.push\[0\]\.force: Field required"):
        parse_scene(PUSHED.replace(", force: [2.0e4, 0, 0]", ""))
    with pytest.raises(ConfigError, match=r"stages\[1\]\.push\[0\]\.groups: no block has "
                                          r"group 'nope'"):
        parse_scene(STAGED.replace("push: [{names: [cube]", "push: [{groups: [nope]"))
    BOUNDARY_KINDS.unregister("push")
    try:
        assert list(BoundaryConditions.model_fields) == ["velocity", "stress", "quiet"]
        assert "push" not in Stage.model_fields and "push" not in CONDITION_MODELS
        with pytest.raises(ConfigError, match=r"boundary\.push: unknown key"):
            parse_scene(PUSHED)
        with pytest.raises(ConfigError, match=r"stages\[1\]\.push: unknown key"):
            parse_scene(STAGED)
    finally:
        BOUNDARY_KINDS.register("push", PUSH)


def test_a_kind_from_outside_is_applied_as_a_shipped_key_would_be(push_kind):
    pushed = make_simulation(PUSHED)
    boundary = pushed.state.boundary
    assert boundary.pushes == [((1,), 0.0)]  # the cube, from the scene's boundary: at t = 0
    pushed.run()
    assert boundary.push_steps == list(range(5))  # before every step
    forced = make_simulation(FORCED)
    forced.run()
    for key in ("x", "v", "q", "w"):
        assert np.array_equal(getattr(pushed.blocks, key), getattr(forced.blocks, key)), key
    assert pushed.blocks.v[1, 0] > 0.0 and pushed.blocks.x[1, 0] > 0.0  # the cube slides


def test_a_kind_from_outside_acts_from_its_stage_on(push_kind):
    sim = make_simulation(STAGED)
    assert not getattr(sim.state.boundary, "pushes", None)
    sim.run()
    boundary = sim.state.boundary
    (gids, t0), = boundary.pushes
    assert gids == (1,) and t0 == sim.state.stage_times[1] > 0.0
    assert boundary.push_steps == [3, 4, 5, 6]  # the stage's steps, not the settling ones
    # what its ``add`` refuses is the message, under the stage's key path
    with pytest.raises(ConfigError, match=r"stages\[1\]\.push\[0\] \(line \d+\): a push "
                                          r"of zero force"):
        make_simulation(STAGED.replace("force: [2.0e4, 0, 0]", "force: [0, 0, 0]")).run()


def test_a_kind_whose_key_is_taken_or_model_is_not_a_selection_is_refused():
    with pytest.raises(ValueError, match="'force': already a key of Stage"):
        BOUNDARY_KINDS.register("force", PUSH)
    # refused, and undone: the registry and the grammar as they were
    assert BOUNDARY_KINDS.names() == CONDITION_MODELS.names() == ("velocity", "stress", "quiet")
    assert list(Stage.model_fields)[4:9] == ["free", "velocity", "stress", "quiet", "force"]
    with pytest.raises(TypeError, match="not a pdem.config.schema.Selection"):
        BoundaryKind(dict, _add_push, bool, _before_push)
