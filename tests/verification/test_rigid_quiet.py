"""Quiet faces and wave input on rigid blocks (issue 41; pdem.dynamics.quiet, docs/dynamics.md)
against closed forms. A unit cube (m = rho, I = m/6) of a material with ``young`` and
``poisson`` (``Z_p = rho Cp``, ``Z_s = rho Cs`` per area):

- free, moving at ``v0`` with a quiet face (normal dashpot ``c = Z_p A``): the centred step
  gives ``v(t + dt/2) = v(t - dt/2) (1 - g/2) / (1 + g/2)``, ``g = c dt / m``, to round-off
  (asserted 1e-12), which is ``v0 exp(-c t / m)`` to ``g^2 / 8 + n g^3 / 12`` (measured
  2.2e-5 at g = 0.008, asserted 1e-4); at g = 3, where an explicit dashpot diverges, still
  the centred factor, decaying;
- spinning about z with shear dashpots on its faces (at their centroids): ``w0 exp(-6 Z_s t /
  m)`` (four side faces, arm 1/2: ``4 Z_s / 4 / (m / 6)``); measured 9.4e-6, asserted 1e-4;
- a wave of particle velocity ``V`` put in through its quiet bottom face (the traction
  ``2 Z V``): the face's velocity goes to ``2 V`` (the free surface's doubling) as ``2 V (1 -
  exp(-Z A t / m_e))``, ``m_e = m`` for a P wave (through the centroid), ``1 / (1/m +
  h^2/I) = m / 2.5`` for an S wave (the shear turns the cube about the face's arm h = 1/2);
  measured 3.1e-6 of 2 V, asserted 1e-3;
- resting on a joint spring ``kn A`` under gravity with its top face quiet (normal): a damped
  oscillator of fraction ``zeta = c / (2 sqrt(kn A m))`` (0.05 here): its log decrement
  and damped period against the closed form (measured 2e-4, asserted 1 %);
- a fixed base (2 x 2 x 1) carrying a cube, settled, then made quiet: with ``release`` it
  keeps the force and moment that held it (both weights) and stays at rest (measured
  2e-10 m/s, asserted 1e-6 of the sinking speed); freed alone it sinks with the cube at
  ``W / (Z_p A)`` (measured 1.3e-4, asserted 1e-3); a restart after the release ends
  bitwise where the straight run ends (its load from the checkpoint);
- the energy budget books what the dashpots absorb as ``quiet_absorbed``: it balances to
  round-off (asserted 1e-9 of the energy put in; with the joint, its energy taken at the
  kinetic energy's time t - dt/2, the rigid budget's O(dt) offset removed, docs/output.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import ConfigError, parse_scene
from pdem.dynamics.quiet import impedances
from pdem.errors import SimulationError
from pdem.plugins.base import Plugin
from pdem.plugins.energy import balance, energy_totals
from pdem.simulation import Simulation

RHO, YOUNG, POISSON = 2000.0, 1.0e9, 0.25
ZP, ZS = impedances(RHO, YOUNG, POISSON)
BOTTOM = "{box: {min: [-1, -1, -0.6], max: [1, 1, -0.4]}}"  # the cube's bottom face


def simulation(text: str) -> Simulation:
    """The scene set up, its energy budget's start sampled (the steps are taken here)."""
    sim = Simulation(parse_scene(text), MPI.COMM_SELF, output=False)
    sim.runner.plugin("energy").sample()
    return sim


def budget(sim) -> tuple[dict, float, float]:
    t = energy_totals(sim.state)
    err, put_in = balance(t, sim.runner.plugin("energy").e0)
    return t, err, put_in


def free_cube(conditions: str, *, dt: float, steps: int, velocity=(0, 0, 0),
              spin=(0, 0, 0), young: float = YOUNG, damping: str = "none") -> str:
    return f"""
gravity: [0, 0, 0]
materials: {{rock: {{density: {RHO}, young: {young}, poisson: {POISSON}}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9}}}}
blocks:
  - {{name: stone, box: {{min: [-0.5, -0.5, -0.5], max: [0.5, 0.5, 0.5]}}, material: rock,
     velocity: {list(velocity)}, angular_velocity: {list(spin)}}}
boundary:
{conditions}
solve: {{steps: {steps}, damping: {damping}, timestep: {{dt: {dt}}}}}
output: {{energy_every: 10}}
"""


class Trace:
    """The cube's velocity and angular velocity after every step, at t + dt/2."""

    def __init__(self, sim):
        self.sim, self.t, self.v, self.w = sim, [], [], []

    def run(self, steps: int):
        s = self.sim.state
        for _ in range(steps):
            self.sim.stepper.advance()
            self.t.append(s.time - 0.5 * s.dt)
            self.v.append(s.blocks.v[0].copy())
            self.w.append(s.blocks.w[0].copy())
        return np.array(self.t), np.array(self.v), np.array(self.w)


@pytest.mark.parametrize("gamma", [0.0077459667, 3.0])
def test_a_free_block_with_a_quiet_face_decays_as_the_dashpot(gamma):
    """``m dv/dt = -c v``: the centred factor per step exactly, exp(-c t/m) at small g."""
    v0, c = 1.0, ZP * 1.0
    dt = gamma * RHO / c
    steps = int(round(3.0 * RHO / c / dt)) if gamma < 1 else 20
    sim = simulation(free_cube(f"  quiet:\n    - {{range: {BOTTOM}, directions: [normal]}}",
                               dt=dt, steps=steps, velocity=(0, 0, -v0)))
    s = sim.state
    bc = s.boundary.rigid
    assert list(bc.d_gid) == [0] and np.allclose(bc.d_normal, [[0, 0, -1]])
    assert abs(bc.d_rate / (c / RHO) - 1.0) < 1e-12  # the largest lambda of M^-1 D: c / m
    g = c * s.dt / RHO
    t, v, w = Trace(sim).run(steps)
    r = (1.0 - 0.5 * g) / (1.0 + 0.5 * g)
    # the staggered start took v(-dt/2) = v0 (1 + g/2) (the dashpot at t = 0 in)
    discrete = -v0 * (1.0 + 0.5 * g) * r ** np.arange(1, steps + 1)
    err_d = float(np.max(np.abs(v[:, 2] / discrete - 1.0)))
    print(f"g = {g:.4g}: {steps} steps, centred factor to {err_d:.2g}", end="")
    assert err_d < 1e-12
    assert np.all(v[:, :2] == 0.0) and np.all(w == 0.0)
    if gamma < 1:
        exact = -v0 * np.exp(-c * t / RHO)
        err = float(np.max(np.abs(v[:, 2] / exact - 1.0)))
        print(f", exp(-c t / m) to {err:.2g}", end="")
        assert err < 1e-4
    else:  # an explicit dashpot's factor 1 - g = -2 would grow
        assert np.all(np.abs(np.diff(np.abs(v[:, 2]))) <= np.abs(v[:-1, 2]))
    tot, err_b, put_in = budget(sim)
    held = tot["kinetic"] + tot["quiet_absorbed"]
    print(f"; quiet_absorbed {tot['quiet_absorbed']:.6g} J, balance error {err_b:.2g} J of "
          f"{put_in:.6g} J")
    assert tot["applied_work"] == 0.0  # (moved to quiet_absorbed, to round-off)
    assert abs(err_b) < 1e-9 * put_in and abs(held / put_in - 1.0) < 1e-9


def test_a_spinning_block_is_slowed_by_its_faces_shear_dashpots():
    """Shear dashpots at the four side faces' centroids (arm 1/2; the top and bottom faces'
    centroids lie on the axis): ``I dw/dt = -4 Z_s A (1/2)^2 w``, ``I = m / 6``."""
    w0 = 2.0
    rate = 4.0 * ZS * 0.25 / (RHO / 6.0)
    dt = 0.005 / rate
    steps = int(round(3.0 / rate / dt))
    sim = simulation(free_cube("  quiet:\n    - {names: [stone], directions: [shear]}", dt=dt, steps=steps,
                               spin=(0, 0, w0)))
    assert len(sim.state.boundary.rigid.d_gid) == 6
    t, v, w = Trace(sim).run(steps)
    exact = w0 * np.exp(-rate * t)
    err = float(np.max(np.abs(w[:, 2] / exact - 1.0)))
    tot, err_b, put_in = budget(sim)
    print(f"w / exp decay - 1: {err:.2g} over {steps} steps; balance error {err_b:.2g} J of "
          f"{put_in:.6g}")
    assert err < 1e-4
    assert np.abs(v).max() < 1e-12 * w0 and np.abs(w[:, :2]).max() < 1e-12 * w0
    assert abs(err_b) < 1e-9 * put_in


@pytest.mark.parametrize("wave", ["P", "S"])
def test_a_wave_through_a_quiet_face_drives_the_face_to_twice_its_velocity(wave):
    """``m_e du/dt = 2 Z A V - Z A u`` for the bottom face's velocity ``u``: ``u -> 2 V``."""
    V = 0.05
    k = 2 if wave == "P" else 0
    vel = [0.0, 0.0, 0.0]
    vel[k] = V
    z = ZP if wave == "P" else ZS
    m_e = RHO if wave == "P" else 1.0 / (1.0 / RHO + 0.25 / (RHO / 6.0))
    rate = z / m_e
    dt = 0.005 / rate
    steps = int(round(3.0 / rate / dt))
    table = [[0.0, *vel], [1.0e3, *vel]]
    sim = simulation(free_cube(f"""  quiet:
    - {{range: {BOTTOM}}}
  stress:
    - {{range: {BOTTOM}, wave: {{table: {table}}}}}""", dt=dt, steps=steps))
    assert len(sim.state.boundary.rigid.w_gid) == 1
    t, v, w = Trace(sim).run(steps)
    # the face's velocity v + w x r, r = (0, 0, -1/2)
    u = v + np.cross(w, np.array([0.0, 0.0, -0.5]))
    exact = 2.0 * V * (1.0 - np.exp(-rate * t))
    err = float(np.max(np.abs(u[:, k] - exact)) / (2.0 * V))
    others = np.delete(u, k, axis=1)
    tot, err_b, put_in = budget(sim)
    print(f"{wave}: face velocity {u[-1, k] / V:.5f} V at {t[-1] * rate:.2f} / rate, worst "
          f"error {err:.2g} of 2 V; applied {tot['applied_work']:.6g} J = kinetic "
          f"{tot['kinetic']:.6g} + quiet {tot['quiet_absorbed']:.6g} (error {err_b:.2g})")
    assert err < 1e-3
    # (the S wave turns the cube and its face: the face's other components are of the angle)
    print(f"other components at most {np.abs(others).max() / (2.0 * V):.2g} of 2 V")
    assert np.abs(others).max() < 1e-3 * 2.0 * V
    if wave == "P":
        assert np.abs(w).max() == 0.0
    else:  # the cube turns about y as the face's shear pushes it
        assert w[-1, 1] < 0.0
    assert tot["applied_work"] > 0.0 and tot["quiet_absorbed"] > 0.0
    assert abs(err_b) < 1e-9 * put_in


def test_a_block_on_a_joint_with_a_quiet_face_is_a_damped_oscillator():
    """A cube on a fixed floor (joint ``kn``, area 1) under gravity, started at twice its
    static overlap, its top face quiet (normal ``c = Z_p``, ``young`` chosen for zeta =
    0.05): vertical velocity ``~ exp(-zeta w t) sin(w_d t)``; its successive peaks fall by
    ``exp(-2 pi zeta / sqrt(1 - zeta^2))`` a period ``2 pi / (w sqrt(1 - zeta^2))``."""
    kn, g, zeta = 1.0e9, 9.81, 0.05
    # Z_p = sqrt(rho M), M = E (1 - nu) / ((1 + nu)(1 - 2 nu)) = 1.2 E at nu = 1/4
    young = (2.0 * zeta * math.sqrt(kn * RHO)) ** 2 / (1.2 * RHO)
    c = impedances(RHO, young, POISSON)[0]
    assert abs(c / (2.0 * math.sqrt(kn * RHO)) / zeta - 1.0) < 1e-12
    delta = RHO * g / kn
    omega = math.sqrt(kn / RHO)
    text = f"""
gravity: [0, 0, -{g}]
materials: {{rock: {{density: {RHO}, young: {young}, poisson: {POISSON}}}}}
joints: {{default: {{kn: {kn}, ks: {kn}, friction: 60.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [-0.5, -0.5, {-2 * delta}], max: [0.5, 0.5, {1 - 2 * delta}]}},
     material: rock}}
boundary:
  quiet:
    - {{names: [cube], range: {{box: {{min: [-1, -1, 0.9], max: [1, 1, 1.1]}}}},
       directions: [normal]}}
solve: {{time: 1.0, damping: none}}
output: {{energy_every: 10}}
"""
    sim = simulation(text)
    s = sim.state
    assert np.allclose(s.boundary.rigid.d_normal, [[0, 0, 1]])
    wd = omega * math.sqrt(1.0 - zeta * zeta)
    steps = int(6.0 * 2.0 * math.pi / wd / s.dt)
    i = int(np.nonzero(s.blocks.fixed == 0)[0][0])
    t, vz = np.empty(steps), np.empty(steps)

    def balance_error():
        """The budget's balance error with the joint's energy at the kinetic energy's time
        t - dt/2 (a rigid scene's budget keeps it at t: an O(dt) offset, docs/output.md; it
        fell at -F_c . v over the half step)."""
        tot, err_b, put_in = budget(sim)
        f, v = s.blocks.force[i], s.blocks.v[i]
        return tot, err_b + 0.5 * s.dt * float(np.dot(f, v)), put_in

    for k in range(steps):
        sim.stepper.advance()
        if k == 0:  # (the start's own offset: strain at t = 0, kinetic energy at -dt/2)
            err0 = balance_error()[1]
        t[k] = s.time - 0.5 * s.dt
        vz[k] = s.blocks.v[i, 2]
    peaks = np.nonzero((vz[1:-1] > vz[:-2]) & (vz[1:-1] >= vz[2:]) & (vz[1:-1] > 0))[0] + 1
    # each peak refined by the parabola through it and its neighbours
    a, b_, c_ = vz[peaks - 1], vz[peaks], vz[peaks + 1]
    shift = 0.5 * (a - c_) / (a - 2 * b_ + c_)
    tp = t[peaks] + shift * s.dt
    vp = b_ - 0.25 * (a - c_) * shift
    dec = float(np.mean(np.log(vp[:-1] / vp[1:])))
    got = dec / math.sqrt(4.0 * math.pi ** 2 + dec ** 2)
    period = float(np.mean(np.diff(tp)))
    want_t = 2.0 * math.pi / wd
    tot, err_b, put_in = balance_error()
    err_b -= err0
    print(f"zeta {got:.5f} against {zeta} ({got / zeta - 1:+.2g}), period {period:.6g} s against "
          f"{want_t:.6g} ({period / want_t - 1:+.2g}), {len(peaks)} peaks, {steps} steps of "
          f"{s.dt:.3g} s (omega dt {omega * s.dt:.3g}); quiet_absorbed "
          f"{tot['quiet_absorbed']:.6g} J, balance error {err_b:.2g} J of {put_in:.6g} J")
    assert len(peaks) >= 5
    assert abs(got / zeta - 1.0) < 0.01
    assert abs(period / want_t - 1.0) < 0.01
    assert tot["quiet_absorbed"] > 0.0
    assert abs(err_b) < 1e-9 * put_in


def test_rigid_quiet_faces_are_checked():
    """A material without the elastic keys, faces out of range, and local damping against a
    dashpot it would destabilise are refused, naming what."""
    quiet = f"  quiet:\n    - {{range: {BOTTOM}}}"
    no_young = free_cube(quiet, dt=1e-5, steps=1).replace(
        f", young: {YOUNG}, poisson: {POISSON}", "")
    with pytest.raises(ConfigError, match=r"boundary.quiet\[0\].*material 'rock' has no young "
                                          r"\(materials.rock.young\)"):
        simulation(no_young)
    away = "{box: {min: [5, 5, 5], max: [6, 6, 6]}}"
    with pytest.raises(ConfigError, match=r"boundary.stress\[0\].*no exposed face in range"):
        simulation(free_cube(f"  stress:\n    - {{range: {away}, wave: {{table: [[0, 0, 0, 1]]}}}}",
                             dt=1e-5, steps=1))
    # local damping (alpha 0.8) with c dt / m = 3 (dt lambda 4.33 with the shear turning it)
    sim = simulation(free_cube(quiet, dt=3.0 * RHO / ZP, steps=5, velocity=(0, 0, -1),
                               damping="local"))
    with pytest.raises(SimulationError, match=r"dt lambda\(M\^-1 D\) = 4.33 .*1/alpha = 1.25"):
        sim.run()


class BaseTrace(Plugin):
    """The base's (gid 0) stage, vertical velocity and height after every step."""

    name = "base-trace"

    def __init__(self, state):
        self.state, self.rows = state, []

    def after_step(self, run):
        s = self.state
        self.rows.append((s.stage, s.blocks.v[0, 2], s.blocks.x[0, 2]))


def base_scene(how: str) -> str:
    """A fixed base (2 x 2 x 1) carrying a cube settles; then its bottom face is made quiet,
    released (``how`` "release") or freed by the stage alone ("free")."""
    quiet = "{names: [base], range: {box: {min: [-2, -2, -1.1], max: [2, 2, -0.9]}}}"
    stage = (f"quiet: [{quiet[:-1]}, release: true}}]" if how == "release"
             else f"free: {{names: [base]}}\n    quiet: [{quiet}]")
    return f"""
gravity: [0, 0, -9.81]
materials: {{rock: {{density: {RHO}, young: {YOUNG}, poisson: {POISSON}}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 40.0}}}}
blocks:
  - {{name: base, box: {{min: [-1, -1, -1], max: [1, 1, 0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
solve: {{damping: local}}
stages:
  - {{name: settle, solve: {{ratio: 1.0e-9}}}}
  - name: dynamic
    {stage}
    solve: {{time: 0.15, damping: none}}
"""


@pytest.mark.parametrize("how", ["release", "free"])
def test_a_fixed_base_made_quiet_keeps_its_support_or_sinks_at_the_dashpots_speed(how):
    """A fixed base (2 x 2 x 1) carrying a cube settles, then its bottom face is made quiet:
    with ``release`` the force and moment that held it stay as its load, and the two stay at
    rest; freed alone (a stage's ``free``) it sinks with the cube at the speed at which the
    dashpot carries their weight, ``W / (Z_p A)``."""
    text = base_scene(how)
    sim = Simulation(parse_scene(text), MPI.COMM_SELF, output=False)
    trace = BaseTrace(sim.state)
    sim.runner.plugins.append(trace)
    sim.run()
    rows = np.array([r for r in trace.rows if r[0] == 1])
    v_t = -(4.0 + 1.0) * RHO * 9.81 / (ZP * 4.0)  # base and cube, on a face of 4 m2
    bc = sim.state.boundary.rigid
    print(f"{how}: base velocity at the end {rows[-1, 1]:.6g} m/s, largest "
          f"{np.abs(rows[:, 1]).max():.3g}; W / (Z_p A) = {v_t:.6g} m/s; released loads "
          f"{bc.r_load.round(3).tolist()}")
    if how == "release":
        assert list(bc.r_gid) == [0]
        assert abs(bc.r_load[0, 2] / (5.0 * RHO * 9.81) - 1.0) < 1e-6  # it held both weights
        assert np.abs(rows[:, 1]).max() < 1e-6 * abs(v_t)
    else:
        assert not len(bc.r_gid)
        assert abs(rows[-1, 1] / v_t - 1.0) < 1e-3


def test_a_released_base_restarts_bitwise(tmp_path):
    """A checkpoint taken after the base's release: the replay of the stage frees it, its
    load comes back from the checkpoint's ``released_loads``, and the run ends where the
    straight run ends (one rank: tests/mpi/test_rigid_quiet_mpi.py restarts quiet faces on
    two)."""
    import glob

    from pdem.io.checkpoint import read_checkpoint

    text = base_scene("release").replace("solve: {time: 0.15", "solve: {time: 0.05") + (
        f"output: {{file: {tmp_path}/straight.h5, every_steps: 50}}\n"
        f"checkpoint: {{every: 0.02, keep: 9, file: {tmp_path}/ck}}\n")
    sim = Simulation(parse_scene(text), MPI.COMM_SELF)
    sim.run()
    sim.close()
    cks = [read_checkpoint(p) for p in sorted(glob.glob(f"{tmp_path}/ck-*.h5"))]
    ck = next(c for c in cks if "released_loads" in c["attrs"])
    scene = parse_scene(ck["attrs"]["scene"])
    scene = scene.model_copy(update={"output": scene.output.model_copy(
        update={"file": f"{tmp_path}/again.h5"}), "checkpoint": None})
    again = Simulation(scene, MPI.COMM_SELF, checkpoint=ck)
    assert np.array_equal(again.state.boundary.rigid.r_load, sim.state.boundary.rigid.r_load)
    again.run()
    again.close()
    print(f"restarted at step {ck['attrs']['step']} of {sim.state.step}")
    assert again.state.step == sim.state.step
    for k in ("x", "q", "v", "w", "work"):
        assert np.array_equal(getattr(again.blocks, k), getattr(sim.blocks, k)), k
