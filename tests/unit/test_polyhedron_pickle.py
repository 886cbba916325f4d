"""A polyhedron pickles as one buffer of its arrays (ConvexPolyhedron.__reduce_ex__: the
ranks sharing a rock mass's cutting send each other every piece) and comes back bitwise the
same: every field's values, dtype and shape, read-only, its caches made again alike."""

from __future__ import annotations

import pickle

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pdem.geometry import box, convex_hull
from pdem.geometry.cutting import split_by_plane
from pdem.geometry.polyhedron import ConvexPolyhedron

FIELDS = ("vertices", "face_start", "face_verts", "normals", "offsets", "edges", "centroid",
          "inertia", "face_tag")


def _same(p: ConvexPolyhedron, q: ConvexPolyhedron) -> None:
    for k in FIELDS:
        a, b = getattr(p, k), getattr(q, k)
        if a is None:
            assert b is None, k
            continue
        assert b.dtype == a.dtype and b.shape == a.shape and not b.flags.writeable, k
        assert a.tobytes() == b.tobytes(), k  # bitwise, signed zeros too
    assert q.volume == p.volume
    for k in ("he_origin", "he_twin", "he_next", "he_face", "vert_he"):
        assert np.array_equal(getattr(q, k), getattr(p, k)), k
    assert q.face_areas().tobytes() == p.face_areas().tobytes()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(4, 40), st.floats(-1e6, 1e6))
def test_a_polyhedron_comes_back_from_its_pickle_bitwise(seed, n, shift):
    rng = np.random.default_rng(seed)
    hull = convex_hull(rng.standard_normal((n, 3)) + shift)
    hull.face_areas()  # caches are not sent: made again on the other side
    for p in (hull, hull.with_face_tag(rng.integers(-5, 5, hull.n_faces))):
        q = pickle.loads(pickle.dumps(p, protocol=5))
        assert "_he" not in q.__dict__ and "_face_areas" not in q.__dict__
        _same(p, q)


def test_cut_pieces_and_nested_lists_round_trip():
    """The cut pieces of a block (face tags of the joint sets) in the lists the ranks
    send; a polyhedron whose arrays are not the usual dtypes pickles the default way."""
    below, above = split_by_plane(box([0, 0, 0], [2, 1, 1]), np.array([1.0, 0.2, 0.1]) /
                                  np.linalg.norm([1.0, 0.2, 0.1]), 0.9, tag=3)
    pieces = [[below, above], [box([0, 0, 0], [1, 1, 1])]]
    back = pickle.loads(pickle.dumps(pieces))
    for ps, qs in zip(pieces, back, strict=True):
        for p, q in zip(ps, qs, strict=True):
            _same(p, q)
    odd = ConvexPolyhedron(**{**{k: getattr(below, k) for k in FIELDS},
                              "volume": below.volume,
                              "edges": below.edges.astype(np.int32)})
    again = pickle.loads(pickle.dumps(odd))
    assert again.edges.dtype == np.int32 and np.array_equal(again.edges, below.edges)
