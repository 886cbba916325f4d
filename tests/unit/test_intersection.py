"""The compiled half-space intersection volume (pdem.geometry.intersection) and the touch area
sliver joining reads from it (pdem.model.rockmass.touch_area), against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdem.geometry import GeometryError, box, convex_hull
from pdem.geometry.cutting import split_by_plane
from pdem.geometry.intersection import halfspace_volume
from pdem.model.rockmass import touch_area


def _volume_of_planes(poly, shift=0.0):
    lo, hi = poly.vertices.min(axis=0), poly.vertices.max(axis=0)
    m = float((hi - lo).max())
    return halfspace_volume(np.asarray(poly.normals), np.asarray(poly.offsets) + shift,
                            lo - m, hi + m)


points = st.lists(st.tuples(*[st.floats(-1.0, 1.0)] * 3), min_size=5, max_size=30)


@settings(max_examples=80, deadline=None)
@given(points, st.floats(-1e4, 1e4))
def test_a_box_cut_by_a_polyhedrons_planes_has_its_volume(pts, shift):
    try:
        poly = convex_hull(np.array(pts) + shift)
    except GeometryError:  # degenerate draws: nothing to compare
        return
    size = float(np.ptp(poly.vertices, axis=0).max())
    assert _volume_of_planes(poly) == pytest.approx(poly.volume, rel=1e-9,
                                                    abs=1e-12 * size**3 + 1e-13 * abs(shift)**2)


def test_empty_and_whole_regions():
    cube = box([0, 0, 0], [1, 1, 1])
    assert _volume_of_planes(cube) == pytest.approx(1.0, rel=1e-14)
    # a plane that misses the box keeps all of it; one beyond it leaves nothing
    n = np.array([[0.0, 0.0, 1.0]])
    assert halfspace_volume(n, np.array([5.0]), np.zeros(3), np.ones(3)) == pytest.approx(1.0)
    assert halfspace_volume(n, np.array([-1.0]), np.zeros(3), np.ones(3)) == 0.0
    # two opposite half-spaces a slab apart, and crossing ones that leave nothing
    slab = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    assert halfspace_volume(slab, np.array([0.6, -0.4]), np.zeros(3), np.ones(3)) == \
        pytest.approx(0.2, rel=1e-12)
    assert halfspace_volume(slab, np.array([0.4, -0.6]), np.zeros(3), np.ones(3)) == 0.0
    # a plane through a face of the box (coplanar): the box stays whole
    assert halfspace_volume(n, np.array([1.0]), np.zeros(3), np.ones(3)) == pytest.approx(1.0)


@pytest.mark.parametrize(("b_min", "b_max", "area"), [
    ((1, 0, 0), (2, 1, 1), 1.0),  # face to face
    ((1, 0.5, 0), (2, 1.5, 1), 0.5),  # half the face
    ((1, 1, 0), (2, 2, 1), 0.0),  # an edge only (2 eps wide: ~1e-6)
    ((1, 1, 1), (2, 2, 2), 0.0),  # a corner only
    ((1.5, 0, 0), (2.5, 1, 1), 0.0),  # apart
])
def test_touch_area_of_two_boxes(b_min, b_max, area):
    """Within 1e-5: the pieces grown by eps = 1e-6 of their size also overlap along the shared
    face's rim, O(eps x perimeter)."""
    a = box([0, 0, 0], [1, 1, 1])
    b = box(b_min, b_max)
    assert touch_area(a, b) == pytest.approx(area, abs=1e-5)
    assert touch_area(b, a) == pytest.approx(area, abs=1e-5)


def test_touch_area_across_an_oblique_cut():
    """The two pieces of a unit cube cut by x + y + z = 1.5 share the cut's hexagon, of area
    (3 sqrt 3 / 4) for that plane through the centre."""
    below, above = split_by_plane(box([0, 0, 0], [1, 1, 1]), [1, 1, 1], 1.5)
    assert touch_area(below, above) == pytest.approx(3 * np.sqrt(3) / 4, rel=1e-5)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 20), st.integers(0, 20), st.integers(0, 20),
                          st.integers(1, 3), st.integers(1, 3), st.integers(1, 30)),
                min_size=1, max_size=60),
       st.tuples(st.integers(-2, 22), st.integers(-2, 22), st.integers(-2, 22),
                 st.integers(0, 4)))
def test_box_query_finds_every_meeting_box(boxes, query):
    """Sliver joining's neighbour search (rockmass._BoxQuery) is the test of every box:
    integer corners, so touching boxes (the pieces of a cut) are exact ties, and a few boxes
    much wider than the rest (a base block)."""
    from pdem.model.rockmass import _BoxQuery

    lo = np.array([b[:3] for b in boxes], float)
    hi = lo + np.array([[b[5], b[3], b[4]] for b in boxes], float)
    qlo = np.array(query[:3], float)
    qhi = qlo + query[3]
    every = np.flatnonzero(np.all((lo <= qhi) & (hi >= qlo), axis=1))
    assert _BoxQuery(lo, hi).meeting(qlo, qhi).tolist() == every.tolist()
