"""Contact region on the common plane: polygon clipping, areas, overlaps, degenerate cases."""

import numpy as np
import pytest

from pdem.contact.subcontacts import POINT, POLYGON, SEGMENT, contact_region

N = np.array([0.0, 0.0, 1.0])
P = np.zeros(3)


def box_verts(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def world(pts, e1, e2):
    return pts[:, :1] * e1 + pts[:, 1:] * e2


def test_face_face_partial_overlap_area_and_corners():
    """A 2x2 floor and a unit cube shifted half off its edge: common area 0.5 x 1."""
    va = box_verts([-1, -1, -1], [1, 1, 0])
    vb = box_verts([0.5, -0.5, -1e-4], [1.5, 0.5, 1 - 1e-4])
    pts, ovl, area, kind, e1, e2, counts = contact_region(va, vb, N, P, 1e-3)
    assert kind == POLYGON
    assert tuple(counts) == (4, 4)
    assert area.sum() == pytest.approx(0.5, rel=1e-12)
    corners = world(pts, e1, e2)
    assert sorted(map(tuple, np.round(corners[:, :2], 12))) == [
        (0.5, -0.5), (0.5, 0.5), (1.0, -0.5), (1.0, 0.5)]
    np.testing.assert_allclose(ovl, 1e-4, rtol=1e-9)


def test_tilted_face_gives_linear_overlap():
    """B's bottom face tilted about y: overlap varies linearly along x."""
    va = box_verts([-1, -1, -1], [1, 1, 0])
    slope = 1e-4
    vb = box_verts([-0.5, -0.5, 0], [0.5, 0.5, 1])
    vb[:, 2] += slope * vb[:, 0] - 1e-4  # overlap 1e-4 at x=0, 0 at x=+1
    pts, ovl, area, kind, e1, e2, _ = contact_region(va, vb, N, P, 1e-3)
    x = world(pts, e1, e2)[:, 0]
    np.testing.assert_allclose(ovl, 1e-4 - slope * x, atol=1e-15)
    assert area.sum() == pytest.approx(1.0)


def test_edge_on_face_is_a_segment():
    """A cube rotated 45 deg about x rests on an edge: two sub-contacts at the edge ends."""
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    vb = box_verts([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]) @ R.T
    vb[:, 2] -= vb[:, 2].min() + 2e-5
    va = box_verts([-2, -2, -1], [2, 2, 0])
    pts, ovl, area, kind, e1, e2, counts = contact_region(va, vb, N, P, 1e-3)
    assert kind == SEGMENT and tuple(counts) == (4, 2)
    np.testing.assert_allclose(sorted(world(pts, e1, e2)[:, 0]), [-0.5, 0.5], atol=1e-12)
    np.testing.assert_allclose(ovl, 2e-5, rtol=1e-9)


def test_vertex_on_face_is_a_point():
    apex = np.array([[0.1, 0.2, -3e-5], [1, 0, 1], [-1, 0, 1], [0, 1, 1]])
    va = box_verts([-2, -2, -1], [2, 2, 0])
    pts, ovl, _, kind, e1, e2, counts = contact_region(va, apex, N, P, 1e-3)
    assert kind == POINT and tuple(counts) == (4, 1)
    np.testing.assert_allclose(world(pts, e1, e2)[0, :2], [0.1, 0.2], atol=1e-12)
    assert ovl[0] == pytest.approx(3e-5, rel=1e-9)


def test_crossing_edges_meet_at_one_point():
    """Edge-edge: two crossed wedges' ridges; the crossing carries the gap as overlap."""
    va = np.array([[-1, 0, 0.0], [1, 0, 0.0], [-1, -1, -1], [1, -1, -1], [-1, 1, -1], [1, 1, -1]])
    vb = np.array([[0, -1, -1e-5], [0, 1, -1e-5], [-1, -1, 1], [-1, 1, 1], [1, -1, 1], [1, 1, 1]])
    pts, ovl, _, kind, e1, e2, counts = contact_region(va, vb, N, P, 1e-3)
    assert kind == POINT and tuple(counts) == (2, 2)
    np.testing.assert_allclose(world(pts, e1, e2)[0, :2], [0, 0], atol=1e-12)
    assert ovl[0] == pytest.approx(1e-5, rel=1e-9)


def _moment(pts, area, ovl):
    """Sum of area x overlap (the normal force over kn) and its first moments about the
    origin: what a joint's sub-contacts push with, and where."""
    w = area * ovl
    return np.array([w.sum(), (w * pts[:, 0]).sum(), (w * pts[:, 1]).sum()])


def test_sliver_overlap_keeps_one_sub_contact_per_end():
    """Diagonal neighbours of a settling stack: B's bottom face overlaps A's top face over a
    strip 1 m long and 5 um wide. Its four corners are two pairs 5 um apart (closer than the
    touch tolerance): two sub-contacts, one at each end, carrying the strip's area and the
    same force and moment to within the pairs' spacing."""
    w = 5e-6
    va = box_verts([0, 0, -1], [1, 1, 0])
    vb = box_verts([1 - w, 0, -2e-4], [2 - w, 1, 1 - 2e-4])
    pts, ovl, area, kind, e1, e2, counts = contact_region(va, vb, N, P, 1e-2)
    assert kind == POLYGON and tuple(counts) == (4, 4) and len(pts) == 2
    assert area.sum() == pytest.approx(w * 1.0, rel=1e-9)
    np.testing.assert_allclose(area, 0.5 * w, rtol=1e-9)
    xy = world(pts, e1, e2)[:, :2]
    np.testing.assert_allclose(sorted(xy[:, 1]), [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(xy[:, 0], 1 - w / 2, atol=1e-12)
    np.testing.assert_allclose(ovl, 2e-4, rtol=1e-9)
    # the unmerged corners (a touch tolerance below the spacing) push the same
    p4, o4, a4, _, f1, f2, _ = contact_region(va, vb, N, P, 1e-6)
    assert len(p4) == 4
    np.testing.assert_allclose(_moment(world(pts, e1, e2), area, ovl),
                               _moment(world(p4, f1, f2), a4, o4), rtol=1e-9, atol=1e-18)


def test_turned_face_keeps_corners_that_are_apart():
    """A unit cube turned 0.5 mrad about the normal on an equal face below: the overlap is an
    octagon whose corners lie near the squares' corners and edge midpoints, 0.5 m apart: none
    merges, at any turn (the touch tolerance is 1 cm)."""
    for angle in (5e-4, 0.1):
        c, s = np.cos(angle), np.sin(angle)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        va = box_verts([-0.5, -0.5, -1], [0.5, 0.5, 0])
        vb = box_verts([-0.5, -0.5, 0], [0.5, 0.5, 1]) @ R.T
        vb[:, 2] -= 1e-4
        pts, ovl, area, kind, e1, e2, _ = contact_region(va, vb, N, P, 1e-2)
        assert kind == POLYGON and len(pts) == 8, (angle, len(pts))
        p8, _, a8, _, _, _, _ = contact_region(va, vb, N, P, 1e-9)
        np.testing.assert_array_equal(pts, p8)
        np.testing.assert_array_equal(area, a8)


def test_tiny_region_is_one_sub_contact():
    """A region whose corners all lie within the touch tolerance of the next (a 1 mm square
    overlap of two corners) is one sub-contact at its centroid with its area."""
    va = box_verts([0, 0, -1], [1, 1, 0])
    vb = box_verts([1 - 1e-3, 1 - 1e-3, -1e-4], [2, 2, 1])
    pts, ovl, area, kind, e1, e2, _ = contact_region(va, vb, N, P, 1e-2)
    assert kind == POLYGON and len(pts) == 1
    assert area[0] == pytest.approx(1e-6, rel=1e-9)
    np.testing.assert_allclose(world(pts, e1, e2)[0, :2], [1 - 5e-4, 1 - 5e-4], atol=1e-12)


def _rotated(v, angle, axis):
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (0, 2), (0, 1)][axis]
    out = v.copy()
    out[:, i] = c * v[:, i] - s * v[:, j]
    out[:, j] = s * v[:, i] + c * v[:, j]
    return out


def test_one_scratch_reused_gives_each_region_as_its_own_arrays():
    """The geometry update reuses one room (RegionScratch) for every contact's region: 300
    regions of every kind (faces shifted and turned, tilted edges and corners, prisms of six
    vertices beside cubes of eight, found apart) through one scratch equal, bit for bit, the
    regions computed each in arrays of their own."""
    from pdem.contact.subcontacts import EMPTY, region_in, region_scratch

    rng = np.random.default_rng(7)
    scratch = region_scratch(8)
    floor = box_verts([-1, -1, -1], [1, 1, 0])
    prism = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], float)
    kinds = set()
    for _ in range(300):
        top = box_verts([-0.5, -0.5, 0], [0.5, 0.5, 1]) if rng.random() < 0.7 else prism - 0.3
        r = rng.random()
        if r < 0.2:  # on an edge
            top = _rotated(top, np.pi / 4 + rng.normal(0, 1e-9), 0)
        top = _rotated(top, rng.normal(0, 0.3), 2)
        if 0.2 <= r < 0.5:  # on a corner
            top = _rotated(_rotated(top, rng.normal(0, 0.5), 0), rng.normal(0, 0.5), 1)
        top = top + [rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5), 0.0]
        top[:, 2] += -top[:, 2].min() + rng.uniform(-1e-3, 1e-3)
        tol = 10.0 ** rng.uniform(-6, -2)
        want = contact_region(floor, top, N, P, tol)
        pts, ovl, area, kind, e, counts = region_in(floor, top, N, P, tol, scratch)
        kinds.add(kind)
        assert kind == want[3]
        for got, ref in ((pts, want[0]), (ovl, want[1]), (area, want[2]), (counts, want[6]),
                         (np.array(e[:3]), want[4]), (np.array(e[3:]), want[5])):
            assert got.shape == ref.shape and np.array_equal(got, ref)
    assert kinds == {EMPTY, POINT, SEGMENT, POLYGON}
