"""Unit tests for pdem.geometry.cutting against closed forms and independent checks."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.geometry import GeometryError, box, from_planes, prism
from pdem.geometry.cutting import (
    UNTAGGED,
    _Cut,
    box_planes,
    clip_below,
    cut_blocks,
    cylinder_planes,
    dip_normal,
    excavate,
    excavate_blocks,
    joint_set_planes,
    piece_names,
    split_by_plane,
)

RTOL = 1e-12


def rotation(seed: int) -> np.ndarray:
    """Random proper rotation from a QR decomposition (independent of pdem code)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def random_block(seed: int):
    """A rotated, shifted box or hexagonal prism."""
    rng = np.random.default_rng(seed)
    if seed % 2:
        poly = box([0, 0, 0], rng.uniform(0.5, 3.0, 3))
    else:
        ang = np.linspace(0, 2 * np.pi, 7)[:-1] + rng.uniform(0, 1)
        base = np.stack([np.cos(ang), np.sin(ang), np.zeros(6)], axis=1) * rng.uniform(0.5, 2)
        poly = prism(base, [rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(1, 3)])
    return poly.transformed(rotation(seed), rng.uniform(-10, 10, 3))


def assert_piece_ok(piece, parent_volume):
    """A piece is a closed convex block: positive volume, every vertex inside all its planes."""
    assert 0.0 < piece.volume <= parent_volume * (1 + RTOL)
    dist = piece.vertices @ piece.normals.T - piece.offsets
    assert dist.max() <= 1e-9 * max(1.0, np.abs(piece.vertices).max())
    assert piece.face_tag is not None and piece.face_tag.shape == (piece.n_faces,)


def inside(poly, x, eps):
    """Mask of points at least ``eps`` inside ``poly`` (``eps < 0``: within ``-eps`` of it)."""
    return np.all(x @ poly.normals.T - poly.offsets < -eps, axis=1)


def assert_tiles(parent, pieces, seed=0, n=4000):
    """Pieces fill the parent without interior overlap: volume sum and point sampling."""
    assert sum(p.volume for p in pieces) == pytest.approx(parent.volume, rel=RTOL)
    rng = np.random.default_rng(seed)
    lo, hi = parent.vertices.min(axis=0), parent.vertices.max(axis=0)
    x = rng.uniform(lo, hi, size=(n, 3))
    eps = 1e-9 * float(np.linalg.norm(hi - lo))
    x = x[inside(parent, x, eps)]
    strictly = np.array([inside(p, x, eps) for p in pieces])
    loosely = np.array([inside(p, x, -eps) for p in pieces])
    assert strictly.sum(axis=0).max() <= 1  # no point strictly inside two pieces
    assert loosely.any(axis=0).all()  # every parent point is covered


def plane_match(poly, f, normals, offsets, scale=1.0):
    """Index of the plane (rows of normals/offsets) that face ``f`` lies on, or -1."""
    pts = poly.face_polygon(f)
    for k, (n, d) in enumerate(zip(normals, offsets, strict=True)):
        if poly.normals[f] @ n > 1 - 1e-9 and np.abs(pts @ n - d).max() < 1e-9 * scale:
            return k
    return -1


# ---------------------------------------------------------------------------- joint sets
@pytest.mark.parametrize(
    ("dip", "dd", "expected"),
    [
        (90, 90, [1, 0, 0]),
        (90, 0, [0, 1, 0]),
        (90, 270, [-1, 0, 0]),
        (0, 0, [0, 0, 1]),
        (0, 137, [0, 0, 1]),
        (60, 120, [0.75, -np.sqrt(3) / 4, 0.5]),
        (45, 225, [-0.5, -0.5, np.sqrt(0.5)]),
    ],
)
def test_dip_normal_closed_form(dip, dd, expected):
    n = dip_normal(dip, dd)
    np.testing.assert_allclose(n, expected, rtol=0, atol=1e-15)
    assert np.linalg.norm(n) == pytest.approx(1.0, rel=1e-15)


def test_dip_normal_exact_on_axes():
    # Multiples of 90 degrees give exact axis normals (no 6e-17 tilt off the box faces).
    assert dip_normal(90, 90).tolist() == [1.0, 0.0, 0.0]
    assert dip_normal(0, 45).tolist()[2] == 1.0
    with pytest.raises(GeometryError):
        dip_normal(95, 0)


def test_joint_set_single_plane_and_count():
    o = np.array([1.0, 2.0, 3.0])
    n, d = joint_set_planes(60, 120, o)
    assert d.shape == (1,) and d[0] == pytest.approx(n @ o, rel=1e-15)
    # count = planes on each side of the origin plane: 2 * count + 1 in all
    n, d = joint_set_planes(60, 120, o, spacing=0.5, count=2)
    np.testing.assert_allclose(d, n @ o + 0.5 * np.arange(-2, 3), rtol=0, atol=1e-14)
    assert len(joint_set_planes(30, 10, o, spacing=1.0, count=0)[1]) == 1
    with pytest.raises(GeometryError):
        joint_set_planes(30, 10, o, count=3)
    with pytest.raises(GeometryError):
        joint_set_planes(30, 10, o, spacing=1.0)
    with pytest.raises(GeometryError):
        joint_set_planes(30, 10, o, spacing=-1.0, count=1)


def test_joint_set_fills_bounds():
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([3.0, 5.0, 4.0])
    o = np.array([0.3, 0.1, 2.2])
    n, d = joint_set_planes(35, 200, o, spacing=0.37, bounds=(lo, hi))
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    pmin, pmax = (corners @ n).min(), (corners @ n).max()
    assert np.all((d > pmin) & (d < pmax))
    np.testing.assert_allclose(np.diff(d), 0.37, rtol=1e-12)
    assert d[0] - 0.37 <= pmin and d[-1] + 0.37 >= pmax  # nothing missing at either end
    k = (d - n @ o) / 0.37
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)  # all on the origin's lattice


# ---------------------------------------------------------------------------- split
@pytest.mark.parametrize("seed", range(12))
def test_split_conserves_volume_random(seed):
    poly = random_block(seed)
    rng = np.random.default_rng(100 + seed)
    for _ in range(5):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        w = rng.dirichlet(np.ones(poly.n_vertices))  # a random interior point
        d = n @ (w @ poly.vertices)
        below, above = split_by_plane(poly, n, d, tag=4)
        assert below is not None and above is not None
        assert below.volume + above.volume == pytest.approx(poly.volume, rel=RTOL)
        assert_piece_ok(below, poly.volume)
        assert_piece_ok(above, poly.volume)
        scale = np.abs(poly.vertices).max()
        assert (below.vertices @ n - d).max() <= 1e-12 * scale
        assert (above.vertices @ n - d).min() >= -1e-12 * scale


def test_split_non_unit_normal_same_as_unit():
    b = box([0, 0, 0], [1, 2, 3])
    lo1, _ = split_by_plane(b, [2, 2, 2], 4.0)
    lo2, _ = split_by_plane(b, np.ones(3) / np.sqrt(3), 2.0 / np.sqrt(3))
    assert lo1.volume == pytest.approx(lo2.volume, rel=RTOL)
    assert lo1.volume == pytest.approx(7 / 6, rel=RTOL)  # x+y+z <= 2 in the 1x2x3 box


@pytest.mark.parametrize(
    ("normal", "offset", "whole_side"),
    [
        ([1, 1, 1], 0.0, "above"),  # touches the vertex at the origin
        ([1, 1, 1], 6.0, "below"),  # touches the opposite vertex
        ([1, 1, 0], 0.0, "above"),  # touches the edge along z
        ([1, 0, 0], 1.0, "below"),  # contains the +x face
        ([0, 0, 1], 0.0, "above"),  # contains the -z face
        ([0.3, -0.2, 1], 10.0, "below"),  # misses above
        ([0.3, -0.2, 1], -10.0, "above"),  # misses below
    ],
)
def test_split_touching_or_missing_returns_block(normal, offset, whole_side):
    b = box([0, 0, 0], [1, 2, 3])
    below, above = split_by_plane(b, normal, offset, tag=9)
    whole, empty = (below, above) if whole_side == "below" else (above, below)
    assert empty is None
    np.testing.assert_array_equal(whole.vertices, b.vertices)
    np.testing.assert_array_equal(whole.face_verts, b.face_verts)
    assert whole.volume == b.volume
    assert whole.face_tag.tolist() == [UNTAGGED] * 6


def test_split_through_vertices_closed_forms():
    cube = box([0, 0, 0], [1, 1, 1])
    # Diagonal plane through two opposite edges (4 vertices on the plane): two prisms.
    below, above = split_by_plane(cube, [1, -1, 0], 0.0)
    assert below.volume == pytest.approx(0.5, rel=RTOL) and above.volume == pytest.approx(0.5, rel=RTOL)
    assert below.n_vertices == 6 and below.n_faces == 5
    # Plane through three vertices cuts off a corner tetrahedron.
    below, above = split_by_plane(cube, [1, 1, 1], 1.0)
    assert below.volume == pytest.approx(1 / 6, rel=RTOL) and below.n_vertices == 4
    assert above.volume == pytest.approx(5 / 6, rel=RTOL) and above.n_vertices == 7
    # Plane through one vertex and crossing the block.
    below, above = split_by_plane(cube, [1, 1, -1], 0.0)
    assert below.volume + above.volume == pytest.approx(1.0, rel=RTOL)
    assert_piece_ok(below, 1.0)
    assert_piece_ok(above, 1.0)


def _degenerate_plane(poly, kind, rng):
    """A plane through a vertex, an edge, two vertices, or just off a vertex (kind 0..3)."""
    v = poly.vertices
    n = rng.normal(size=3)
    if kind == 1:
        i, j = poly.edges[rng.integers(poly.n_edges)]
    else:
        i, j = rng.choice(len(v), 2, replace=False)
    if kind in (1, 2):  # make the plane contain the segment i-j
        t = v[j] - v[i]
        n -= (n @ t) / (t @ t) * t
    n /= np.linalg.norm(n)
    d = n @ v[i]
    if kind == 3:
        d += rng.choice([-1, 1]) * 10.0 ** rng.uniform(-14, -5) * np.abs(v).max()
    return n, d


@pytest.mark.parametrize("seed", range(6))
def test_split_degenerate_planes_random(seed):
    rng = np.random.default_rng(200 + seed)
    poly = random_block(seed)
    for _ in range(2):  # irregular blocks: cut the block itself first
        n = rng.normal(size=3)
        below, above = split_by_plane(poly, n, n @ poly.centroid + 0.1 * rng.normal())
        poly = max(below, above, key=lambda p: p.volume)
    for trial in range(40):
        kind = trial % 4
        n, d = _degenerate_plane(poly, kind, rng)
        below, above = split_by_plane(poly, n, d, tag=1)
        if below is None or above is None:
            whole = below if above is None else above
            assert whole.volume == poly.volume
            continue
        assert_piece_ok(below, poly.volume)
        assert_piece_ok(above, poly.volume)
        # A vertex within round-off of the plane counts as on it (no needle edges), which
        # costs up to that tolerance times a face area in volume; exact incidences cost nothing.
        rtol = 1e-9 if kind == 3 else RTOL
        assert below.volume + above.volume == pytest.approx(poly.volume, rel=rtol)


def test_sliver_thinner_than_tol_not_created():
    b = box([0, 0, 0], [1, 1, 1])
    below, above = split_by_plane(b, [1, 0, 0], 1e-3, tol=1e-2)
    assert below is None and above.volume == b.volume
    below, above = split_by_plane(b, [1, 0, 0], 1 - 1e-3, tol=1e-2)
    assert above is None and below.volume == b.volume
    # An inclined plane clipping a corner less than tol deep (along the normal) is ignored too.
    n = np.ones(3) / np.sqrt(3)
    below, above = split_by_plane(b, n, n @ np.ones(3) - 5e-3, tol=1e-2)
    assert above is None
    below, above = split_by_plane(b, [1, 0, 0], 1e-3, tol=1e-4)
    assert below.volume == pytest.approx(1e-3, rel=1e-10)


def test_face_tags_inherited_and_set():
    b = box([0, 0, 0], [2, 2, 2]).with_face_tag([10, 11, 12, 13, 14, 15])
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    below, above = split_by_plane(b, n, 2.0, tag=7)
    for piece in (below, above):
        for f in range(piece.n_faces):
            k = plane_match(piece, f, b.normals, b.offsets)
            on_cut = plane_match(piece, f, [n, -n], [2.0, -2.0]) >= 0
            assert (k >= 0) != on_cut  # each face lies on exactly one parent face or the cut
            assert piece.face_tag[f] == (7 if on_cut else b.face_tag[k])
    # A second cut keeps the first cut's tag on what is left of that face.
    lo2, hi2 = split_by_plane(above, [0, 0, 1], 1.5, tag=8)
    for piece in (lo2, hi2):
        tags = dict(zip(map(tuple, np.round(piece.normals, 12)), piece.face_tag.tolist(), strict=True))
        assert tags.get(tuple(np.round(-n, 12))) in (7, None)
        assert 8 in piece.face_tag.tolist() and set(piece.face_tag.tolist()) <= {7, 8, 10, 11, 12, 13, 14, 15}
    # Untagged parents give UNTAGGED on inherited faces; rigid motions keep tags.
    below, _ = split_by_plane(box([0, 0, 0], [1, 1, 1]), [1, 0, 0], 0.5, tag=3)
    assert sorted(below.face_tag.tolist()) == [UNTAGGED] * 5 + [3]
    moved = below.transformed(rotation(1), [1, 2, 3])
    np.testing.assert_array_equal(moved.face_tag, below.face_tag)


def test_hull_fallback_agrees_with_face_clipping():
    poly = random_block(3).with_face_tag(np.arange(6))
    n = np.array([0.3, -0.5, 0.8])
    n /= np.linalg.norm(n)
    d = float(n @ poly.centroid)
    s = poly.vertices @ n - d
    side = np.sign(s).astype(np.int64)
    e = poly.edges
    x_edge = np.full((len(e), 3), np.nan)
    cr = side[e[:, 0]] * side[e[:, 1]] < 0
    a, b = e[cr, 0], e[cr, 1]
    t = s[a] / (s[a] - s[b])
    x_edge[cr] = poly.vertices[a] + t[:, None] * (poly.vertices[b] - poly.vertices[a])
    points = np.concatenate([poly.vertices, x_edge])
    cut = _Cut(poly, side, points, e[:, 0] * poly.n_vertices + e[:, 1], 1e-12, 5)
    direct, hull = cut._clip_faces(side, n, d), cut._clip_hull(side, n, d)
    assert hull.volume == pytest.approx(direct.volume, rel=1e-12)

    def planes_and_tags(p):
        return sorted(zip(np.round(p.offsets, 9).tolist(), p.face_tag.tolist(), strict=True))

    assert planes_and_tags(hull) == planes_and_tags(direct)


def test_with_face_tag_validates():
    b = box([0, 0, 0], [1, 1, 1])
    with pytest.raises(GeometryError):
        b.with_face_tag([1, 2, 3])
    with pytest.raises(GeometryError):
        b.with_face_tag(np.zeros(6))
    assert b.face_tag is None and not b.with_face_tag(np.arange(6)).face_tag.flags.writeable


# ---------------------------------------------------------------------------- joint sets on blocks
def test_three_orthogonal_sets_closed_form():
    b = box([0, 0, 0], [4, 3, 2])
    o = np.array([0.5, 0.25, 0.5])
    bounds = ([0, 0, 0], [4, 3, 2])
    pieces, parent = [b], np.zeros(1, dtype=np.int64)
    for tag, (dip, dd) in enumerate([(90, 90), (90, 0), (0, 0)]):
        n, d = joint_set_planes(dip, dd, o, spacing=1.0, bounds=bounds)
        pieces, par = cut_blocks(pieces, tag, n, d)
        parent = parent[par]
    wx, wy, wz = [0.5, 1, 1, 1, 0.5], [0.25, 1, 1, 0.75], [0.5, 1, 0.5]
    assert len(pieces) == 5 * 4 * 3 and np.all(parent == 0)
    expected = sorted(x * y * z for x in wx for y in wy for z in wz)
    np.testing.assert_allclose(sorted(p.volume for p in pieces), expected, rtol=1e-12)
    for p in pieces:
        assert p.n_faces == 6 and p.n_vertices == 8
        # every face is either on the parent's surface (untagged) or on its set's planes
        for f in range(p.n_faces):
            axis = int(np.argmax(np.abs(p.normals[f])))
            on_surface = plane_match(p, f, b.normals, b.offsets) >= 0
            assert p.face_tag[f] == (UNTAGGED if on_surface else axis)


def test_inclined_set_tiles_parent():
    poly = random_block(4)
    lo, hi = poly.vertices.min(axis=0), poly.vertices.max(axis=0)
    n, d = joint_set_planes(35, 200, poly.centroid, spacing=0.37, bounds=(lo, hi))
    pieces, parent = cut_blocks([poly], 2, n, d)
    assert len(pieces) > 3 and np.all(parent == 0)
    assert_tiles(poly, pieces)
    # Ordered along the normal, consecutive slabs separated by a joint plane.
    proj = [(p.vertices @ n).min() for p in pieces]
    assert proj == sorted(proj)
    for p, q in zip(pieces, pieces[1:], strict=False):
        assert (p.vertices @ n).max() <= (q.vertices @ n).min() + 1e-12 * np.abs(poly.vertices).max()
    # A second, crossing set still tiles.
    n2, d2 = joint_set_planes(70, 80, poly.centroid, spacing=0.5, bounds=(lo, hi))
    pieces2, _ = cut_blocks(pieces, 3, n2, d2)
    assert_tiles(poly, pieces2, seed=1)


def test_cut_blocks_order_select_and_names():
    a = box([0, 0, 0], [1, 1, 1])
    b = box([5, 0, 0], [7, 1, 1])
    c = box([0, 0, 5], [3, 1, 6])
    n, d = np.array([1.0, 0.0, 0.0]), [6.5, 0.5, 2.5, 5.5, 6.0]  # any order
    pieces, parent = cut_blocks([a, b, c], [1, 2, 3, 4, 5], n, d, select=[True, True, False])
    assert parent.tolist() == [0, 0, 1, 1, 1, 1, 2]
    assert [p.volume for p in pieces] == pytest.approx([0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 3.0])
    xs = [p.centroid[0] for p in pieces[2:6]]
    assert xs == sorted(xs)  # pieces of a parent in increasing normal . x
    assert pieces[6] is not c and pieces[6].volume == c.volume  # unselected: whole, tagged
    # per-plane tags follow their planes through the sort
    assert pieces[0].face_tag.tolist().count(2) == 1 and pieces[2].face_tag.tolist().count(4) == 1
    assert piece_names(["A", "B", "C"], parent) == ["A[0]", "A[1]", "B[0]", "B[1]", "B[2]", "B[3]", "C[0]"]
    again, parent2 = cut_blocks([a, b, c], [1, 2, 3, 4, 5], n, d, select=lambda p: p.volume < 3)
    assert parent2.tolist() == parent.tolist()
    assert all(np.array_equal(p.vertices, q.vertices) for p, q in zip(pieces, again, strict=True))
    with pytest.raises(GeometryError):
        cut_blocks([a], [1, 2], n, d)


# ---------------------------------------------------------------------------- excavation
def test_cylinder_planes_closed_form():
    start, end, r, sides = np.array([0.2, -1.0, 0.3]), np.array([1.0, 3.0, 0.8]), 0.7, 10
    N, D = cylinder_planes(start, end, r, sides)
    prism_ = from_planes(N, D)
    length = np.linalg.norm(end - start)
    assert prism_.volume == pytest.approx(r**2 * sides * np.sin(2 * np.pi / sides) / 2 * length, rel=RTOL)
    a = (end - start) / length
    radial = prism_.vertices - start - np.outer((prism_.vertices - start) @ a, a)
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), r, rtol=1e-12)  # corners on the circle


@pytest.mark.parametrize("sides", [3, 8, 16])
def test_cylinder_excavation_removes_prism_volume(sides):
    b = box([-3, -3, -3], [4, 3, 3])
    start, end, r = np.array([-1.0, 0.2, -0.1]), np.array([2.0, -0.4, 0.5]), 1.1
    pieces, removed = excavate(b, cylinder_planes(start, end, r, sides), tag=42)
    expected = r**2 * sides * np.sin(2 * np.pi / sides) / 2 * np.linalg.norm(end - start)
    assert removed == pytest.approx(expected, rel=RTOL)
    assert sum(p.volume for p in pieces) == pytest.approx(b.volume - expected, rel=RTOL)
    assert len(pieces) == sides + 2
    N, D = cylinder_planes(start, end, r, sides)
    for p in pieces:
        assert_piece_ok(p, b.volume)
        # separating plane: each piece is outside one of the prism's planes
        assert np.any((p.vertices @ N.T - D).min(axis=0) >= -1e-12)
        assert 42 in p.face_tag.tolist()


def test_tunnel_through_block_and_edge_cases():
    b = box([0, 0, 0], [2, 2, 2])
    # A tunnel crossing the whole block: the caps are outside, only the sides cut.
    pieces, removed = excavate(b, cylinder_planes([-1, 1, 1], [3, 1, 1], 0.5, 6))
    assert len(pieces) == 6
    assert removed == pytest.approx(0.25 * 6 * np.sin(np.pi / 3) / 2 * 2, rel=RTOL)
    # Region beside the block, overlapping its slab in x but not the block: block untouched.
    pieces, removed = excavate(b, box_planes([1, 3, 0.5], [5, 4, 1.5]))
    assert removed == 0.0 and len(pieces) == 1 and np.array_equal(pieces[0].vertices, b.vertices)
    # Block fully inside the region vanishes.
    pieces, removed = excavate(b, box_planes([-1, -1, -1], [3, 3, 3]))
    assert pieces == [] and removed == pytest.approx(8.0, rel=RTOL)
    # Region touching a face only: nothing removed.
    pieces, removed = excavate(b, box_planes([2, 0, 0], [3, 1, 1]))
    assert removed == 0.0 and len(pieces) == 1


def test_excavate_region_given_as_polyhedron():
    b = box([-3, -3, -3], [4, 3, 3])
    planes = cylinder_planes([-1, 0.2, -0.1], [2, -0.4, 0.5], 1.1, 9)
    pieces, removed = excavate(b, planes)
    pieces2, removed2 = excavate(b, from_planes(*planes))
    assert removed2 == pytest.approx(removed, rel=RTOL) and len(pieces2) == len(pieces)


def test_box_excavation_corner_only_active_planes():
    b = box([0, 0, 0], [2, 2, 2])
    pieces, removed = excavate(b, box_planes([1, 1.5, -1], [5, 5, 0.5]), tag=1)
    assert removed == pytest.approx(1 * 0.5 * 0.5, rel=RTOL)
    assert len(pieces) == 3  # only the three planes bounding the overlap cut the block
    assert_tiles_outside(b, pieces, removed)


def assert_tiles_outside(parent, pieces, removed):
    assert sum(p.volume for p in pieces) + removed == pytest.approx(parent.volume, rel=RTOL)


def test_excavate_blocks_many():
    blocks = [box([i, 0, 0], [i + 1, 1, 1]) for i in range(4)]
    pieces, parent, removed = excavate_blocks(blocks, box_planes([0.5, 0.25, 0.25], [2.5, 0.75, 0.75]))
    np.testing.assert_allclose(removed, [0.125, 0.25, 0.125, 0.0], rtol=1e-12)
    assert parent.tolist() == sorted(parent.tolist()) and parent[-1] == 3
    assert np.bincount(parent).tolist() == [5, 4, 5, 1]


@pytest.mark.parametrize("seed", range(6))
def test_clip_below_is_split_by_planes_below_piece(seed):
    """Clipping by a half-space gives the very ``below`` piece of the split (vertices, faces,
    tags, volume: the same bits), whole blocks and misses included."""
    poly = random_block(seed)
    rng = np.random.default_rng(100 + seed)
    c = poly.vertices.mean(axis=0)
    for k in range(8):
        n = rng.normal(size=3)
        s = (poly.vertices - c) @ (n / np.linalg.norm(n))
        d = float(np.linalg.norm(n) * (n / np.linalg.norm(n)) @ c) + np.linalg.norm(n) * \
            (s.min() - 0.1 + (s.max() - s.min() + 0.2) * k / 7)
        below, _ = split_by_plane(poly, n, d, 0.01, tag=3)
        clipped = clip_below(poly, n, d, 0.01, tag=3)
        assert (below is None) == (clipped is None)
        if below is not None:
            assert np.array_equal(below.vertices, clipped.vertices)
            for k in ("face_start", "face_verts", "normals", "offsets", "face_tag", "centroid",
                      "inertia"):
                assert np.array_equal(getattr(below, k), getattr(clipped, k)), k
            assert below.volume == clipped.volume


def test_compiled_cut_points_are_numpys_bit_for_bit():
    """The plane cut's sides, intersection points and edge keys, compiled
    (``_cut_points``), are the numpy expressions they replace, bit for bit: on random blocks
    and planes, with vertices on the plane within the snap distance (side 0) and without."""
    from pdem.geometry.cutting import _cut_points

    rng = np.random.default_rng(11)
    crossed = touched = 0
    for k in range(40):
        poly = random_block(k)
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        d = float(n @ poly.vertices[k % poly.n_vertices]) if k % 2 else float(n @ poly.centroid)
        s = poly.vertices @ n - d
        snap = 1e-9
        side = np.where(s > snap, 1, np.where(s < -snap, -1, 0)).astype(np.int64)
        e = poly.edges
        cr = side[e[:, 0]] * side[e[:, 1]] < 0
        a, b = e[cr, 0], e[cr, 1]
        t = s[a] / (s[a] - s[b])
        x_edge = np.full((len(e), 3), np.nan)
        x_edge[cr] = poly.vertices[a] + t[:, None] * (poly.vertices[b] - poly.vertices[a])
        got_side, got_points, got_key = _cut_points(poly.vertices, e, s, snap)
        assert np.array_equal(got_side, side)
        assert np.array_equal(got_points, np.concatenate([poly.vertices, x_edge]),
                              equal_nan=True)
        assert np.array_equal(got_key, e[:, 0] * poly.n_vertices + e[:, 1])
        crossed += int(cr.any())
        touched += int((side == 0).any())
    assert crossed > 30 and touched >= 20  # the cases exist: cuts, and vertices on the plane


def test_a_fresh_piece_is_checked_as_any_other():
    """``from_csr(..., fresh=True)`` (a cut piece's arrays, kept instead of copied) refuses
    what the copying path refuses, with the same messages, and gives the same polyhedron
    with read-only arrays."""
    from pdem.geometry.polyhedron import ConvexPolyhedron

    b = box([0, 0, 0], [1, 2, 3])

    def arrays(fv=None, fs=None):
        return (np.array(b.vertices), np.array(b.face_start if fs is None else fs),
                np.array(b.face_verts if fv is None else fv), np.array(b.normals),
                np.array(b.offsets))

    for bad in (dict(fv=np.where(b.face_verts == 3, 8, b.face_verts)),
                dict(fv=np.where(b.face_verts == 3, -1, b.face_verts)),
                dict(fs=b.face_start[[0, 1, 2, 3, 6]], fv=b.face_verts[:b.face_start[3]]),
                dict(fs=np.array([0, 2, 4, 6, 8, 10, 12]), fv=b.face_verts[:12]),
                dict(fv=b.face_verts[::-1].copy())):
        messages = []
        for fresh in (False, True):
            with pytest.raises(GeometryError) as err:
                ConvexPolyhedron.from_csr(*arrays(**bad), fresh=fresh)
            messages.append(str(err.value))
        assert messages[0] == messages[1]
    kept = ConvexPolyhedron.from_csr(*arrays(), fresh=True)
    copied = ConvexPolyhedron.from_csr(*arrays())
    for k in ("vertices", "face_start", "face_verts", "normals", "offsets", "edges",
              "centroid", "inertia"):
        assert np.array_equal(getattr(kept, k), getattr(copied, k))
        assert not getattr(kept, k).flags.writeable
    assert kept.volume == copied.volume
