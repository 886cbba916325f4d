"""The output's block surfaces (pdem.io.surfaces.body_surfaces), taken flat from the scene's
store, are each block's principal-frame pieces as the per-block definition gives them."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.cases.rock_mass import l_on_stack_scene
from pdem.config import parse_scene
from pdem.io.surfaces import BodyMesh, body_surfaces
from pdem.model.build import block_store, expand_blocks

PILE = """
name: pile
materials: {rock: {density: 2600.0}}
joints: {default: {kn: 1.0e8, ks: 5.0e7, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-3, -3, -0.5], max: [3, 3, 0.0]}, material: rock, fixed: true}
  - name: rock
    random: {count: 25, region: {min: [-2, -2, 0.05], max: [2, 2, 1.3]}, size: [0.45, 0.6],
             vertices: 9, seed: 4}
    material: rock
solve: {steps: 1}
"""


def per_block(specs):
    """The per-block definition: each spec's principal-frame pieces side by side."""
    vertices, faces = [], []
    for spec in specs:
        bodies = spec.principal_frame()[0]
        v0, fs = 0, []
        for sh in bodies:
            fs += [[v0 + int(i) for i in sh.face_verts[sh.face_start[f]:sh.face_start[f + 1]]]
                   for f in range(sh.n_faces)]
            v0 += sh.n_vertices
        vertices.append(np.concatenate([sh.vertices for sh in bodies]))
        faces.append(fs)
    return BodyMesh.from_lists(vertices, faces)


@pytest.mark.parametrize("text", [l_on_stack_scene(), PILE], ids=["joined", "random"])
def test_flat_surfaces_equal_the_per_block_definition(text):
    scene = parse_scene(text)
    specs = expand_blocks(scene, 10**6)
    store, _ = block_store(scene, specs)
    got, want = body_surfaces(store), per_block(specs)
    for k in BodyMesh._fields:
        assert np.array_equal(getattr(got, k), getattr(want, k)), k
    assert got.bad_face() is None
