"""Impacts at 100 m/s (issue 10): a block thrown at a thin plate must never pass through it.

How contacts are found (pdem.stepper): a block is searched for new neighbours after the step
in which its accumulated motion passes CTOL/2, with its envelope grown by CTOL/2; a pair found
with a gap <= CTOL gets a contact whose overlap then follows the motion every step. So a pair
not yet in contact overlaps by at most what the blocks moved in that last step before its
contact exists. Two ways through a thin block were found:

* a step longer than the plate (a soft joint makes dt large): the block lands beyond the
  plate's middle before any contact exists (kn = 1e8, dt = 2.1e-4 s: 2.1 cm per step through
  a 1 cm plate);
* a joint too soft for the impact: the contact exists, but the spring lets the block sink
  v sqrt(m / (kn A)) (32 cm for kn = 1e8) into the plate, past the middle of the block, and
  the common plane then pushes it out on the far side, whatever the step.

Both are refused before the run (pdem.preflight: start speed x dt <= CTOL/2, and the
impact overlap <= a tenth of the block); inside those limits a 100 m/s block bounces off a
2 mm plate. Speeds reached during a run are checked by motion_bookkeeping's ``max_step``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdem import preflight as pf
from pdem.cases import make_simulation
from pdem.cases.extremes import RHO, thrown_at_plate
from pdem.config import ConfigError
from pdem.dynamics.motion import motion_bookkeeping
from pdem.errors import SimulationError

V = 100.0


def _fly(sim, t_end):
    """Advance to ``t_end``; (largest x of the bullet's front face, its x velocity)."""
    b = sim.blocks
    half = 0.5 * (sim.specs[1].volume / 0.25)  # the bullet's x extent / 2 (its y, z are 0.5)
    front = -math.inf
    while sim.time < t_end:
        sim.advance()
        front = max(front, b.x[1, 0] + half)
    return front, b.v[1, 0]


@pytest.mark.parametrize("bullet, plate, kn", [
    ((0.5, 0.5, 0.5), 0.002, 1.0e11),  # a 0.5 m cube at a 2 mm plate
    ((0.02, 0.5, 0.5), 0.02, 2.0e9),  # a 2 cm slab face-on at a 2 cm plate
])
def test_fast_block_bounces_off_thin_plate(bullet, plate, kn):
    """No gravity, a fixed plate, no damping: the block comes back at -100 m/s (0.5 %, the
    impact is elastic), ends on the near side, and sinks v sqrt(m / (kn A)) into the plate
    (12 %; measured 0.02 % for the slab, +5 % and +10 % for the cube, whose 1 cm overlap is five
    times the 2 mm plate: the plate's two equal moments make any frame in their plane
    principal, and the 5 % came from a 45-degree frame that one rounding of its inertia gave,
    the 10 % from the axis-aligned one another gives) -- the slab 1.4 cm, more than half its
    own 2 cm thickness, and still it does not pass."""
    sim = make_simulation(thrown_at_plate(V, plate, kn=kn, bullet=bullet, start_gap=0.02))
    m = RHO * bullet[0] * 0.25
    depth = V * math.sqrt(m / (kn * 0.25))
    t_end = 0.02 / V + math.pi * math.sqrt(m / (kn * 0.25)) + 2e-4
    front, vx = _fly(sim, t_end)
    assert vx == pytest.approx(-V, rel=5e-3)
    assert sim.blocks.x[1, 0] + 0.5 * bullet[0] < 0.0
    assert front == pytest.approx(depth, rel=0.12)


def test_fast_block_pushes_free_plate():
    """The same cube at a free 2 cm plate (40 kg against 250 kg): the cube never gets past
    the plate (its centre stays behind the plate's at every step) and momentum is conserved
    (1e-9 relative)."""
    sim = make_simulation(thrown_at_plate(V, 0.02, kn=1.0e11, plate_fixed=False, start_gap=0.02))
    b = sim.blocks
    p0 = float((b.mass[:2] * b.v[:2, 0]).sum())
    worst = -math.inf
    while sim.time < 2e-3:
        sim.advance()
        worst = max(worst, b.x[1, 0] - b.x[0, 0])
    assert worst < -0.25  # centres at least half the cube apart: it stays behind
    assert float((b.mass[:2] * b.v[:2, 0]).sum()) == pytest.approx(p0, rel=1e-9)
    assert b.v[0, 0] > b.v[1, 0]  # the plate flies ahead


def test_step_longer_than_search_refused():
    """kn = 1e8: the automatic dt = 2.1e-4 s moves the 100 m/s cube 2.1 cm per step, more than
    CTOL/2 = 3.4 mm of the 1 cm plate: refused naming the block, its speed and the dt to use."""
    with pytest.raises(ConfigError) as e:
        make_simulation(thrown_at_plate(V, 0.01, kn=1.0e8))
    msg = str(e.value)
    assert "blocks[1].velocity: block 'bullet' starts at 100 m/s and moves 0.02108 m in one step" in msg
    assert "more than 0.5 x CTOL = 0.00342 m" in msg and "solve.timestep.dt <= 3.42e-05 s" in msg


def test_joint_too_soft_for_the_impact_refused():
    """kn = 1e8 with a small enough dt (1e-6 s): the impact overlap v sqrt(m / (kn A)) = 0.32 m
    is 0.63 of the 0.5 m cube: refused naming the joint and the numbers."""
    with pytest.raises(ConfigError) as e:
        make_simulation(thrown_at_plate(V, 0.01, kn=1.0e8, end="time: 0.01, timestep: {dt: 1.0e-6}"))
    msg = str(e.value)
    assert "joints.default.kn: 1e+08 Pa/m is too soft for block 'bullet' (blocks[1]) started at " \
           "100 m/s" in msg and "= 0.3162 m" in msg


@pytest.mark.parametrize("end", ["time: 0.01", "time: 0.01, timestep: {dt: 3.4e-5}"])
def test_refused_scenes_did_tunnel(monkeypatch, end):
    """What the refusals prevent: with the checks off, the 100 m/s cube on kn = 1e8 passes
    through the 1 cm fixed plate and flies on beyond it, with the automatic step (2.1 cm per
    step) and with one inside CTOL/2 (the joint too soft for the impact)."""
    monkeypatch.setattr(pf, "MAX_STEP_MOTION", math.inf)
    monkeypatch.setattr(pf, "_check_impact_overlap", lambda *a: None)
    sim = make_simulation(thrown_at_plate(V, 0.01, kn=1.0e8, end=end))
    sim.state.max_step = math.inf  # and no run-time guard either (the compiled step reads it)
    _fly(sim, 0.01)
    assert sim.blocks.x[1, 0] - 0.25 > 0.01 and sim.blocks.v[1, 0] > 50.0  # beyond, going on


def test_run_time_step_guard():
    """motion_bookkeeping flags a free block whose motion bound in one step (|dx| + |dtheta| r)
    exceeds ``max_step``, fixed blocks never, and nothing by default."""
    n = 3
    dx = np.array([[0.001, 0, 0], [0.004, 0, 0], [0.0, 0.0, 0.0]])
    dtheta = np.array([[0, 0, 0], [0, 0, 0], [0.01, 0, 0]])
    radius = np.array([1.0, 1.0, 1.0])

    def run(fixed, **kw):
        z = [np.zeros(n) for _ in range(3)]
        return motion_bookkeeping(dx, dtheta, radius, np.array(fixed, np.uint8), *z,
                                  np.zeros((n, 3)), np.zeros((n, 3)), 1e9, **kw)[0]

    assert run([0, 0, 0]) == -1
    assert run([0, 0, 0], max_step=0.005) == 2  # 0.01 rad x 1 m
    assert run([0, 0, 1], max_step=0.003) == 1
    assert run([0, 1, 1], max_step=0.003) == -1


# A cube dropped from 5 m under 1e3 m/s2 onto a 1 cm plate on kn = 1e8: it starts at rest, so
# the start checks pass; it reaches 100 m/s, moves 2.1 cm per step and the impact overlap
# would be 0.32 m, past its middle.
FALL = """
gravity: [0.0, 0.0, -1000.0]
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
blocks:
  - {name: plate, material: rock, fixed: true, box: {min: [-1, -1, -0.01], max: [1, 1, 0]}}
  - {name: cube, material: rock, box: {min: [-0.25, -0.25, 5.0], max: [0.25, 0.25, 5.5]}}
solve: {time: 0.15, damping: none}
"""


@pytest.mark.parametrize("fused", [True, False])
def test_run_time_guard_stops_a_block_before_it_can_tunnel(fused):
    """The stepper passes max_step = REMAP_FRACTION x CTOL to motion_bookkeeping: the falling
    cube is stopped at 16 m/s, 4.9 m above the plate, by a SimulationError naming it and what
    to change, instead of passing through the plate (compiled loop and step by step alike)."""
    sim = make_simulation(FALL.replace("damping: none}", f"damping: none, fused: {str(fused).lower()}}}"))
    with pytest.raises(SimulationError) as e:
        sim.run()
    msg = str(e.value)
    assert "block 'cube'" in msg and "m that contact detection can follow" in msg
    assert sim.blocks.x[1, 2] > 4.0
