"""The run's energy budget (pdem.plugins.energy) with zoned blocks, against closed forms
(issue 40: the balance within 1 % of the energy put in). The budget counts the grids: their
kinetic energy at the half step, the work done on the zones (``zone_strain``, less their
``plastic_work``), gravity's, the loads', the prescribed velocities' and local damping's work
on the gridpoints, and the joints of zoned contacts (docs/deformable.md, "Energy").

- a velocity pulse driven into the base of a zoned column (nu = 0, 3328 zones): the energy put
  in is the boundary work ``rho c A int v^2 dt`` of a 1-D rod; the travelling pulse holds half
  as kinetic and half as strain energy, all kinetic when it reflects at the free top (stress
  cancels), all strain when it reflects at the held base (velocity cancels). No contacts: the
  balance closes to round-off (measured 1.5e-15 of the energy put in);
- a zoned cube sliding on a rigid floor under tilted gravity (40 deg against a 30 deg joint
  friction): the joints dissipate ``tan(phi) m g cos(theta)`` times the slide, ``1/2 a t^2``
  with ``a = g (sin theta - cos theta tan phi)`` (two thirds of gravity's work);
- a stack of two zoned cubes on a rigid floor, the upper one overhanging (its centroid past
  the lower one's edge): it tips, slides off and falls, with friction between zoned blocks and
  on the floor; gravity's booked work is the gridpoints' potential energy drop;
- a zoned arch collapsing: 12 zoned voussoirs (2,140 zones) of a semicircle too thin to stand
  (t/R = 0.06) on a fixed base, 0.3 s: hinging, sliding and falling, many zoned-zoned contacts
  made and updated.

Each case is undamped, 2-11 s warm (the budget sampled every 4 or 10 steps); the balance is
checked at every sample against the energy put in so far.
"""

import numpy as np
from mpi4py import MPI

from pdem.cases.collapse import arch_scene, zoned_row_scene
from pdem.config import parse_scene
from pdem.plugins.energy import balance, energy_totals
from pdem.simulation import Simulation

RHO, E = 2000.0, 1.0e8


def simulation(text: str) -> Simulation:
    return Simulation(parse_scene(text), MPI.COMM_SELF, output=False)


def budget(sim, e0: float) -> tuple[dict, float, float]:
    t = energy_totals(sim.state)
    err, put_in = balance(t, e0)
    return t, err, put_in


def start(sim) -> float:
    t = energy_totals(sim.state)
    return t["kinetic"] + t["strain"]


# ------------------------------------------------------------------ a wave in a column
L, V0 = 4.0, 0.1
C = float(np.sqrt(E / RHO))  # the bar wave speed (nu = 0: also the P-wave speed)
T = 2.0 / C  # the pulse: half a sine 2 m long
PULSE = [[float(t), 0.0, 0.0, float(V0 * np.sin(np.pi * t / T))] for t in np.linspace(0, T, 41)]
COLUMN = f"""
name: wave
gravity: [0, 0, 0]
materials:
  soft: {{density: {RHO}, young: {E}, poisson: 0.0}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30}}}}
blocks:
  - {{name: col, box: {{min: [0, 0, 0], max: [1, 1, {L}]}}, material: soft, zones: {{size: 0.35}}}}
boundary:
  velocity:
    - {{range: {{box: {{min: [-1, -1, -0.01], max: [2, 2, 0.01]}}}},
       history: {{table: {PULSE + [[T + 1.0, 0.0, 0.0, 0.0]]}}}}}
solve: {{steps: 1000000000, damping: none}}
"""


def test_a_pulse_in_a_zoned_column_exchanges_kinetic_and_strain_energy():
    sim = simulation(COLUMN)
    s = sim.state
    e0 = start(sim)
    # what the pulse puts in, rho c A int v^2 dt, of the history as the table gives it
    fine = np.linspace(0.0, T, 20001)
    v = np.interp(fine, [r[0] for r in PULSE], [r[3] for r in PULSE])
    put = RHO * C * 1.0 * float(np.sum(0.5 * (v[1:] ** 2 + v[:-1] ** 2) * np.diff(fine)))
    at = {0.5: None, 0.75: None, 1.25: None, 2.25: None}  # times in L / c
    worst = 0.0
    while s.time < 2.3 * L / C:
        sim.stepper.advance()
        if s.step % 4:
            continue
        t, err, put_in = budget(sim, e0)
        worst = max(worst, abs(err) / max(abs(put_in), 1e-300))
        for k in at:
            if at[k] is None and s.time >= k * L / C:
                at[k] = t
    summary = {k: (round(t["kinetic"] / put, 4), round(t["zone_strain"] / put, 4))
               for k, t in at.items()}
    print(f"wave: {s.step} steps; boundary work {at[2.25]['boundary_work'] / put:.4f} of "
          f"rho c A int v^2; (kinetic, zone strain) / it at t c / L: {summary}; balance "
          f"{worst:.2e} of the energy put in")
    # measured 0.9845: the grid's reaction to the driven base is not quite the 1-D rod's
    # (the pulse's dispersion on 0.2 x 0.235 m lattice boxes, size 0.35, the lumped masses;
    # at size 0.5, boxes of 1/3 m, six per half sine, the dispersed tail leaves 0.8975
    # kinetic at the top's reflection and 0.827 strain at the base's)
    assert abs(at[2.25]["boundary_work"] / put - 1.0) < 0.03
    for k in (0.5, 0.75):  # travelling: half and half (measured 0.494, 0.491)
        assert abs(at[k]["kinetic"] / put - 0.5) < 0.03
        assert abs(at[k]["zone_strain"] / put - 0.5) < 0.03
    # reflecting at the free top: all kinetic (measured 0.966 kinetic, 0.019 strain)
    assert at[1.25]["kinetic"] > 0.9 * put and at[1.25]["zone_strain"] < 0.08 * put
    # reflecting at the held base: all strain (measured 0.926 strain, 0.058 kinetic)
    assert at[2.25]["zone_strain"] > 0.85 * put and at[2.25]["kinetic"] < 0.12 * put
    assert at[2.25]["strain"] == 0.0 and at[2.25]["plastic_work"] == 0.0
    assert worst < 1e-9  # no contacts: the leap-frog's own balance, to round-off


# ------------------------------------------------------------------ a cube sliding
THETA, PHI, G = np.radians(40.0), np.radians(30.0), 4 * 9.81
SLIDE = f"""
name: slide
gravity: [{G * np.sin(THETA)}, 0, {-G * np.cos(THETA)}]
materials:
  rock: {{density: {RHO}}}
  soft: {{density: {RHO}, young: {E}, poisson: 0.25}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [4, 2, 0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [0, 0, 0], max: [1, 1, 1]}}, material: soft, zones: {{size: 0.5}}}}
solve: {{steps: 1000000000, damping: none}}
"""


def test_a_zoned_cube_sliding_dissipates_its_friction_work():
    sim = simulation(SLIDE)
    s = sim.state
    g = s.grids
    m = float(g.gmass.sum())
    x0 = g.gmass @ g.nodes / m
    e0 = start(sim)
    worst = 0.0
    while s.time < 0.3:
        sim.stepper.advance()
        if s.step % 10 == 0:
            _, err, put_in = budget(sim, e0)
            worst = max(worst, abs(err) / max(abs(put_in), 1e-300))
    t, err, put_in = budget(sim, e0)
    worst = max(worst, abs(err) / put_in)
    slid = float((g.gmass @ g.nodes / m - x0)[0])
    a = G * (np.sin(THETA) - np.cos(THETA) * np.tan(PHI))
    friction = np.tan(PHI) * m * G * np.cos(THETA) * slid
    print(f"slide: {s.step} steps; slid {slid:.4f} m ({slid / (0.5 * a * s.time ** 2):.4f} of "
          f"1/2 a t^2); joint dissipation {t['joint_dissipation'] / friction:.4f} of mu N d "
          f"({t['joint_dissipation'] / put_in:.3f} of the energy put in); balance {worst:.2e}")
    # the cube starts unloaded on the floor and rings on its joint springs: its mean normal
    # force is 2 % under m g cos(theta) (measured: slide 1.056, dissipation 0.974)
    assert abs(slid / (0.5 * a * s.time ** 2) - 1.0) < 0.08
    assert abs(t["joint_dissipation"] / friction - 1.0) < 0.03
    assert t["joint_dissipation"] > 0.6 * put_in  # tan 30 / tan 40 of gravity's work
    assert worst < 1e-2  # issue 40's bound, at every sample (measured 1.4e-4)


# ------------------------------------------------------------------ a stack collapsing
STACK = f"""
name: stack
gravity: [0, 0, {-G}]
materials:
  rock: {{density: {RHO}}}
  soft: {{density: {RHO}, young: {E}, poisson: 0.25}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -1, -1], max: [4, 2, 0]}}, material: rock, fixed: true}}
  - {{name: low, box: {{min: [0, 0, 0], max: [1, 1, 1]}}, material: soft, zones: {{size: 0.5}}}}
  - {{name: top, box: {{min: [0.6, 0, 1], max: [1.6, 1, 2]}}, material: soft, zones: {{size: 0.5}}}}
solve: {{steps: 1000000000, damping: none}}
"""


def test_a_zoned_stack_collapsing_keeps_its_balance():
    sim = simulation(STACK)
    s = sim.state
    g = s.grids
    grav = np.asarray(s.scene.gravity)

    def potential():
        return -float(np.sum(g.gmass[:, None] * g.nodes * grav))

    p0 = potential()
    e0 = start(sim)
    worst = drift = 0.0
    while s.time < 0.4:
        sim.stepper.advance()
        if s.step % 10 == 0:
            t, err, put_in = budget(sim, e0)
            worst = max(worst, abs(err) / max(abs(put_in), 1e-300))
            drift = max(drift, abs(t["gravity_work"] - (p0 - potential())))
    t, err, put_in = budget(sim, e0)
    drift /= put_in
    top = g.nodes[g.node_start[1]:g.node_start[2]]
    print(f"stack: {s.step} steps; top block's centroid at z {top[:, 2].mean():.3f}; joint "
          f"dissipation {t['joint_dissipation'] / put_in:.2e}, zone strain "
          f"{t['zone_strain'] / put_in:.2e} of the energy put in; balance {worst:.2e}; "
          f"gravity's work less the potential drop {drift:.2e}")
    assert top[:, 2].mean() < 1.1  # it fell off the lower block (from 1.5)
    assert t["joint_dissipation"] > 1e-3 * put_in  # it slid on the zoned block (4.0e-3)
    assert worst < 1e-2  # issue 40's bound, at every sample (measured 1.5e-3)
    # gravity's work over the steps' mean velocities is the drop of the gridpoints'
    # potential energy but for half a step's motion (measured 1.5e-3)
    assert drift < 2e-3


def test_a_zoned_arch_collapsing_keeps_its_balance():
    text = arch_scene(0.06, n=12, time=0.3, radius=2.0).replace(
        "material: stone, prism:", "material: stone, zones: {size: 0.3}, prism:").replace(
        "{stone: {density: 2000.0}}", f"{{stone: {{density: {RHO}, young: {E}, poisson: 0.2}}}}"
    ).replace("kn: 1.0e10, ks: 1.0e10", "kn: 1.0e9, ks: 1.0e9")
    sim = simulation(text)
    s = sim.state
    g = s.grids
    assert len(g.bodies) == 12
    e0 = start(sim)
    worst = 0.0
    while s.time < 0.3:
        sim.stepper.advance()
        if s.step % 20 == 0:
            t, err, put_in = budget(sim, e0)
            worst = max(worst, abs(err) / max(abs(put_in), 1e-300))
    t, err, put_in = budget(sim, e0)
    fell = float(np.abs(g.nodes - np.concatenate([b.nodes0 for b in g.bodies])).max())
    print(f"arch: {s.step} steps; largest gridpoint displacement {fell:.3f} m; kinetic "
          f"{t['kinetic'] / put_in:.3f}, joint dissipation {t['joint_dissipation'] / put_in:.2e} "
          f"of the energy put in; balance {worst:.2e}")
    assert fell > 0.1  # it collapsed (measured 0.24 m)
    assert t["joint_dissipation"] > 0.0
    assert worst < 1e-2  # issue 40's bound, at every sample (measured 5.3e-4)


# ------------------------------------------------------------------ a rim pressed past an edge
def test_a_rigid_edge_pressed_into_a_zoned_face_makes_no_energy():
    """The gridpoints of the zoned face along r1's edge bear r1 from the first touch (the
    part of their cells under r1's face), so no gridpoint joins the contact centimetres deep:
    the contact updates create no energy. Before, the rim row was left out while it lay
    outside r1's outline by more than the touch tolerance; r1's edge sank 2.4 cm into z2's
    face beside it, and the update that took the row in created 5.1e3 J, 35 % of the energy
    put in (the run stopped on solve.energy_tolerance at step 180)."""
    sim = simulation(zoned_row_scene(240))  # (pdem.cases.collapse: the scene and its story)
    s = sim.state
    e0 = start(sim)
    worst = made = 0.0
    while s.step < 240:
        sim.run(steps=10)  # (the compiled loop of steps, with its grid step)
        t, err, put_in = budget(sim, e0)
        worst = max(worst, abs(err) / put_in)
        made = max(made, abs(t["geometry_created"]) / put_in)
    print(f"soft row: balance {worst:.2e}, created by contact updates {made:.2e} of the energy "
          f"put in")
    z2 = s.grids.bodies[list(s.grids.names).index("z2")]
    print(f"z2's largest zone stress {np.abs(z2.stress).max():.3g} Pa")
    assert np.abs(z2.stress).max() > 1e5  # the collision strained z2
    assert made < 1e-3  # (measured 4.6e-4; 0.35 before)
    assert worst < 1e-2  # issue 40's bound, at every sample
