"""Block shape kinds are registry entries (pdem.model.shapes.SHAPES): each owns its builder,
member count, size estimate and whether it may be zoned; build and pre-flight look a kind up
instead of naming it, so a kind registered from outside works in both without a KeyError."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from pdem.config import parse_scene
from pdem.config.schema import SHAPE_KEYS, ZONED_SHAPES, Block
from pdem.geometry import tetrahedron
from pdem.model.build import expand_blocks
from pdem.model.shapes import SHAPES, ShapeKind, family_size, shape_size
from pdem.preflight import estimate, preflight

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
    assert SHAPES.names() == SHAPE_KEYS
    assert tuple(k for k, s in SHAPES.items() if s.zoned) == ZONED_SHAPES


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


@dataclass(frozen=True)
class TetraRow:
    count: int
    spacing: float = 2.0


@dataclass
class TetraBlock:
    """A ``blocks:`` entry of the kind (the scene grammar's Block has a field per schema
    kind; this stand-in has the attributes build and pre-flight read)."""

    name: str
    tetra: TetraRow
    material: str = "rock"
    group: str = "default"
    mesh: None = None
    zones: None = None
    shape_kind: str = "tetra"


def _tetras(p: TetraRow):
    for k in range(p.count):
        x = k * p.spacing
        yield k, tetrahedron([x, 0, 1], [x + 1, 0, 1], [x, 1, 1], [x, 0, 2])


@pytest.fixture
def tetra_kind(monkeypatch):
    """Registers "tetra" for one test (the registry is restored after)."""
    monkeypatch.setattr(SHAPES, "_entries", dict(SHAPES._entries))
    return SHAPES.register("tetra", ShapeKind(_tetras, lambda p: (4, 4, 6),
                                              members=lambda p: p.count))


def _scene_with(*blocks):
    scene = parse_scene(SCENE)
    return scene.model_copy(update={"blocks": [*scene.blocks, *blocks]})


def test_registered_kind_counts_and_sizes(tetra_kind):
    b = TetraBlock("t", TetraRow(3))
    assert family_size(b) == 3
    assert shape_size(b) == (3, 4, 4, 6)
    scene = _scene_with(b)
    est, per_entry = estimate(scene, 1, memory=2.0**40)
    assert per_entry == [(0, 1), (1, 3)] and est.blocks == 4
    assert preflight(scene, 2, memory=2.0**40, warn=False).blocks == 4


def test_registered_kind_builds(tetra_kind):
    scene = _scene_with(TetraBlock("t", TetraRow(3)))
    specs = expand_blocks(scene)
    assert [s.name for s in specs] == ["floor", "t[0]", "t[1]", "t[2]"]
    assert all(s.pieces[0].n_vertices == 4 for s in specs[1:])
    assert np.isclose(specs[3].pieces[0].centroid[0], 4.25)
    # a rank's share: the members outside it are not kept (the count from the registry)
    seen = []
    shared = expand_blocks(scene, share=lambda n: (seen.append(n), (0, 2))[1])
    assert seen == [4] and len(shared) == 4


def test_unregistered_kind_is_named():
    with pytest.raises(KeyError, match="unknown block shape 'tetra'"):
        shape_size(TetraBlock("t", TetraRow(3)))
