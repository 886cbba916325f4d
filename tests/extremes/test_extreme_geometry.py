"""Sizes, shapes and places at the extremes (issue 10): a 1 cm cube among 1 m blocks (size
ratio 1:100, mass ratio 1e6), slabs and columns of aspect 1:100, and models far from the
origin (mine-grid coordinates, 1e6 m). Every block must rest at its closed-form static overlap
``m g / (kn A) = rho c g / kn`` without drift or spurious rotation.
"""

from __future__ import annotations

import numpy as np
import pytest

from pdem.cases import make_simulation, vec
from pdem.cases.extremes import RHO, G, box_on_floor, incline_gravity, sliding_acceleration, static_overlap

KN = 1.0e9
EPS = np.finfo(float).eps  # 2.2e-16


def _box(name, lo, hi, fixed=False):
    return (f"  - {{name: {name}, material: rock, fixed: {str(fixed).lower()}, "
            f"box: {{min: {vec(lo)}, max: {vec(hi)}}}}}\n")


def test_centimetre_cube_among_metre_blocks():
    """Two 1 m cubes on the floor, 10 cm apart; one 1 cm cube (1e-6 of their mass) on top of
    the first, another on the floor between them, every block started at its static overlap
    (the small ones m g / (kn A) = 1.962e-7 m, the loaded big one (M + m) g / (kn A)), local
    damping. The step is set by the 2 g cube against the big blocks' stiffness (dt = 2e-7 s,
    a small cube's contact period is 4400 steps, settling from touching would take ~20 000):
    over 3000 steps (0.6 ms) every overlap stays within 1 % of its closed form, nothing drifts
    sideways by more than 1e-3 of the small overlap, nothing turns or moves (< 1e-5 m/s)."""
    M, m = RHO * 1.0, RHO * 1e-6
    d_big = (M + m) * G / KN  # the first big cube carries the small one
    d_other = M * G / KN
    s = 0.01
    small = static_overlap(s, KN)
    extra = (_box("big2", (0.05, -0.5, -d_other), (1.05, 0.5, 1.0 - d_other))
             + _box("top", (-0.55 - s / 2, -s / 2, 1.0 - d_big - small),
                    (-0.55 + s / 2, s / 2, 1.0 - d_big - small + s))
             + _box("beside", (-s / 2, -s / 2, -small), (s / 2, s / 2, s - small)))
    text = box_on_floor((1.0, 1.0, 1.0), origin=(-0.55, 0.0, 0.0), name="big1", kn=KN,
                        damping="local", end="steps: 3000", extra_blocks=extra, floor=(6.0, 4.0))
    sim = make_simulation(text)
    b = sim.blocks
    rows = {sim.specs[g].name: r for r, g in enumerate(b.gid[:sim.n_owned])}
    x0 = b.x.copy()
    sim.run()
    top, big1 = rows["top"], rows["big1"]
    # the small cube's overlap into the big one's top face, wherever that is now
    assert b.x[big1, 2] + 0.5 + s / 2 - b.x[top, 2] == pytest.approx(small, rel=1e-2)
    beside = rows["beside"]
    assert s / 2 - b.x[beside, 2] == pytest.approx(small, rel=1e-2)
    assert 0.5 - b.x[rows["big1"], 2] == pytest.approx(d_big, rel=1e-2)
    assert 0.5 - b.x[rows["big2"], 2] == pytest.approx(d_other, rel=1e-2)
    free = b.fixed[:sim.n_owned] == 0
    assert np.abs(b.x[:sim.n_owned][free, :2] - x0[:sim.n_owned][free, :2]).max() < 1e-3 * small
    assert np.abs(b.w[:sim.n_owned]).max() < 1e-6  # rad/s
    assert np.abs(b.v[:sim.n_owned]).max() < 1e-5  # m/s


def test_thin_slab_settles_flat():
    """A 10 m x 10 m x 0.1 m slab (aspect 1:100) dropped from touching with local damping:
    it settles at rho c g / kn = 1.962e-6 m (1e-3), does not move sideways and does not turn
    (no rocking from the 4-vertex face contact)."""
    sim = make_simulation(box_on_floor((10.0, 10.0, 0.1), gap=0.0, damping="local", kn=KN,
                                       end="ratio: 1.0e-6, max_steps: 5000"))
    b = sim.blocks
    x0, q0 = b.x[1].copy(), b.q[1].copy()
    sim.run()
    assert sim.step < 5000
    assert 0.05 - b.x[1, 2] == pytest.approx(static_overlap(0.1, KN), rel=1e-3)
    assert np.abs(b.x[1, :2] - x0[:2]).max() < 1e-12
    assert np.abs(b.q[1] - q0).max() < 1e-12 and np.abs(b.w[1]).max() < 1e-9


def test_slender_column_stands():
    """A 0.1 x 0.1 x 10 m column (aspect 1:100) standing on the floor, started at its static
    overlap rho c g / kn = 1.962e-4 m, undamped, for 3000 steps (the rotational step bound of
    its 5 m radius makes dt = 6.3e-7 s): it stays there (1e-3), does not tip (its top moves
    less than 1e-9 m sideways) and does not turn."""
    sim = make_simulation(box_on_floor((0.1, 0.1, 10.0), kn=KN, end="steps: 3000"))
    b = sim.blocks
    x0, q0 = b.x[1].copy(), b.q[1].copy()
    sim.run()
    assert 5.0 - b.x[1, 2] == pytest.approx(static_overlap(10.0, KN), rel=1e-3)
    assert np.abs(b.x[1, :2] - x0[:2]).max() < 1e-9
    assert np.abs(b.q[1] - q0).max() < 1e-12 and np.abs(b.w[1]).max() < 1e-9


ORIGINS = [(1.0e6, 1.0e6, 1.0e3), (1.0e6, 1.0e6, 1.0e6)]


@pytest.mark.parametrize("origin", ORIGINS)
@pytest.mark.parametrize("side", [1.0, 0.01])
def test_far_from_origin_rests_alike(origin, side):
    """The same cube (1 m, and 1 cm) resting on a floor at the origin and at mine-grid
    coordinates: the settled overlaps agree within 10 ulp of the coordinates
    (10 x 2.2e-16 x 1e6 = 2.2e-9 m; measured 1e-10 m for 1 m, 8e-10 m for 1 cm): the
    geometry is in world coordinates, so its error is absolute, ~1 ulp of |x|, not relative
    to the block (the 1 cm cube's 1.96e-7 m overlap is off by 0.4 % at 1e6 m)."""
    def settle(o):
        sim = make_simulation(box_on_floor((side,) * 3, origin=o, gap=0.0, damping="local",
                                           kn=KN, end="ratio: 1.0e-6, max_steps: 5000"))
        b = sim.blocks
        x0 = b.x[1].copy()
        sim.run()
        assert sim.step < 5000
        return side / 2 + o[2] - b.x[1, 2], b.x[1] - x0, np.abs(b.w[1]).max()

    d0, _, _ = settle((0.0, 0.0, 0.0))
    d, moved, w = settle(origin)
    tol = 10 * EPS * max(origin)
    assert abs(d - d0) < tol
    assert d0 == pytest.approx(static_overlap(side, KN), rel=1e-3)
    assert np.abs(moved[:2]).max() < tol and w < 1e-9


@pytest.mark.parametrize("origin", ORIGINS)
def test_far_from_origin_slides_alike(origin):
    """A cube sliding down a 20 deg incline (friction 10 deg) for 0.2 s at the origin and at
    mine-grid coordinates: the distances slid agree within 1e-6 relative (3.5e-8 m, ~300 ulp
    of 1e6 m; measured 2e-9 relative) and match the closed form g (sin psi - cos psi tan phi)
    t^2 / 2 within 2 % (the start at rest at t = 0 and a little rocking)."""
    def slide(o):
        sim = make_simulation(box_on_floor(origin=o, gravity=incline_gravity(20.0), kn=KN,
                                           friction=10.0, end="time: 0.2"))
        b = sim.blocks
        x0 = b.x[1].copy()
        sim.run()
        return b.x[1] - x0, sim.time

    s0, t = slide((0.0, 0.0, 0.0))
    s, _ = slide(origin)
    assert s[0] == pytest.approx(s0[0], rel=1e-6)
    assert s[0] == pytest.approx(0.5 * sliding_acceleration(20.0, 10.0) * t * t, rel=2e-2)
    assert abs(s[1]) < 1e-6 * s[0]
