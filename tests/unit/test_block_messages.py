"""A block's static data and geometry as the rebuild sends them (pdem.model.blocks.pack /
unpack / take_rows): what arrives is the block, whatever other blocks share the message."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.cases.rock_mass import l_on_stack_scene
from pdem.config import parse_scene
from pdem.model.blocks import BLOCK, GEOMETRY, SCRATCH_GEOMETRY, pack, take_rows, unpack
from pdem.model.build import block_store, expand_blocks


@pytest.fixture(scope="module")
def scene_store():
    """The L block (two convex pieces) on a cut stack: blocks of one and of two pieces."""
    scene = parse_scene(l_on_stack_scene())
    specs = expand_blocks(scene, 10**6)
    store, _ = block_store(scene, specs)
    assert (np.diff(store.piece_start) == 2).any()
    return store


def block_geometry(store, row):
    """Block ``row``'s geometry with its own numbering (vertex ids from its first vertex)."""
    p0, p1 = store.piece_start[row], store.piece_start[row + 1]
    v0, v1 = store.vert_start[p0], store.vert_start[p1]
    f0, f1 = store.face_start[p0], store.face_start[p1]
    e0, e1 = store.edge_start[p0], store.edge_start[p1]
    d0, d1 = store.edir_start[p0], store.edir_start[p1]
    fv0, fv1 = store.fvert_start[f0], store.fvert_start[f1]
    return {
        "piece_gid": store.piece_gid[p0:p1], "piece_center": store.piece_center[p0:p1],
        "piece_verts": np.diff(store.vert_start[p0:p1 + 1]),
        "piece_faces": np.diff(store.face_start[p0:p1 + 1]),
        "face_lens": np.diff(store.fvert_start[f0:f1 + 1]),
        "verts_local": store.verts_local[v0:v1], "face_tag": store.face_tag[f0:f1],
        "normals_local": store.normals_local[f0:f1], "offsets_local": store.offsets_local[f0:f1],
        "face_verts": store.face_verts[fv0:fv1] - v0, "edges": store.edges[e0:e1] - v0,
        "edirs_local": store.edirs_local[d0:d1],
    }


def assert_same_block(a, ra, b, rb):
    for f in BLOCK:
        if f.static:
            assert np.array_equal(getattr(a, f.name)[ra], getattr(b, f.name)[rb]), f.name
    ga, gb = block_geometry(a, ra), block_geometry(b, rb)
    for k in ga:
        assert np.array_equal(ga[k], gb[k]), k


def test_messages_rebuild_every_block_bitwise(scene_store):
    """Blocks split over three messages in a scrambled order, unpacked and put back in gid
    order: every block's static fields and geometry equal the scene's, and the store is
    consistent (pieces point at their block, vertex ids inside the block's vertices)."""
    g = scene_store
    rng = np.random.default_rng(3)
    rows = rng.permutation(g.n)
    parts = [pack(g, r) for r in np.array_split(rows, 3)]
    got = unpack(parts, np.zeros(g.n, np.uint8))
    order = np.argsort(got.gid, kind="stable")
    back = take_rows(got, order, np.ones(g.n, np.uint8))
    assert np.array_equal(back.gid, np.arange(g.n))
    for r in range(g.n):
        assert_same_block(g, r, back, r)
    assert np.array_equal(back.piece_block, np.repeat(np.arange(g.n), np.diff(back.piece_start)))
    assert set(GEOMETRY) == set(back.geometry())
    for k in SCRATCH_GEOMETRY:  # recomputed from the pose where the block arrives
        assert not getattr(back, k).any()


def test_a_message_carries_no_scratch_and_empty_ones_join(scene_store):
    """A message holds the static fields and body-frame geometry only; an empty message (a
    rank that sends nothing) joins the others without changing them."""
    g = scene_store
    msg = pack(g, np.array([1, 0]))
    assert not set(SCRATCH_GEOMETRY) & set(msg)
    assert {f.name for f in BLOCK if f.static} <= set(msg)
    assert not {f.name for f in BLOCK if not f.static} & set(msg)
    both = unpack([pack(g, np.zeros(0, np.int64)), msg, pack(g, np.zeros(0, np.int64))],
                  np.zeros(2, np.uint8))
    assert list(both.gid) == [1, 0]
    assert_same_block(g, 1, both, 0)
    assert_same_block(g, 0, both, 1)
    with pytest.raises(ValueError, match="no messages"):
        unpack([], np.zeros(0, np.uint8))
