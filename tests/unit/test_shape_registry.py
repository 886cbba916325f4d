"""Block shape kinds are registry entries (pdem.model.shapes.SHAPES): each owns its scene
model, builder, member count, size estimate and whether it may be zoned; the scene grammar
(``Block``'s fields, SHAPE_KEYS, ZONED_SHAPES) follows the registry, and build and pre-flight
look a kind up instead of naming it.

The recipe "a block shape" (docs/architecture.md) is done here from outside pdem's tree,
touching no file of it: a ``tetra`` family (its own model, builder, member count and size
estimate) is registered by the test, accepted by the scene grammar, built, pre-flighted and
run, and unregistered (the grammar goes back)."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import PositiveInt

from pdem.cases import make_simulation
from pdem.config import ConfigError, parse_scene, schema
from pdem.config.schema import SHAPE_KEYS, SHAPE_MODELS, ZONED_SHAPES, Block, Length
from pdem.geometry import tetrahedron
from pdem.model.build import expand_blocks
from pdem.model.shapes import SHAPES, ShapeKind, family_size, shape_size
from pdem.preflight import estimate, preflight
from pdem.strict import Strict

SCENE = """
materials: {rock: {density: 2600}}
joints:
  default: {kn: 1.0e9, ks: 5.0e8}
blocks:
  - {name: floor, material: rock, fixed: true, box: {min: [-2, -2, -1], max: [2, 2, 0]}}
solve: {time: 0.01}
"""

CUBE = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1]]
BOX = {"min": [0, 0, 0], "max": [1, 1, 1]}

# (shape key, its parameters, (members or None, (blocks, vertices, faces, edges))): the numbers
# the pre-flight's old if-chains gave, by hand (box-like: 8 vertices, 6 faces, 12 edges; a
# polytope of v vertices: max(2v - 4, 4) faces, max(3v - 6, 6) edges; random: 2v - 4, 3v - 6)
SAMPLES = [
    ("box", BOX, (None, (1, 8, 6, 12))),
    ("polyhedron", {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]},
     (None, (1, 5, 6, 9))),
    ("polyhedron", {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]},
     (None, (1, 4, 4, 6))),
    ("polyhedron", {"vertices": CUBE}, (None, (1, 8, 12, 18))),
    ("prism", {"base": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "extrude": [0, 0, 1]},
     (None, (1, 6, 8, 12))),
    ("prism", {"base": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], "extrude": [0, 0, 1]},
     (None, (1, 8, 12, 18))),
    ("planes", {"normals": [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, -1, -1]],
                "offsets": [1, 1, 1, 0]}, (None, (1, 8, 12, 18))),
    ("planes", {"normals": [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                "offsets": [1, 0, 1, 0, 1, 0]}, (None, (1, 12, 20, 30))),
    ("array", {"box": BOX, "count": [2, 3, 4], "spacing": [1.1, 1.1, 1.1]},
     (24, (24, 8, 6, 12))),
    ("array", {"box": BOX, "count": [1, 1, 1], "spacing": [1.1, 1.1, 1.1]}, (1, (1, 8, 6, 12))),
    ("random", {"count": 5, "region": {"min": [0, 0, 0], "max": [10, 10, 10]},
                "size": [0.5, 1.0]}, (5, (5, 10, 16, 24))),
    ("random", {"count": 7, "region": {"min": [0, 0, 0], "max": [10, 10, 10]},
                "size": [0.5, 1.0], "vertices": 4}, (7, (7, 4, 4, 6))),
    ("mesh", {"file": "cells.msh"}, (None, (1, 8, 6, 12))),
]


def test_every_schema_shape_kind_is_registered():
    assert SHAPES.names() == SHAPE_KEYS == SHAPE_MODELS.names()
    assert SHAPE_KEYS == ("box", "polyhedron", "prism", "planes", "array", "random", "mesh")
    assert tuple(k for k, s in SHAPES.items() if s.zoned) == ZONED_SHAPES
    # the grammar follows the kinds: a Block field per kind, after ``name``, of its own model
    assert list(Block.model_fields)[:8] == ["name", *SHAPE_KEYS]
    for key, kind in SHAPES.items():
        assert SHAPE_MODELS[key].model is kind.params
        assert Block.model_fields[key].annotation == (kind.params | None)


def test_every_kind_sampled():
    assert {kind for kind, _, _ in SAMPLES} == set(SHAPE_KEYS)


@pytest.mark.parametrize("kind, params, expected", SAMPLES,
                         ids=[f"{k}-{i}" for i, (k, _, _) in enumerate(SAMPLES)])
def test_counts_and_sizes_are_the_old_ones(kind, params, expected):
    b = Block.model_validate({"name": "b", "material": "rock", kind: params})
    members, size = expected
    assert b.shape_kind == kind
    assert family_size(b) == members
    assert shape_size(b) == size
    entry = SHAPES[kind]
    assert entry.family == (members is not None)
    assert entry.count(getattr(b, kind)) == (members or 1) == size[0]


# a shape kind from outside the tree: a row of tetrahedra


class TetraRow(Strict):
    """``count`` unit tetrahedra in a row along x, ``spacing`` apart (the test's family)."""

    count: PositiveInt
    spacing: Length = 2.0


def _tetras(p: TetraRow):
    for k in range(p.count):
        x = k * p.spacing
        yield k, tetrahedron([x, 0, 1], [x + 1, 0, 1], [x, 1, 1], [x, 0, 2])


TETRA = ShapeKind(TetraRow, _tetras, lambda p: (4, 4, 6), members=lambda p: p.count)
ROW = "  - {name: t, material: rock, tetra: {count: 3}}\n"
WITH_ROW = SCENE.replace("solve:", ROW + "solve:")


@pytest.fixture
def tetra_kind():
    """``tetra`` registered from here (no file of pdem changed), unregistered after."""
    SHAPES.register("tetra", TETRA)
    yield TETRA
    SHAPES.unregister("tetra")


def test_before_it_is_registered_the_key_is_unknown():
    with pytest.raises(ConfigError, match=r"blocks\[1\]\.tetra: unknown key"):
        parse_scene(WITH_ROW)
    with pytest.raises(KeyError, match="unknown block shape 'tetra'"):
        SHAPES["tetra"]


def test_registered_kind_extends_the_grammar_and_goes_back(tetra_kind):
    assert list(Block.model_fields)[:9] == ["name", *SHAPE_KEYS, "tetra"]
    assert schema.SHAPE_KEYS == (*SHAPE_KEYS, "tetra") and schema.ZONED_SHAPES == ZONED_SHAPES
    scene = parse_scene(WITH_ROW)
    assert scene.blocks[1].shape_kind == "tetra"
    assert scene.blocks[1].tetra == TetraRow(count=3, spacing=2.0)
    # its model's checks and the grammar's, named under its key path
    with pytest.raises(ConfigError, match=r"blocks\[1\]\.tetra\.count: Input should be "
                                          r"greater than 0"):
        parse_scene(WITH_ROW.replace("count: 3", "count: 0"))
    with pytest.raises(ConfigError, match=r"give exactly one shape of box, .*, mesh, tetra "
                                          r"\(got \['box', 'tetra'\]\)"):
        parse_scene(WITH_ROW.replace("tetra:", "box: {min: [0, 0, 0], max: [1, 1, 1]}, tetra:"))
    with pytest.raises(ConfigError, match=r"zones: not yet supported on 'tetra' blocks"):
        parse_scene(WITH_ROW.replace("material: rock, tetra", "material: rock, "
                                     "zones: {size: 0.5}, tetra")
                    .replace("{density: 2600}", "{density: 2600, young: 1.0e9, poisson: 0.2}"))
    SHAPES.unregister("tetra")
    try:
        assert list(Block.model_fields)[:9] == ["name", *SHAPE_KEYS, "material"]
        assert schema.SHAPE_KEYS == SHAPE_KEYS and "tetra" not in SHAPE_MODELS
        with pytest.raises(ConfigError, match=r"blocks\[1\]\.tetra: unknown key"):
            parse_scene(WITH_ROW)
    finally:
        SHAPES.register("tetra", TETRA)


def test_registered_kind_counts_and_sizes(tetra_kind):
    scene = parse_scene(WITH_ROW)
    b = scene.blocks[1]
    assert family_size(b) == 3
    assert shape_size(b) == (3, 4, 4, 6)
    est, per_entry = estimate(scene, 1, memory=2.0**40)
    assert per_entry == [(0, 1), (1, 3)] and est.blocks == 4
    assert preflight(scene, 2, memory=2.0**40, warn=False).blocks == 4
    # the pre-flight refuses a family too large, from its registered member count
    big = parse_scene(WITH_ROW.replace("count: 3", "count: 1000").replace(
        "solve:", "limits: {max_blocks: 100}\nsolve:"))
    with pytest.raises(ConfigError, match=r"limits\.max_blocks: the scene makes 1001 blocks"):
        preflight(big, 1, memory=2.0**40, warn=False)


def test_registered_kind_builds_and_runs(tetra_kind):
    scene = parse_scene(WITH_ROW)
    specs = expand_blocks(scene)
    assert [s.name for s in specs] == ["floor", "t[0]", "t[1]", "t[2]"]
    assert all(s.pieces[0].n_vertices == 4 for s in specs[1:])
    assert np.isclose(specs[3].pieces[0].centroid[0], 4.25)
    # a rank's share: the members outside it are not kept (the count from the registry)
    seen = []
    shared = expand_blocks(scene, share=lambda n: (seen.append(n), (0, 2))[1])
    assert seen == [4] and len(shared) == 4
    sim = make_simulation(WITH_ROW.replace("time: 0.01", "steps: 3"))
    sim.run()
    assert sim.state.step == 3 and sim.blocks.v[1:4, 2].max() < 0.0  # the row falls


def test_a_kind_whose_key_is_taken_is_refused():
    with pytest.raises(ValueError, match="'material': already a key of Block"):
        SHAPES.register("material", TETRA)
    # refused, and undone: the registry and the grammar as they were
    assert SHAPES.names() == SHAPE_MODELS.names() == SHAPE_KEYS
    assert list(Block.model_fields)[:9] == ["name", *SHAPE_KEYS, "material"]
