"""Joint stiffness from 1e4 to 1e14 Pa/m under a 1 m cube resting on a fixed floor (issue 10).

Soft joints whose static overlap m g / (kn A) is more than a tenth of the block are refused
before the run (pdem.preflight); from 1e6 Pa/m up the cube settles (local damping, to an
unbalanced-force ratio of 1e-6) at the closed-form overlap, the automatic timestep shrinking as
1 / sqrt(kn). A stiffness that makes the requested model time an absurd number of steps is
refused naming the step count.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdem.cases import make_simulation
from pdem.cases.extremes import box_on_floor, static_overlap
from pdem.config import ConfigError


@pytest.mark.parametrize("kn", [1.0e4, 1.0e5])
def test_soft_joint_refused(kn):
    """rho g / kn = 2000 x 9.81 / kn: 1.96 and 0.196 of the cube's size, above 0.1."""
    with pytest.raises(ConfigError) as e:
        make_simulation(box_on_floor(kn=kn, gap=0.0))
    msg = str(e.value)
    assert f"joints.default.kn: {kn:.4g} Pa/m is too soft for block 'box' (blocks[1])" in msg
    assert f"= {static_overlap(1.0, kn):.4g} m is" in msg and "more than 0.1" in msg


@pytest.mark.parametrize("kn", [1.0e6, 1.0e8, 1.0e10, 1.0e12, 1.0e14])
@pytest.mark.parametrize("ks_ratio", [1.0, 0.01])
def test_cube_settles_at_static_overlap(kn, ks_ratio):
    """Dropped from touching (gap 0) with local damping: the overlap converges to
    m g / (kn A) within 1e-3 relative (measured 1.3e-4 at ratio 1e-6, for every kn), no
    sideways drift or rotation; dt ~ 1 / sqrt(max(kn, ks))."""
    sim = make_simulation(box_on_floor(kn=kn, ks=kn * ks_ratio, gap=0.0, damping="local",
                                       end="ratio: 1.0e-6, max_steps: 5000"))
    b = sim.blocks
    x0, q0 = b.x[1].copy(), b.q[1].copy()
    sim.run()
    assert sim.step < 5000  # converged
    delta = static_overlap(1.0, kn)
    overlap = -(b.x[1, 2] - 0.5)
    assert overlap == pytest.approx(delta, rel=1e-3)
    assert np.abs(b.x[1, :2] - x0[:2]).max() < 1e-3 * delta
    assert np.abs(q0 - b.q[1]).max() < 1e-12 and np.abs(b.w[1]).max() < 1e-9
    # the automatic step: 0.1 x 2 sqrt(m / K) with K = kn x (surface / 3), halved by rotation
    assert sim.dt < 0.2 * math.sqrt(2000.0 / (kn * 2.0))


def test_absurd_step_count_refused():
    """kn = 1e14 Pa/m: dt = 3e-7 s, so 1000 s of model time is 3.4e9 steps (days of
    computing for a single cube), more than limits.max_steps (1e9): refused, naming it."""
    with pytest.raises(ConfigError) as e:
        make_simulation(box_on_floor(kn=1.0e14, end="time: 1000.0"))
    msg = str(e.value)
    assert "solve.time: 1000 s at dt=" in msg and "more than limits.max_steps = 1e+09" in msg
    assert "joints.default: kn=1e+14" in msg
    # a cap by solve.max_steps (or a larger limit) makes it a run again
    make_simulation(box_on_floor(kn=1.0e14, end="time: 1000.0, max_steps: 10"))
    make_simulation(box_on_floor(kn=1.0e14, end="time: 1000.0")
                    + "limits: {max_steps: 10000000000}\n")
