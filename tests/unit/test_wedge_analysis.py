"""Limit equilibrium of a rock wedge (pdem.analysis.wedge) against closed forms that the test
computes on its own: Hoek & Bray's wedge factor, planar sliding, a published worked example
and a brute-force 3x3 force balance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pdem.analysis.wedge import (
    bolted_wedge_factor_of_safety,
    critical_friction,
    intersection_line,
    normal_reactions,
    wedge_factor_of_safety,
)
from pdem.geometry.cutting import dip_normal
from pdem.geometry.errors import GeometryError

DOWN = np.array([0.0, 0.0, -1.0])
SETTINGS = settings(max_examples=300, deadline=None)

dips = st.floats(5.0, 85.0)
azimuths = st.floats(0.0, 360.0, exclude_max=True)
phis = st.floats(1.0, 60.0)


def normal(dip: float, dd: float) -> np.ndarray:
    """Upward normal, written out here rather than taken from pdem."""
    d, a = math.radians(dip), math.radians(dd)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def down_line(n1: np.ndarray, n2: np.ndarray) -> np.ndarray:
    d = np.cross(n1, n2)
    d /= np.linalg.norm(d)
    return -d if d[2] > 0.0 else d


def hoek_bray_k(dip1, dd1, dip2, dd2) -> tuple[float, float, float]:
    """(K, beta, xi) of Hoek & Bray's wedge factor ``K = sin(beta) / sin(xi / 2)`` from the
    cross-section normal to the line of intersection: xi = included angle of the wedge, beta =
    angle between the horizontal of that section and the wedge's bisector."""
    n1, n2 = normal(dip1, dd1), normal(dip2, dd2)
    d = down_line(n1, n2)
    xi = math.pi - math.acos(float(n1 @ n2))
    bisector = (n1 + n2) / np.linalg.norm(n1 + n2)  # into the wedge, in the section
    w_perp = DOWN - (DOWN @ d) * d
    u = w_perp / np.linalg.norm(w_perp)  # "straight down" within the section
    beta = math.asin(min(1.0, float(-bisector @ u)))
    return math.sin(beta) / math.sin(xi / 2.0), beta, xi


def brute_force(dip1, dd1, phi1, dip2, dd2, phi2) -> tuple[float, float, float]:
    """Solve ``N1 n1 + N2 n2 - F s + W = 0`` (3 equations, 3 unknowns; W = -z, s down the line)
    and return (N1, N2, fs = (N1 tan phi1 + N2 tan phi2) / F)."""
    n1, n2 = normal(dip1, dd1), normal(dip2, dd2)
    s = down_line(n1, n2)
    n1_, n2_, f = np.linalg.solve(np.column_stack([n1, n2, -s]), -DOWN)
    fs = (n1_ * math.tan(math.radians(phi1)) + n2_ * math.tan(math.radians(phi2))) / f
    return float(n1_), float(n2_), float(fs)


# --------------------------------------------------------------------------- intersection line
def test_intersection_line_of_symmetric_planes_is_the_apparent_dip():
    plunge, trend, d = intersection_line(60.0, 45.0, 60.0, 315.0)
    # apparent dip of either plane along north, 45 degrees off its dip direction
    assert plunge == pytest.approx(math.degrees(math.atan(math.tan(math.radians(60)) * math.cos(
        math.radians(45)))), abs=1e-12)
    assert trend == pytest.approx(0.0, abs=1e-12)
    assert d[2] < 0.0 and np.linalg.norm(d) == pytest.approx(1.0)


@SETTINGS
@given(dips, azimuths, dips, azimuths)
def test_intersection_line_lies_in_both_planes_and_points_down(dip1, dd1, dip2, dd2):
    n1, n2 = normal(dip1, dd1), normal(dip2, dd2)
    assume(np.linalg.norm(np.cross(n1, n2)) > 1e-3)
    plunge, trend, d = intersection_line(dip1, dd1, dip2, dd2)
    assert abs(d @ n1) < 1e-12 and abs(d @ n2) < 1e-12
    assert d[2] <= 0.0 and 0.0 <= plunge <= 90.0 and 0.0 <= trend < 360.0
    # plunge and trend rebuild d
    p, t = math.radians(plunge), math.radians(trend)
    np.testing.assert_allclose(d, [math.cos(p) * math.sin(t), math.cos(p) * math.cos(t), -math.sin(p)],
                               atol=1e-9)
    # the order of the planes does not matter
    p2, t2, d2 = intersection_line(dip2, dd2, dip1, dd1)
    np.testing.assert_allclose(d2, d, atol=1e-12)


def test_horizontal_line_and_parallel_planes():
    plunge, trend, d = intersection_line(45.0, 90.0, 45.0, 270.0)  # ridge along north-south
    assert plunge == pytest.approx(0.0, abs=1e-12)
    assert trend == pytest.approx(0.0, abs=1e-12)
    fs, mode = wedge_factor_of_safety(45.0, 90.0, 10.0, 45.0, 270.0, 10.0)
    assert (fs, mode) == (math.inf, "stable")
    assert critical_friction(45.0, 90.0, 45.0, 270.0) == 0.0
    with pytest.raises(GeometryError, match="parallel"):
        intersection_line(30.0, 120.0, 30.0, 120.0)


# --------------------------------------------------------------------------- Hoek & Bray K
@pytest.mark.parametrize("dip, half, trend, phi", [
    (60.0, 45.0, 0.0, 30.0), (50.0, 30.0, 135.0, 25.0), (70.0, 60.0, 250.0, 35.0),
    (40.0, 20.0, 300.0, 15.0),
])
def test_symmetric_wedge_matches_the_wedge_factor(dip, half, trend, phi):
    dd1, dd2 = trend - half, trend + half
    k, beta, xi = hoek_bray_k(dip, dd1, dip, dd2)
    assert beta == pytest.approx(math.pi / 2, abs=1e-7)  # symmetric: the bisector is vertical
    plunge, trend_, _ = intersection_line(dip, dd1, dip, dd2)
    assert trend_ == pytest.approx(trend % 360.0, abs=1e-9)
    fs, mode = wedge_factor_of_safety(dip, dd1, phi, dip, dd2, phi)
    assert mode == "both"
    expected = k * math.tan(math.radians(phi)) / math.tan(math.radians(plunge))
    assert fs == pytest.approx(expected, rel=1e-12)


@SETTINGS
@given(dips, azimuths, dips, azimuths, phis)
def test_any_wedge_on_both_planes_matches_the_wedge_factor(dip1, dd1, dip2, dd2, phi):
    n1, n2 = normal(dip1, dd1), normal(dip2, dd2)
    assume(np.linalg.norm(np.cross(n1, n2)) > 1e-2)
    r1, r2, driving = normal_reactions(dip1, dd1, dip2, dd2)
    assume(r1 > 1e-6 and r2 > 1e-6 and driving > 1e-3)
    k, _, _ = hoek_bray_k(dip1, dd1, dip2, dd2)
    plunge = math.asin(-down_line(n1, n2)[2])
    fs, mode = wedge_factor_of_safety(dip1, dd1, phi, dip2, dd2, phi)
    assert mode == "both"
    assert fs == pytest.approx(k * math.tan(math.radians(phi)) / math.tan(plunge), rel=1e-9)


# --------------------------------------------------------------------------- published example
def test_published_example_explicit_3d_dda():
    """Example 1 of the explicit 3-D DDA paper (shared/reference/explicit-3d-dda-fast-common-
    plane.txt, section 6.1): joints A 45/005 and B 55/135, no cohesion, phi = 25 deg on both;
    "the analytical solution for this problem estimates the factor of safety to be 1.302"."""
    fs, mode = wedge_factor_of_safety(45.0, 5.0, 25.0, 55.0, 135.0, 25.0)
    assert mode == "both"
    assert fs == pytest.approx(1.302, abs=5e-4)
    # the same numbers the verification case pdem.cases.wedge derives (tests/verification/test_wedge.py)
    plunge, _, _ = intersection_line(45.0, 5.0, 55.0, 135.0)
    assert plunge == pytest.approx(26.36, abs=5e-3)
    assert critical_friction(45.0, 5.0, 55.0, 135.0) == pytest.approx(19.71, abs=5e-3)


# --------------------------------------------------------------------------- lift-off, free fall
@pytest.mark.parametrize("phi", [10.0, 30.0, 45.0])
def test_steep_plane_lifts_off_and_the_wedge_slides_on_the_other(phi):
    # plane 2 dips steeply roughly the same way as plane 1: sliding down plane 1 moves away from it
    fs, mode = wedge_factor_of_safety(30.0, 0.0, phi, 80.0, 300.0, 5.0)
    assert mode == "plane1"
    assert fs == pytest.approx(math.tan(math.radians(phi)) / math.tan(math.radians(30.0)), rel=1e-12)
    fs2, mode2 = wedge_factor_of_safety(80.0, 300.0, 5.0, 30.0, 0.0, phi)
    assert (fs2, mode2) == (pytest.approx(fs, rel=1e-15), "plane2")
    assert critical_friction(30.0, 0.0, 80.0, 300.0) == pytest.approx(30.0, abs=1e-12)


def test_gravity_pulling_off_both_planes_is_free_fall():
    fs, mode = wedge_factor_of_safety(45.0, 5.0, 25.0, 55.0, 135.0, 25.0, gravity=(0.0, 0.0, 1.0))
    assert (fs, mode) == (0.0, "free")
    assert math.isnan(critical_friction(45.0, 5.0, 55.0, 135.0, gravity=(0.0, 0.0, 1.0)))


def test_gravity_magnitude_does_not_matter_and_bad_input_is_refused():
    a = wedge_factor_of_safety(45.0, 5.0, 25.0, 55.0, 135.0, 30.0)
    b = wedge_factor_of_safety(45.0, 5.0, 25.0, 55.0, 135.0, 30.0, gravity=(0.0, 0.0, -9.81))
    assert a[1] == b[1] and a[0] == pytest.approx(b[0], rel=1e-15)
    with pytest.raises(GeometryError):
        wedge_factor_of_safety(45.0, 5.0, 90.0, 55.0, 135.0, 30.0)
    with pytest.raises(GeometryError):
        wedge_factor_of_safety(45.0, 5.0, 25.0, 55.0, 135.0, 30.0, gravity=(0.0, 0.0, 0.0))
    with pytest.raises(GeometryError):
        wedge_factor_of_safety(95.0, 5.0, 25.0, 55.0, 135.0, 30.0)


# --------------------------------------------------------------------------- brute force
@SETTINGS
@given(dips, azimuths, phis, dips, azimuths, phis)
def test_brute_force_force_balance(dip1, dd1, phi1, dip2, dd2, phi2):
    n1, n2 = normal(dip1, dd1), normal(dip2, dd2)
    assume(np.linalg.norm(np.cross(n1, n2)) > 1e-2)
    assume(abs(down_line(n1, n2)[2]) > 1e-3)
    r1, r2, fs_bf = brute_force(dip1, dd1, phi1, dip2, dd2, phi2)
    assume(abs(r1) > 1e-6 and abs(r2) > 1e-6)  # clear of the lift-off boundary
    fs, mode = wedge_factor_of_safety(dip1, dd1, phi1, dip2, dd2, phi2)
    if r1 > 0.0 and r2 > 0.0:
        assert mode == "both"
        assert fs == pytest.approx(fs_bf, rel=1e-9)
    elif r1 > 0.0:
        assert mode == "plane1"
        assert fs == pytest.approx(math.tan(math.radians(phi1)) / math.tan(math.radians(dip1)), rel=1e-9)
    else:
        assert r2 > 0.0  # both negative cannot happen with gravity straight down
        assert mode == "plane2"
        assert fs == pytest.approx(math.tan(math.radians(phi2)) / math.tan(math.radians(dip2)), rel=1e-9)


# --------------------------------------------------------------------------- critical friction, scaling
@SETTINGS
@given(dips, azimuths, dips, azimuths)
def test_critical_friction_gives_unit_factor_of_safety(dip1, dd1, dip2, dd2):
    n1, n2 = normal(dip1, dd1), normal(dip2, dd2)
    assume(np.linalg.norm(np.cross(n1, n2)) > 1e-2)
    assume(abs(down_line(n1, n2)[2]) > 1e-3)
    phi_c = critical_friction(dip1, dd1, dip2, dd2)
    assert 0.0 < phi_c < 90.0
    fs, mode = wedge_factor_of_safety(dip1, dd1, phi_c, dip2, dd2, phi_c)
    assert mode in ("both", "plane1", "plane2")
    assert fs == pytest.approx(1.0, abs=1e-12)


@SETTINGS
@given(dips, azimuths, dips, azimuths, phis, phis)
def test_factor_of_safety_scales_with_tan_phi(dip1, dd1, dip2, dd2, phi_a, phi_b):
    n1, n2 = normal(dip1, dd1), normal(dip2, dd2)
    assume(np.linalg.norm(np.cross(n1, n2)) > 1e-2)
    assume(abs(down_line(n1, n2)[2]) > 1e-3)
    fs_a, mode_a = wedge_factor_of_safety(dip1, dd1, phi_a, dip2, dd2, phi_a)
    fs_b, mode_b = wedge_factor_of_safety(dip1, dd1, phi_b, dip2, dd2, phi_b)
    assert mode_a == mode_b  # the mode is geometric
    ta, tb = math.tan(math.radians(phi_a)), math.tan(math.radians(phi_b))
    assert fs_a / ta == pytest.approx(fs_b / tb, rel=1e-13)


# ---------------------------------------------------------------- a bolt's force
def test_a_bolted_wedge_without_its_bolt_is_the_plain_wedge():
    for planes in ((45.0, 105.0, 70.0, 235.0), (30.0, 90.0, 80.0, 20.0), (45.0, 5.0, 55.0, 135.0)):
        a, b = planes[:2], planes[2:]
        assert bolted_wedge_factor_of_safety(*a, 30.0, *b, 25.0, 5.0e4, (0.0, 0.0, 0.0)) == \
            wedge_factor_of_safety(*a, 30.0, *b, 25.0)


@pytest.mark.parametrize("theta", [0.0, 20.0, 45.0, -10.0])
def test_a_bolted_block_on_one_plane_is_hoek_and_bray_s_planar_formula(theta):
    """A wedge that rides plane 1 alone (plane 2 dips 80/020: it lifts off it) held by a bolt
    at ``theta`` to plane 1, pointing up its dip into the rock: Hoek & Bray's planar failure
    with a bolt, ``FS = (W cos psi + T sin theta) tan phi / (W sin psi - T cos theta)``."""
    psi, phi, w, t = 30.0, 35.0, 1000.0, 300.0
    r = math.radians
    n = dip_normal(psi, 90.0)
    up = np.array([-math.cos(r(psi)), 0.0, math.sin(r(psi))])
    u = math.cos(r(theta)) * up - math.sin(r(theta)) * n
    fs, mode = bolted_wedge_factor_of_safety(psi, 90.0, phi, 80.0, 20.0, phi, w, t * u)
    want = (w * math.cos(r(psi)) + t * math.sin(r(theta))) * math.tan(r(phi)) \
        / (w * math.sin(r(psi)) - t * math.cos(r(theta)))
    assert mode == "plane1" and fs == pytest.approx(want, rel=1e-12)


def test_a_bolt_raises_the_factor_of_safety_or_lifts_the_wedge():
    """The wedge of 45/005 and 55/135 with a bolt pulling up the line of intersection: the
    factor grows with the tension, without bound as the bolt takes the driving component,
    and a bolt pulling the wedge straight off both planes leaves it free."""
    d = intersection_line(45.0, 5.0, 55.0, 135.0)[2]
    w = 1.0e5
    fs = [bolted_wedge_factor_of_safety(45.0, 5.0, 30.0, 55.0, 135.0, 30.0, w, -t * d)[0]
          for t in (0.0, 1e4, 2e4, 4e4)]
    assert all(b > a for a, b in zip(fs, fs[1:], strict=False))
    drive = w * float(np.array([0.0, 0.0, -1.0]) @ d)
    # a bolt that takes nearly all the driving component leaves friction a small load to hold
    # (beyond it, the wedge would be pulled up the line: friction resists that as well)
    fs, mode = bolted_wedge_factor_of_safety(45.0, 5.0, 30.0, 55.0, 135.0, 30.0, w,
                                             -0.99 * drive * d)
    assert mode == "both" and fs > 50.0
    assert bolted_wedge_factor_of_safety(45.0, 5.0, 30.0, 55.0, 135.0, 30.0, w,
                                         (0.0, 0.0, 2.0 * w))[1] == "free"
    with pytest.raises(GeometryError, match="weight"):
        bolted_wedge_factor_of_safety(45.0, 5.0, 30.0, 55.0, 135.0, 30.0, 0.0, (0, 0, 0))
