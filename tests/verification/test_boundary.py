"""Boundary conditions (``boundary:``; pdem.boundary): boundary stresses on exposed faces and
prescribed velocities (whole block or chosen components, constant, table or harmonic).

Closed forms, computed here:

* a column of three unit cubes on a fixed floor, with a pressure p (or the equivalent stress
  tensor) on the top cube's exposed faces, relaxed with local damping: the joint under cube
  k carries ``p A + (weight of the cubes above it)`` (within 1e-4 relative), and the side
  faces' pressures cancel;
* a base shaken harmonically moves at ``a sin(2 pi f t + phase)`` evaluated at every step's
  mid-step time ``t + dt/2`` (to round-off), with a cube sliding on it;
* a table history is interpolated linearly between its rows and held after the last;
* a block whose z velocity is prescribed falls at exactly that speed while it accelerates
  freely in x under a sideways gravity;
* the energy budget closes in each of these runs: balance error below 1e-3 of the energy
  put in (as test_energy.py's sliding runs; slip books O(dt) errors), 1e-9 with no contact.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdem.cases import make_simulation
from pdem.config import ConfigError, parse_scene
from pdem.dynamics.rotation import quat_to_matrix
from pdem.plugins.base import Plugin
from pdem.plugins.energy import balance, energy_totals

RHO, KN, G = 2500.0, 1.0e9, 9.81
P = 2.0e5  # Pa
# balance error / energy put in: as the sliding tests of test_energy.py (slip makes O(dt) errors)
TOL_BALANCE = 1e-3


def budget(sim):
    t = energy_totals(sim.state)
    err, put_in = balance(t, sim.runner.plugin("energy").e0)
    return t, err, put_in


def column_scene(load: str) -> str:
    return f"""
gravity: [0, 0, -{G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - name: col
    array: {{box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, count: [1, 1, 3], spacing: [1, 1, 1]}}
    material: rock
boundary:
  stress:
    - {{range: {{box: {{min: [-1, -1, 2], max: [1, 1, 3]}}}}, {load}}}
solve: {{ratio: 1.0e-7, max_steps: 200000, damping: local}}
"""


@pytest.mark.parametrize("load", [f"pressure: {P}", f"tensor: [0, 0, {-P}, 0, 0, 0]",
                                  f"tensor: [[{-P}, 0, 0], [0, {-P}, 0], [0, 0, {-P}]]"])
def test_column_carries_top_stress_and_weight(load):
    sim = make_simulation(column_scene(load))
    bc = sim.state.boundary
    # the top cube's exposed faces: its four sides and its top, not its base
    assert sorted(map(tuple, bc.f_normal.round(12))) == sorted(
        [(-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0), (0, 0, 1)])
    sim.run()
    assert sim.state.ratio <= 1e-7
    b, c = sim.blocks, sim.contacts
    fn = c.normal_forces(sim.state.joints.kernel_args)
    z_top = {}
    for k in range(c.n):  # the joint's force: the sum of its sub-contacts' normal forces
        upper = c.ib[k] if b.x[c.ib[k], 2] > b.x[c.ia[k], 2] else c.ia[k]
        z_top[round(float(b.x[upper, 2]))] = float(fn[c.sc_start[k]:c.sc_start[k + 1]].sum())
    weight = RHO * 1.0 * G
    assert len(z_top) == 3
    worst = 0.0
    for z, fn in z_top.items():  # the cube centred at z + 0.5 and those above it
        above = 3 - int(z)
        expected = P * 1.0 + above * weight
        worst = max(worst, abs(fn / expected - 1.0))
        assert abs(fn / expected - 1.0) < 1e-4, (z, fn, expected)
    print(f"joint forces: largest relative error {worst:.2g}")
    t, err, put_in = budget(sim)
    assert t["applied_work"] > 0.0
    print(f"balance error {err:.3g} J of {put_in:.4g} J put in ({err / put_in:.2g})")
    assert abs(err) < TOL_BALANCE * put_in


class Recorder(Plugin):
    """The prescribed block's velocity after every step, with its time level t + dt/2."""

    name = "recorder"

    def __init__(self, state, name):
        self.state = state
        self.gid = next(i for i, sp in enumerate(state.specs) if sp.name == name)
        self.rows = []

    def after_step(self, run):
        s = self.state
        r = int(np.nonzero(s.blocks.gid == self.gid)[0][0])
        self.rows.append((s.time - 0.5 * s.dt, *s.blocks.v[r], *s.blocks.w[r]))


def base_scene(condition: str, time: float) -> str:
    return f"""
gravity: [0, 0, -{G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: base, box: {{min: [-3, -3, -1], max: [3, 3, 0]}}, material: rock, group: base}}
  - {{name: cube, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
boundary:
  velocity:
    - {{groups: [base], {condition}}}
solve: {{time: {time}, damping: none}}
"""


def run_recorded(text: str, name: str):
    sim = make_simulation(text)
    rec = Recorder(sim.state, name)
    sim.runner.plugins.append(rec)
    sim.run()
    return sim, np.array(rec.rows)


def test_harmonic_base_velocity_follows_the_formula():
    """Shaking at 2 Hz with 0.5 m/s amplitude: a peak acceleration of 6.3 m/s2 above
    tan(30 deg) g = 5.7 m/s2, so the cube slides on the base (joint dissipation)."""
    amp, f, phase = (0.5, 0.0, 0.1), 2.0, 30.0
    sim, rows = run_recorded(base_scene(
        f"history: {{harmonic: {{amplitude: {list(amp)}, frequency: {f}, phase: {phase}}}}}",
        0.5), "base")
    t = rows[:, 0]
    want = np.array(amp)[None] * np.sin(2 * math.pi * f * t + math.radians(phase))[:, None]
    assert len(rows) > 100
    assert np.abs(rows[:, 1:4] - want).max() <= 1e-14
    assert np.abs(rows[:, 4:7]).max() == 0.0  # all components prescribed: no spin either
    tot, err, put_in = budget(sim)
    assert tot["joint_dissipation"] > 0.0 and tot["boundary_work"] != 0.0
    print(f"balance error {err:.3g} J of {put_in:.4g} J put in ({err / put_in:.2g})")
    assert abs(err) < TOL_BALANCE * put_in


def test_table_history_interpolates_and_holds():
    table = [[0.0, 0.0, 0.0, 0.0], [0.1, 0.2, 0.0, 0.0], [0.2, 0.2, -0.1, 0.0]]

    def expected(t):
        if t <= 0.1:
            return np.array([2.0 * t, 0.0, 0.0])
        if t <= 0.2:
            return np.array([0.2, -(t - 0.1), 0.0])
        return np.array([0.2, -0.1, 0.0])

    sim, rows = run_recorded(base_scene(f"history: {{table: {table}}}", 0.3), "base")
    want = np.array([expected(t) for t in rows[:, 0]])
    assert rows[-1, 0] > 0.25
    assert np.abs(rows[:, 1:4] - want).max() <= 1e-12
    tot, err, put_in = budget(sim)
    print(f"balance error {err:.3g} J of {put_in:.4g} J put in ({err / put_in:.2g})")
    assert abs(err) < TOL_BALANCE * put_in


def test_one_component_prescribed_the_others_free():
    """z prescribed at -0.1 m/s (``components: [z]``) under a gravity [2, 0, -9.81]: the
    block falls at exactly 0.1 m/s while x accelerates freely at 2 m/s2 (the leap-frog is
    exact for constant acceleration) and it does not spin."""
    text = """
gravity: [2.0, 0, -9.81]
materials: {rock: {density: 2500.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
blocks:
  - {name: b, box: {min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}, material: rock}
boundary:
  velocity:
    - {names: [b], components: [z], velocity: [0, 0, -0.1]}
solve: {time: 0.2, damping: none, timestep: {dt: 1.0e-4}}
"""
    sim, rows = run_recorded(text, "b")
    t = rows[:, 0]
    assert np.abs(rows[:, 3] + 0.1).max() == 0.0
    assert np.abs(rows[:, 1] - 2.0 * t).max() < 1e-12
    assert np.abs(rows[:, 2]).max() == 0.0
    assert np.abs(rows[:, 4:7]).max() == 0.0
    x = sim.blocks.x[0]
    T = sim.state.time
    assert x[2] - 0.5 == pytest.approx(-0.1 * T, rel=1e-12)
    assert x[0] == pytest.approx(0.5 * 2.0 * T * T, rel=1e-9)
    tot, err, put_in = budget(sim)
    m = 2500.0
    # the kinetic energy is the free component's alone, and only that component's gravity
    # works (the z component's 2500 * 9.81 * 0.02 = 490 J is not booked: the boundary holds it)
    assert tot["kinetic"] == pytest.approx(0.5 * m * float(sim.blocks.v[0, 0]) ** 2, rel=1e-9)
    assert tot["gravity_work"] == pytest.approx(tot["kinetic"], rel=1e-6)
    print(f"balance error {err:.3g} J of {put_in:.4g} J put in ({err / put_in:.2g})")
    assert abs(err) < 1e-9 * put_in


BAD = [
    ("velocity: [{groups: [nope], velocity: [0, 0, 1]}]", "boundary.velocity[0].groups"),
    ("stress: [{groups: [nope], pressure: 1.0}]", "boundary.stress[0].groups"),
    ("stress: [{names: [b], tensor: [[1, 2, 0], [0, 1, 0], [0, 0, 1]]}]", "tensor"),
    ("stress: [{names: [b], tensor: [1, .nan, 0, 0, 0, 0]}]", "tensor"),
    ("stress: [{names: [b], tensor: [1, .inf, 0, 0, 0, 0]}]", "tensor"),
    ("stress: [{names: [b], pressure: 1.0, tensor: [0, 0, 0, 0, 0, 0]}]", "stress"),
    ("velocity: [{names: [b], history: {table: [[0, 0, 0, 0], [0, 1, 0, 0]]}}]", "table"),
    ("velocity: [{names: [b], history: {table: [[1, 0, 0, 0], [0.5, 1, 0, 0]]}}]", "table"),
    ("velocity: [{names: [b], components: [x, w]}]", "components"),
    ("velocity: [{names: [b], components: [x], angular_velocity: [0, 0, 1]}]",
     "angular_velocity"),
]


@pytest.mark.parametrize("section,key", BAD)
def test_bad_boundary_input_is_refused_naming_the_key(section, key):
    text = f"""
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9}}}}
blocks:
  - {{name: b, box: {{min: [0, 0, 0], max: [1, 1, 1]}}, material: rock}}
boundary: {{{section}}}
solve: {{steps: 1}}
"""
    with pytest.raises(ConfigError) as e:
        parse_scene(text)
    assert key in str(e.value)


def test_stage_conditions_start_with_the_stage():
    """A stage's velocity history runs on the time since the stage began; its stress loads
    the cube's exposed faces from then on (none before)."""
    text = f"""
gravity: [0, 0, -{G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: base, box: {{min: [-3, -3, -1], max: [3, 3, 0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
solve: {{damping: local}}
stages:
  - {{name: settle, solve: {{steps: 100}}}}
  - name: shake
    velocity: [{{names: [base], history: {{harmonic: {{amplitude: [0.1, 0, 0], frequency: 5.0}}}}}}]
    stress: [{{names: [cube], pressure: 1.0e4}}]
    solve: {{steps: 200, damping: none}}
"""
    sim = make_simulation(text)
    assert len(sim.state.boundary.f_gid) == 0
    rec = Recorder(sim.state, "base")
    sim.runner.plugins.append(rec)
    sim.run()
    rows = np.array(rec.rows)
    t0 = sim.state.stage_times[1]
    assert t0 > 0.0
    shaking = rows[rows[:, 0] > t0]
    assert len(shaking) == 200
    want = 0.1 * np.sin(2 * math.pi * 5.0 * (shaking[:, 0] - t0))
    assert np.abs(shaking[:, 1] - want).max() <= 1e-14
    assert np.abs(rows[rows[:, 0] < t0, 1:]).max() == 0.0  # fixed while settling
    assert len(sim.state.boundary.f_gid) == 5  # the cube's sides and top
    cube = int(np.nonzero(sim.blocks.gid == 1)[0][0])
    # a follower load: -p A along the top face's turned normal (the cube rocks a little)
    sim.state.boundary.tractions(sim.state)  # on the pose now (the step used the last one)
    R = quat_to_matrix(sim.blocks.q[cube])
    assert np.abs(sim.blocks.bforce[cube] + 1.0e4 * R[:, 2]).max() < 1e-9
    assert np.abs(sim.blocks.bmoment[cube]).max() < 1e-9
