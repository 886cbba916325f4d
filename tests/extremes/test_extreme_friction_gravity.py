"""Friction and gravity at the extremes (issue 10): frictionless sliding, friction 89 deg on a
steep incline, and gravity from 0 through 1e-6 to 1e3 m/s2 (and a refused 1e5).

The incline is gravity tilted by psi (pdem.cases.extremes.incline_gravity): down-slope is +x.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdem.cases import fit_acceleration, make_simulation
from pdem.cases.extremes import RHO, box_on_floor, incline_gravity, sliding_acceleration, static_overlap
from pdem.config import ConfigError

KN = 1.0e9


@pytest.mark.parametrize("g", [9.81, 1.0e3, 1.0e-6])
def test_frictionless_block_slides_with_g_sin_psi(g):
    """Friction 0 on a 20 deg incline: a = g sin psi (1e-3, fitted over 0.1 s of steps; the
    floor is long enough), at g = 9.81, 1e3 and 1e-6 m/s2 alike. No shear force, so no
    moment: the block only pitches because the contact's sub-contacts are refreshed every
    ``detect_every`` = 10 steps while it slides on. At 1e3 m/s2 (34 m/s after 0.1 s, 3 cm per
    refresh) the pitch reached 1.4e-4 rad (2.5e-5 with detect_every 1), at 9.81 less than
    3e-8: bounded here by 2.5e-7 g + 1e-7 rad."""
    text = box_on_floor(gravity=incline_gravity(20.0, g), friction=0.0, kn=KN,
                        floor=(20.0, 3.0), end="time: 1.0")
    sim = make_simulation(text)
    b = sim.blocks
    x0, q0 = b.x[1].copy(), b.q[1].copy()
    t, x, tilt = [], [], 0.0
    while sim.time < 0.1:
        sim.advance()
        t.append(sim.time)
        x.append(b.x[1, 0] - x0[0])
        tilt = max(tilt, 2.0 * math.acos(min(1.0, abs(float(np.dot(q0, b.q[1]))))))
    a = fit_acceleration(np.array(t), np.array(x))
    assert a == pytest.approx(g * math.sin(math.radians(20.0)), rel=1e-3)
    assert tilt < 2.5e-7 * g + 1e-7


def test_friction_89_holds_on_80_degree_incline():
    """Friction 89 deg (tan = 57) on an 80 deg incline (tan = 5.7): no slip. A 1 x 1 x 0.1 m
    slab (it would topple only beyond 84.3 deg) with local damping settles where its shear
    spring carries m g sin psi: x = rho c g sin psi / ks = 9.66e-7 m (2 %), normal overlap
    rho c g cos psi / kn (2 %); it has not slipped (speed < 1e-6 m/s) and has not turned."""
    psi = 80.0
    assert sliding_acceleration(psi, 89.0) < 0.0
    text = box_on_floor((1.0, 1.0, 0.1), gravity=incline_gravity(psi), friction=89.0, kn=KN,
                        gap=0.0, damping="local", end="ratio: 1.0e-6, max_steps: 20000")
    sim = make_simulation(text)
    b = sim.blocks
    x0, q0 = b.x[1].copy(), b.q[1].copy()
    sim.run()
    assert sim.step < 20000
    g = 9.81
    shear = RHO * 0.1 * g * math.sin(math.radians(psi)) / KN
    assert b.x[1, 0] - x0[0] == pytest.approx(shear, rel=2e-2)
    normal = RHO * 0.1 * g * math.cos(math.radians(psi)) / KN
    assert x0[2] - b.x[1, 2] == pytest.approx(normal, rel=2e-2)
    assert np.abs(b.v[1]).max() < 1e-6
    assert np.abs(b.q[1] - q0).max() < 1e-6


@pytest.mark.parametrize("g", [1.0e-6, 9.81, 1.0e3])
def test_rest_overlap_scales_with_gravity(g):
    """A cube dropped from touching (local damping, ratio 1e-6) settles at rho c g / kn:
    1e-3 relative at 9.81 and 1e3 m/s2 (2 mm: 0.2 % of the cube), 2 % at 1e-6 m/s2, where
    the overlap, 2e-15 m, is only 36 ulp of the cube's 0.5 m centroid height."""
    sim = make_simulation(box_on_floor(gravity=(0.0, 0.0, -g), kn=KN, gap=0.0, damping="local",
                                       end="ratio: 1.0e-6, max_steps: 5000"))
    b = sim.blocks
    sim.run()
    assert sim.step < 5000
    rel = 2e-2 if g < 1e-3 else 1e-3
    assert 0.5 - b.x[1, 2] == pytest.approx(static_overlap(1.0, KN, g), rel=rel)


def test_zero_gravity_nothing_moves():
    """No gravity: a cube touching the floor stays exactly where it was (no force at a zero
    overlap), and a ratio end is reached at once."""
    sim = make_simulation(box_on_floor(gravity=(0.0, 0.0, 0.0), kn=KN, gap=0.0, end="steps: 200"))
    b = sim.blocks
    x0 = b.x[1].copy()
    sim.run()
    assert np.array_equal(b.x[1], x0) and not np.abs(b.v[1]).any()


def test_huge_gravity_refused():
    """1e5 m/s2 on kn = 1e9 Pa/m: the cube would sink rho g / kn = 0.2 of its size: refused by
    the static-overlap check, naming the joint."""
    with pytest.raises(ConfigError, match=r"joints.default.kn: 1e\+09 Pa/m is too soft for block "
                                          r"'box' .* = 0.2 m is 0.2 of its size 1 m"):
        make_simulation(box_on_floor(gravity=(0.0, 0.0, -1.0e5), kn=KN, gap=0.0))
