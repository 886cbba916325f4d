"""Cables and rock bolts (pdem.reinforce, pdem.dynamics.cables) against closed forms:

* a cable anchored at both ends and pulled: it stretches ``F L / (E A)``, and past
  ``yield_tension`` it holds exactly that force while the block runs away at
  ``(F - T_y) / m``;
* pull-out of a grouted cable: the peak load is the grout strength times the embedded length,
  and once the grout has yielded the axial force falls linearly along it, ``s (x - x_end)``;
* a block on an incline steeper than its friction angle, held by a bolt parallel to the
  slope: the bolt carries ``W (sin psi - cos psi tan phi)`` at rest, and with a capacity
  below that the block slides at ``g (sin psi - cos psi tan phi) - T_y / m``;
* a rock bolt across a joint: the joint's shear loads its dowel to its shear strength;
* the energy budget closes with the elements' springs, slip and yield in it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import ConfigError, parse_scene
from pdem.plugins.base import Plugin
from pdem.plugins.energy import balance, energy_totals
from pdem.simulation import Simulation

E, A = 2.0e11, 1.0e-4  # steel, a 11 mm bar
RHO = 2500.0


def simulation(text: str) -> Simulation:
    return Simulation(parse_scene(text), MPI.COMM_SELF, output=False)


def pulled(force: float, damping: str, end: str, ty: float = 2.0e5, scaled: bool = True) -> str:
    """Block b (1 m cube, free) beside fixed block a, held by a cable anchored in both
    (from x = -0.5 in a to x = 0.5 in b: 1 m long, ungrouted), pulled along x by ``force``."""
    return f"""
gravity: [0, 0, 0]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30.0}}}}
blocks:
  - {{name: a, box: {{min: [-1, -0.5, -0.5], max: [0, 0.5, 0.5]}}, material: rock, fixed: true}}
  - {{name: b, box: {{min: [0, -0.5, -0.5], max: [1, 0.5, 0.5]}}, material: rock,
     force: [{force}, 0, 0]}}
reinforcement:
  - {{name: c, from: [-0.5, 0, 0], to: [0.5, 0, 0], segments: 6, young: {E}, area: {A},
     yield_tension: {ty}, anchors: [from, to]}}
solve: {{{end}, damping: {damping}, mass_scaling: {str(scaled).lower()}}}
"""


def test_a_cable_pulled_stretches_at_ea_over_l():
    sim = simulation(pulled(1.0e5, "local", "ratio: 1.0e-7, max_steps: 200000"))
    sim.run()
    b, e = sim.state.blocks, sim.state.reinforcement
    stretch = b.x[1, 0] - 0.5
    print(f"\npulled: stretch {stretch:.6e} m (F L/EA {1.0e5 / (E * A):.6e}), axial "
          f"{e.axial.min():.6g}..{e.axial.max():.6g} N")
    assert stretch == pytest.approx(1.0e5 * 1.0 / (E * A), rel=1e-3)
    assert np.allclose(e.axial, 1.0e5, rtol=1e-3)


def test_a_cable_past_its_yield_holds_its_yield_force_and_the_block_runs_away():
    """Undamped and unscaled: the block's acceleration once the cable has yielded (it takes
    0.013 s to stretch to its yield), from its velocity at two times; the energy budget
    closes with the plastic work of the yield in it."""
    sim = simulation(pulled(3.0e5, "none", "time: 1.0", scaled=False))
    s = sim.state
    sim.run(steps=int(0.02 / s.dt))
    v0, t0 = s.blocks.v[1, 0], s.time
    sim.run(steps=int(0.01 / s.dt))
    v1, t1 = s.blocks.v[1, 0], s.time
    m = RHO * 1.0
    print(f"\nyielded: a {(v1 - v0) / (t1 - t0):.6g} m/s2 ((F - Ty)/m {(3.0e5 - 2.0e5) / m:.6g})")
    assert (v1 - v0) / (t1 - t0) == pytest.approx((3.0e5 - 2.0e5) / m, rel=2e-3)
    assert np.allclose(s.reinforcement.axial, 2.0e5, rtol=1e-3)
    t = energy_totals(s)
    err, put_in = balance(t, sum(s.energy_start or (0.0, 0.0)))
    assert t["reinforcement_dissipation"] > 0.3 * put_in
    print(f"  energy: balance error {err:.3e} J of {put_in:.4g} put in; yield and slip "
          f"{t['reinforcement_dissipation']:.4g} J")
    assert abs(err) < 1e-3 * put_in


PULL_OUT = """
gravity: [0, 0, 0]
materials: {{rock: {{density: {rho}}}}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30.0}}}}
blocks:
  - {{name: rock, box: {{min: [-2, -0.5, -0.5], max: [0, 0.5, 0.5]}}, material: rock, fixed: true}}
  - {{name: plate, box: {{min: [0, -0.5, -0.5], max: [1, 0.5, 0.5]}}, material: rock,
     velocity: [{v}, 0, 0], velocity_fixed: true}}
reinforcement:
  - {{name: c, from: [-1.875, 0, 0], to: [0.625, 0, 0], segments: 10, young: {E}, area: {A},
     grout: {{stiffness: 1.0e9, strength: {s}}}, anchors: [to]}}
solve: {{time: {time}, damping: local}}
"""


def test_a_grouted_cable_pulls_out_at_its_grout_strength_times_its_embedded_length():
    """Embedded 1.875 m in the fixed block (its nodes' grout lengths end at the joint), pulled
    out by the plate at 0.5 m/s: the load at the joint levels off at ``s L_e``, and the
    axial force along the embedded part is ``s (x - x_end)`` at each segment's middle (2 %:
    the nodes' local damping and inertia at the slip rate)."""
    s = 1.0e5
    sim = simulation(PULL_OUT.format(rho=RHO, v=0.5, E=E, A=A, s=s, time=0.1))
    sim.run()
    e = sim.state.reinforcement
    x0 = -1.875 + 0.25 * np.arange(10) + 0.125  # the segments' middles as installed
    embedded = x0 < 0.1  # (the last one's middle is on the joint: the segment across it)
    exit_ = int(np.nonzero(embedded)[0][-1])
    print(f"\npull-out: load at the joint {e.axial[exit_]:.6g} N (s L_e {s * 1.875:.6g}); profile "
          f"max rel. error {np.abs(e.axial[embedded] / (s * (x0[embedded] + 1.875)) - 1).max():.2e}")
    assert e.axial[exit_] == pytest.approx(s * 1.875, rel=2e-2)
    assert np.allclose(e.axial[embedded], s * (x0[embedded] + 1.875), rtol=2e-2, atol=0.01 * s)
    assert (e.slip[:8] > 0.01).all()  # every embedded node slid out with the plate


def incline(ty: float, damping: str, end: str, scaled: bool = True, stages: str = "") -> str:
    """A 1 m cube on a fixed base under gravity tilted by psi = 35 degrees (down the slope:
    +x), friction 25 degrees, held by a bolt from a fixed wall up-slope (x < 0)."""
    psi = math.radians(35.0)
    g = 9.81
    return f"""
gravity: [{g * math.sin(psi)!r}, 0, {-g * math.cos(psi)!r}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 25.0}}}}
blocks:
  - {{name: base, box: {{min: [-2, -1, -1], max: [3, 1, 0]}}, material: rock, fixed: true}}
  - {{name: wall, box: {{min: [-2, -1, 0], max: [0, 1, 1]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [0, -0.5, 0], max: [1, 0.5, 1]}}, material: rock}}
reinforcement:
  - {{name: bolt, from: [-1.0, 0, 0.5], to: [0.5, 0, 0.5], segments: 6, young: {E}, area: {A},
     yield_tension: {ty}, anchors: [from, to]}}
solve: {{{end}, damping: {damping}, mass_scaling: {str(scaled).lower()}}}
{stages}"""


# the friction lowered to 25 degrees in steps, each solved to rest: the block slides into
# its bolt quasi-statically (a sudden drop overshoots: any bolt force from the closed form up
# to W (sin psi + cos psi tan phi) holds the block at rest)
LOWERED = "stages:\n" + "".join(
    f"  - {{name: f{k}, joints: {{default: {{friction: {phi}}}}}, solve: {{ratio: 1.0e-7, "
    f"max_steps: 100000}}}}\n"
    for k, phi in enumerate((40.0, 34.0, 32.0, 30.0, 29.0, 28.0, 27.5, 27.0, 26.5, 26.0, 25.7,
                             25.4, 25.2, 25.1, 25.03, 25.0)))


def test_a_bolt_holds_a_block_on_an_incline_steeper_than_its_friction():
    sim = simulation(incline(0.0, "local", "steps: 1", stages=LOWERED).replace(
        "solve: {steps: 1, ", "solve: {"))
    sim.run()
    psi, phi = math.radians(35.0), math.radians(25.0)
    w = RHO * 9.81
    want = w * (math.sin(psi) - math.cos(psi) * math.tan(phi))
    print(f"\nbolted incline: axial {sim.state.reinforcement.axial.mean():.6g} N (closed form "
          f"{want:.6g})")
    assert np.allclose(sim.state.reinforcement.axial, want, rtol=5e-3)


class CubeTrace(Plugin):
    """The cube's (gid 2) stage, time and velocity along the slope after every step."""

    name = "cube-trace"

    def __init__(self, state):
        self.state, self.rows = state, []

    def after_step(self, run):
        s = self.state
        self.rows.append((s.stage, s.time, s.blocks.v[2, 0]))


def test_a_bolt_weaker_than_the_load_lets_the_block_slide():
    """Settled at 40 degrees (its normal springs at rest: undamped, a block dropped onto its
    base bounces on them for ever and its friction with them), then undamped at 25: it slides
    at ``g (sin psi - cos psi tan phi) - T_y / m`` once the bolt has yielded."""
    psi, phi = math.radians(35.0), math.radians(25.0)
    stages = ("stages:\n  - {name: settle, joints: {default: {friction: 40.0}}, "
              "solve: {ratio: 1.0e-7}}\n  - {name: slide, joints: {default: {friction: 25.0}}, "
              "solve: {time: 0.5, damping: none}}\n")
    sim = simulation(incline(2000.0, "local", "steps: 1", scaled=False, stages=stages)
                     .replace("solve: {steps: 1, ", "solve: {"))
    trace = CubeTrace(sim.state)
    sim.runner.plugins.append(trace)
    sim.run()
    rows = np.array([r[1:] for r in trace.rows if r[0] == 1])
    t0 = rows[0, 0]
    late = rows[rows[:, 0] > t0 + 0.2]
    a_measured = np.polyfit(late[:, 0], late[:, 1], 1)[0]
    a = 9.81 * (math.sin(psi) - math.cos(psi) * math.tan(phi)) - 2000.0 / RHO
    print(f"\nweak bolt: a {a_measured:.6g} m/s2 (closed form {a:.6g})")
    assert a_measured == pytest.approx(a, rel=1e-2)
    # yielded where it is loaded most; along it the nodes' own weight (1.1 N each down the
    # slope) takes the rest
    axial = sim.state.reinforcement.axial
    assert axial.max() == pytest.approx(2000.0, rel=1e-9) and np.allclose(axial, 2000.0, rtol=5e-3)


def test_a_node_in_no_block_is_refused_with_its_position():
    text = pulled(1.0e5, "local", "steps: 10").replace("to: [0.5, 0, 0]", "to: [1.5, 0, 0]")
    with pytest.raises(ConfigError, match=r"reinforcement 'c': node at \(1\.5, 0, 0\) lies in no "
                                          r"block"):
        simulation(text).run()


def test_bad_reinforcement_input_is_refused_naming_the_key():
    base = pulled(1.0e5, "local", "steps: 10")
    for bad, good, why in (
            ("anchors: [from, to]}", "anchors: [from, to], shear_stiffness: 1.0e8}", "rockbolt's"),
            ("name: c, from", "name: c, model: rockbolt, from", "shear_stiffness"),
            ("to: [0.5, 0, 0]", "to: [-0.5, 0, 0]", "same point"),
            ("yield_tension: 200000.0", "yield_tension: 1.0, pretension: 5.0", "not below"),
            ("solve:", "stages: [{name: s, reinforce: [d], solve: {steps: 1}}]\nsolve:",
             "unknown reinforcement 'd'")):
        assert bad in base, bad
        with pytest.raises(ConfigError, match=why):
            parse_scene(base.replace(bad, good))


def test_the_elements_are_in_the_output_in_paraview_s_sidecar_and_in_pdem_info(tmp_path):
    """Snapshots hold the nodes and segment forces (pdem.io.elements), the polyline sidecar
    points at them, and ``pdem info`` names the most loaded element."""
    import h5py

    from pdem.io.elements import elements_path
    from pdem.io.info import summarise

    out = tmp_path / "pulled.h5"
    text = pulled(1.0e5, "local", "steps: 400") + f"output: {{file: {out}, every_steps: 200}}\n"
    sim = Simulation(parse_scene(text), MPI.COMM_SELF)
    sim.run()
    sim.close()
    with h5py.File(out) as f:
        g = f["reinforcement"]
        assert sorted(g) == ["000000", "000001", "000002"]
        last = g["000002"]
        assert last["points"].shape == (7, 3) and last["segments"].shape == (6, 2)
        assert np.array_equal(last["axial"][()], sim.state.reinforcement.axial)
        assert g.attrs["entries"] == "c"
        cols = f["histories/energy"].attrs["columns"].split(",")
        assert cols[-3:] == ["reinforcement_strain", "reinforcement_dissipation", "balance_error"]
    xdmf = elements_path(out).read_text()
    assert xdmf.count('TopologyType="Polyline"') == 3 and "/reinforcement/000002/axial" in xdmf
    text = summarise(out)
    assert "reinforcement: 1 elements, 6 segments" in text and "c[0]: axial" in text


def test_the_factor_of_safety_of_a_bolted_wedge_is_hoek_and_bray_s_with_the_bolt_force():
    """The wedge of pdem.cases.wedge (planes 45/005 and 55/135, friction 35 degrees: FS 1.955
    unbolted) held by a bolt from its centroid 1.2 m into the rock behind (20 degrees below
    the horizontal, against the line of intersection's trend), pretensioned to 0.95 T and
    yielding at T = 0.15 W: while the wedge slides the bolt pulls with T. The strength
    reduction weakens the joints, not the bolt, so its factor is the closed form's with the
    bolt's force in the resultant (pdem.analysis.wedge.bolted_wedge_factor_of_safety), to the
    search's tolerance (2 %; measured -0.23 %)."""
    from pdem.analysis.wedge import bolted_wedge_factor_of_safety, wedge_factor_of_safety
    from pdem.cases.wedge import RHO as ROCK
    from pdem.cases.wedge import WEDGE_D, WEDGE_N, D, G, wedge_scene
    from pdem.geometry.builders import from_planes

    phi = 35.0
    shape = from_planes(WEDGE_N, WEDGE_D)
    w = ROCK * shape.volume * G
    h = np.array([D[0], D[1], 0.0]) / math.hypot(D[0], D[1])
    tilt = math.radians(20.0)
    u = -math.cos(tilt) * h - math.sin(tilt) * np.array([0.0, 0.0, 1.0])
    p0, p1 = shape.centroid, shape.centroid + 1.2 * u
    t = 0.15 * w

    def vec(p):
        return "[" + ", ".join(repr(float(x)) for x in p) + "]"

    text = wedge_scene(phi).replace("solve: {time: 0.5, damping: none}",
                                    "solve: {damping: local, mass_scaling: true}") + f"""
reinforcement:
  - {{name: bolt, from: {vec(p0)}, to: {vec(p1)}, segments: 4, young: 2.0e11, area: 1.0e-4,
     yield_tension: {t!r}, pretension: {0.95 * t!r}, anchors: [from, to]}}
stages:
  - {{name: settle, solve: {{ratio: 1.0e-5, max_steps: 50000}}}}
  - {{name: strength, factor_of_safety: {{tolerance: 0.02, high: 4.0, max_steps: 20000,
                                        max_displacement: 0.02}}}}
"""
    got = simulation(text).run()["factor"]
    want, mode = bolted_wedge_factor_of_safety(45.0, 5.0, phi, 55.0, 135.0, phi, w, t * u)
    plain = wedge_factor_of_safety(45.0, 5.0, phi, 55.0, 135.0, phi)[0]
    print(f"\nbolted wedge: FS {got:.4f}, closed form {want:.4f} ({mode}; {plain:.4f} unbolted)")
    assert mode == "both" and want > 1.4 * plain
    assert got == pytest.approx(want, rel=0.02)


def test_a_cable_grouted_in_a_zoned_block_pulls_out_at_its_grout_strength():
    """The pull-out above with the rock a zoned block held at every gridpoint: the anchors
    are interpolated in its tetrahedra (rigid and zoned hosts are one seam), and the load
    at the joint levels off at ``s L_e`` as before."""
    s = 1.0e5
    text = PULL_OUT.format(rho=RHO, v=0.5, E=E, A=A, s=s, time=0.1).replace(
        "materials: {rock: {density: 2500.0}}",
        "materials: {rock: {density: 2500.0, young: 2.0e10, poisson: 0.25}}").replace(
        "material: rock, fixed: true}", "material: rock, fixed: true, zones: {size: 0.5}}")
    sim = simulation(text)
    e = sim.state.reinforcement
    sim.run()
    assert e.zoned[:8].all() and not e.zoned[8:].any()
    assert e.axial[7] == pytest.approx(s * 1.875, rel=2e-2)
    assert (e.slip[:8] > 0.01).all()


def test_a_cable_anchored_in_a_zoned_block_stretches_at_ea_over_l():
    """The pulled cable with the pulled block zoned (E 2e10: it stretches 1e-3 of the bar's
    stretch): the anchors, interpolated in its tetrahedra, part by ``F L / (E A)``; the
    reactions spread on its gridpoints hold it."""
    text = pulled(1.0e5, "local", "steps: 15000").replace(
        "materials: {rock: {density: 2500.0}}",
        "materials: {rock: {density: 2500.0, young: 2.0e10, poisson: 0.25}}").replace(
        "force: [100000.0, 0, 0]}", "force: [100000.0, 0, 0], zones: {size: 0.5}}")
    sim = simulation(text)
    sim.run()
    e = sim.state.reinforcement
    assert e.zoned.tolist() == [0, 0, 0, 0, 1, 1, 1]
    stretch = np.linalg.norm(e.ax[-1] - e.ax[0]) - 1.0
    print(f"\nzoned anchor: stretch {stretch:.6e} (F L/EA {1.0e5 / (E * A):.6e}), axial "
          f"{e.axial.min():.6g}..{e.axial.max():.6g}")
    assert stretch == pytest.approx(1.0e5 / (E * A), rel=2e-3)
    assert np.allclose(e.axial, 1.0e5, rtol=2e-3)
