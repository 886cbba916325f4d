"""The compiled mass properties and half-edge build (pdem.geometry.mass, .topology) against
the numpy definitions they replaced, kept here as the reference, and every topology error."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from pdem.geometry import GeometryError, box, convex_hull
from pdem.geometry.cutting import split_by_plane
from pdem.geometry.mass import mass_properties
from pdem.geometry.topology import build_half_edges


def reference_mass_properties(v, face_start, face_verts):
    """The numpy version (einsum sums over the faces' triangle fans)."""
    tri = np.concatenate([
        np.stack([np.full(face_start[f + 1] - face_start[f] - 2, face_verts[face_start[f]]),
                  face_verts[face_start[f] + 1:face_start[f + 1] - 1],
                  face_verts[face_start[f] + 2:face_start[f + 1]]], axis=1)
        for f in range(len(face_start) - 1)])
    ref = v.mean(axis=0)
    a, b, c = v[tri[:, 0]] - ref, v[tri[:, 1]] - ref, v[tri[:, 2]] - ref
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    volume = det.sum() / 6.0
    s = a + b + c
    first = (det[:, None] * s).sum(axis=0) / 24.0
    outer = sum(np.einsum("i,ij,ik->jk", det, x, x) for x in (a, b, c, s)) / 120.0
    g = first / volume
    cov = outer - volume * np.outer(g, g)
    inertia = np.trace(cov) * np.eye(3) - cov
    return volume, ref + g, 0.5 * (inertia + inertia.T)


def reference_edges(face_start, face_verts):
    """Twin of every half-edge and the sorted unique edges, by the definition."""
    nxt = np.array([h + 1 if h + 1 < face_start[f + 1] else face_start[f]
                    for f in range(len(face_start) - 1)
                    for h in range(face_start[f], face_start[f + 1])])
    dest = face_verts[nxt]
    pos = {(int(o), int(d)): h for h, (o, d) in enumerate(zip(face_verts, dest, strict=True))}
    twin = np.array([pos[int(d), int(o)] for o, d in zip(face_verts, dest, strict=True)])
    edges = sorted((int(o), int(d)) for o, d in zip(face_verts, dest, strict=True) if o < d)
    return nxt, twin, np.array(edges)


points = st.lists(st.tuples(*[st.floats(-1.0, 1.0)] * 3), min_size=6, max_size=30)


@settings(max_examples=60, deadline=None)
@given(points, st.floats(-1e6, 1e6))
@example([(0.0, 0.0, 0.5), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.5),
          (0.04752790354919356, 0.0, -0.5), (-0.6719119377624279, 1.0, 1.0)], 524288.0)
def test_compiled_mass_and_topology_equal_the_definitions(pts, shift):
    try:
        poly = convex_hull(np.array(pts) + shift)
    except GeometryError:  # degenerate draws (coplanar, coincident): nothing to compare
        return
    v, fs, fv = poly.vertices, poly.face_start, poly.face_verts
    vol, cen, inertia = mass_properties(v, fs, fv)
    rvol, rcen, rinertia = reference_mass_properties(v, fs, fv)
    size = float(np.ptp(v, axis=0).max())
    assert vol == pytest.approx(rvol, rel=1e-11, abs=1e-12 * size**3)
    # the vertex mean's rounding: a few ulps of the coordinates far from the origin
    assert np.allclose(cen, rcen, rtol=0.0, atol=1e-11 * size + 1e-15 * np.abs(v).max())
    assert np.allclose(inertia, rinertia, rtol=0.0, atol=1e-11 * size**5)
    he = build_half_edges(len(v), fs, fv)
    nxt, twin, edges = reference_edges(fs, fv)
    assert np.array_equal(he.next, nxt) and np.array_equal(he.twin, twin)
    assert np.array_equal(he.edges, edges) and np.array_equal(he.origin, fv)
    assert np.array_equal(he.face, np.repeat(np.arange(len(fs) - 1), np.diff(fs)))
    assert all(fv[he.vert_he[k]] == k and not (fv[:he.vert_he[k]] == k).any()
               for k in range(len(v)))


def test_unit_cube_and_a_cut_piece_against_closed_forms():
    vol, cen, inertia = mass_properties(*_csr(box([1, 2, 3], [3, 3, 4])))
    assert vol == pytest.approx(2.0, rel=1e-14)
    assert np.allclose(cen, [2.0, 2.5, 3.5], atol=1e-14)
    # a 2 x 1 x 1 box: I = V/12 diag(b² + c², a² + c², a² + b²)
    assert np.allclose(inertia, np.diag([2 / 12 * 2, 2 / 12 * 5, 2 / 12 * 5]), atol=1e-14)
    # the lower half of the unit cube cut by x + y = 1: a right prism on a triangle
    below, _ = split_by_plane(box([0, 0, 0], [1, 1, 1]), [1, 1, 0], 1.0)
    assert below.volume == pytest.approx(0.5, rel=1e-14)
    assert np.allclose(below.centroid, [1 / 3, 1 / 3, 0.5], atol=1e-14)


def _csr(poly):
    return poly.vertices, poly.face_start, poly.face_verts


CUBE_FACES = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2],
              [1, 3, 7, 5]]


def _faces(faces):
    start = np.cumsum([0] + [len(f) for f in faces])
    return start, np.concatenate([np.array(f) for f in faces])


@pytest.mark.parametrize(("nv", "faces", "msg"), [
    (8, CUBE_FACES[:3], "at least 4 polygons"),
    (8, [[0, 2, 2, 1]] + CUBE_FACES[1:], "repeats a vertex"),
    (8, [[1, 3, 2, 0]] + CUBE_FACES[1:], "used by two faces"),
    (8, CUBE_FACES[:5] + [[1, 3, 7]], "not closed"),
    (9, CUBE_FACES, "not used by any face"),
    # two cubes sharing only a corner (vertex 0): closed, but V - E + F = 3
    (15, CUBE_FACES + [[0, 9, 10, 8], [11, 12, 14, 13], [0, 8, 12, 11], [9, 13, 14, 10],
                       [0, 11, 13, 9], [8, 10, 14, 12]], "Euler characteristic"),
])
def test_topology_errors_name_the_fault(nv, faces, msg):
    start, verts = _faces(faces)
    with pytest.raises(GeometryError, match=msg):
        build_half_edges(nv, start, verts)


def test_half_edges_of_a_hull_of_many_points():
    """A scanned boulder's hull (2,000 points on a sphere, ~12,000 half-edges): the compiled
    build equals the definition, with the twins found by sorted keys."""
    rng = np.random.default_rng(7)
    p = rng.normal(size=(2000, 3))
    poly = convex_hull(p / np.linalg.norm(p, axis=1)[:, None])
    he = build_half_edges(len(poly.vertices), poly.face_start, poly.face_verts)
    nxt, twin, edges = reference_edges(poly.face_start, poly.face_verts)
    assert len(twin) > 10_000
    assert np.array_equal(he.twin, twin) and np.array_equal(he.next, nxt)
    assert np.array_equal(he.edges, edges)
