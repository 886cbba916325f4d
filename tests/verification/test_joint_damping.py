"""Rayleigh damping's stiffness-proportional term at the joints (docs/dynamics.md, "Rayleigh
damping"): every closed sub-contact is a dashpot ``beta kn A`` normal and ``beta ks A`` in
shear (pdem.contact.forces.dashpot), so a block on its joint spring is a damped oscillator
whose fraction of critical is Rayleigh's ``(alpha / w + beta w) / 2``.

* A 1 m cube (2000 kg) on a fixed floor, kn = 1e9 Pa/m over 1 m^2 (``w`` = 707 rad/s,
  112.5 Hz), in free vertical vibration about its static overlap (start velocity 5 mm/s,
  amplitude 7 um against the 20 um overlap: it never opens): the logarithmic decay of its
  velocity peaks gives the fraction to within 3e-3 of the closed form, with the centre
  frequency at the contact's (0.05: the stiffness and mass terms half each) and at three
  times it (5/3 of 0.05, nine tenths of it the stiffness term's). The step is the undamped
  one times ``sqrt(1 + xi^2) - xi``, ``xi = beta / dt_crit``, to rounding.
* The same cube thrown at the floor without gravity (0.2 m/s) bounces off with the
  restitution of a linear spring-dashpot contact that lets go when its overlap returns to
  zero, ``e = exp(-zeta pi / sqrt(1 - zeta^2))``, to 1.5 %; after it, with nothing in contact,
  the energy budget's balance error is within the bound of the dashpots' booking (what they
  take out at the relative velocity of t - dt/2 against the integrator's mean velocity:
  ``c dt (v_close^2 + v_open^2) / 4 + (w dt)^2 / 4`` times what they dissipated, ``c = beta
  kn A``), and below 1 % of the energy damping took (measured 3e-4 to 4e-3).
* Housner's rocking block released from half its slenderness angle, Rayleigh 0.02 at 8 Hz:
  the mass term is a drag ``alpha`` on the pivoting block whose closed form (the pivot ODE
  with ``- alpha theta'``) gives the first impact's time to 0.5 %; the corner dashpots make
  the impact inelastic: the angular velocity ratio across it falls below 1 (1.025 undamped).
* A pile of blocks dropped with Rayleigh damping keeps its energy balance within 1 % of the
  energy put in (the rigid budget's own tolerance, tests/verification/test_energy.py).
* The zoned contact kernel: a zoned cube (E = 1e11 Pa) ringing on the same joint has the
  fraction of its mode's own frequency to 3e-3 (measured 6e-5: Rayleigh's ``C = alpha M +
  beta K`` holds for the zones and the joint together).
* A static stage then a Rayleigh stage: the dashpots and the lowered step come with the
  stage's damping.

Run: ``.venv/bin/python -m pytest -q -s tests/verification/test_joint_damping.py``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from pdem.cases import make_simulation
from pdem.cases.collapse import pile_scene
from pdem.cases.oscillator import (
    KN,
    RHO,
    cube_on_floor,
    rayleigh,
    rayleigh_fraction,
    static_overlap,
)
from pdem.cases.shaking import (
    housner_restitution,
    pivot_impact_time,
    rocking_constants,
    tilted_scene,
)
from pdem.deformable.motion import rayleigh_limit
from pdem.plugins.base import Plugin
from pdem.plugins.energy import balance, energy_totals

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_base_motion import run_rocker  # noqa: E402

OMEGA = math.sqrt(KN * 1.0 / RHO)  # the cube on its 1 m^2 joint, rad/s
FREQ = OMEGA / (2.0 * math.pi)
FRACTION = 0.05
TOL_DECAY = 3e-3  # relative, on the fraction (measured 6e-4 and 1e-4)
# relative: the dashpot comes on at the full closing speed and the opening is resolved to a
# step, each ~ zeta w dt (4e-3 at zeta 0.083); measured 1e-3 to 7e-3
TOL_RESTITUTION = 1.5e-2


class Recorder(Plugin):
    """``fn(state)`` (a tuple) after every step, with the time."""

    name = "recorder"

    def __init__(self, state, fn):
        self.state = state
        self.fn = fn
        self.rows = []

    def after_step(self, run):
        self.rows.append((self.state.time, *self.fn(self.state)))


def recorded(sim, fn) -> np.ndarray:
    rec = Recorder(sim.state, fn)
    sim.runner.plugins.append(rec)
    sim.run()
    return np.array(rec.rows)


def cube_row(sim) -> int:
    return int(np.nonzero(sim.blocks.fixed == 0)[0][0])


def decay_fraction(t, v) -> tuple[float, int]:
    """The fraction of critical of a decaying oscillation ``v(t)`` from its positive peaks
    (each refined by the parabola through it and its neighbours): the log's slope ``-zeta
    w_n`` over the peaks and the damped frequency from their spacing; and the peak count."""
    k = np.nonzero((v[1:-1] > v[:-2]) & (v[1:-1] >= v[2:]) & (v[1:-1] > 0.0))[0] + 1
    y0, y1, y2 = v[k - 1], v[k], v[k + 1]
    off = 0.5 * (y0 - y2) / (y0 - 2.0 * y1 + y2)
    peak = y1 - 0.25 * (y0 - y2) * off
    tp = t[k] + off * (t[1] - t[0])
    slope = np.polyfit(tp, np.log(peak), 1)[0]
    wd = 2.0 * math.pi / float(np.mean(np.diff(tp)))
    r = -slope / wd  # zeta / sqrt(1 - zeta^2)
    return r / math.sqrt(1.0 + r * r), len(k)


@pytest.mark.parametrize("centre", [1.0, 3.0])
def test_contact_oscillator_decays_at_the_rayleigh_fraction(centre):
    v0 = 0.005
    text = cube_on_floor(-static_overlap(), velocity=(0.0, 0.0, -v0), end="time: 0.05",
                         damping=rayleigh(FRACTION, centre * FREQ))
    sim = make_simulation(text)
    r = cube_row(sim)
    a = recorded(sim, lambda s: (s.blocks.v[r, 2],))
    zeta, peaks = decay_fraction(a[:, 0], a[:, 1])
    want = rayleigh_fraction(FRACTION, centre * FREQ, FREQ)
    undamped = make_simulation(cube_on_floor(-static_overlap(), end="steps: 1")).dt
    beta = FRACTION / (2.0 * math.pi * centre * FREQ)
    frac = sim.state.scene.solve.timestep.frac
    step = frac * rayleigh_limit(undamped / frac, beta)
    print(f"centre {centre:g} x {FREQ:.2f} Hz: fraction {zeta:.6f} over {peaks} peaks, closed "
          f"form {want:.6f} ({zeta / want - 1:+.2e}); step {sim.dt:.4e} s, undamped "
          f"{undamped:.4e} s")
    assert peaks >= 5
    assert abs(zeta / want - 1.0) < TOL_DECAY
    assert sim.dt == pytest.approx(step, rel=1e-12) and sim.dt < undamped


@pytest.mark.parametrize("fraction,centre", [(0.05, 1.0), (0.05, 3.0), (0.2, 1.0), (0.05, 1 / 3)])
def test_a_bounce_loses_what_the_dashpots_take_and_the_budget_balances(fraction, centre):
    v0 = 0.2
    text = cube_on_floor(0.0, gravity=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, -v0),
                         end="time: 0.03", damping=rayleigh(fraction, centre * FREQ))
    sim = make_simulation(text)
    r = cube_row(sim)
    a = recorded(sim, lambda s: (s.blocks.x[r, 2] - 0.5, s.blocks.v[r, 2]))
    t, z, v = a[:, 0], a[:, 1], a[:, 2]
    k = int(np.nonzero(z > 0.0)[0][0])  # the step the contact opened
    t_open = t[k - 1] + (t[k] - t[k - 1]) * -z[k - 1] / (z[k] - z[k - 1])
    v_open = float(np.interp(t_open, t - 0.5 * sim.dt, v))  # velocities are at t - dt/2
    zeta = rayleigh_fraction(fraction, centre * FREQ, FREQ)
    e = math.exp(-zeta * math.pi / math.sqrt(1.0 - zeta * zeta))
    budget = energy_totals(sim.state)
    err, _ = balance(budget, sim.runner.plugin("energy").e0)
    took = budget["damping_dissipation"]
    c = fraction / (2.0 * math.pi * centre * FREQ) * KN * 1.0
    bound = c * sim.dt * (v0 ** 2 + v_open ** 2) / 4.0 + (OMEGA * sim.dt) ** 2 / 4.0 * took
    print(f"fraction {fraction} at {centre:.3g} f: restitution {v_open / v0:.5f}, closed form "
          f"{e:.5f} ({v_open / v0 / e - 1:+.2e}); damping took {took:.4g} J of "
          f"{0.5 * RHO * v0 ** 2:.4g}, balance error {err:.3g} J ({err / took:+.2e}), bound "
          f"{bound:.3g} J")
    assert abs(v_open / v0 / e - 1.0) < TOL_RESTITUTION
    assert budget["strain"] == 0.0  # apart: nothing stored in the joint
    assert abs(err) < min(bound, 1e-2 * took)


def test_rocking_block_impact_with_rayleigh_at_the_contacts():
    fraction, centre = 0.02, 8.0
    drag = fraction * 2.0 * math.pi * centre
    alpha, _, _ = rocking_constants()
    theta0 = 0.5 * alpha
    t, tilt, w = run_rocker(tilted_scene(theta0, 0.7, rayleigh(fraction, centre)))
    tilt = tilt + theta0
    k = int(np.nonzero(tilt <= 0.0)[0][0])
    f = tilt[k - 1] / (tilt[k - 1] - tilt[k])
    tc = t[k - 1] + f * (t[k] - t[k - 1])
    w_before = w[k - 1] + f * (w[k] - w[k - 1])
    t_pivot, w_pivot = pivot_impact_time(theta0, drag=drag)
    t_free, _ = pivot_impact_time(theta0)
    after = (t > tc + 0.005) & (t < tc + 0.04)
    c = np.polyfit(t[after] - tc, w[after], 1)
    ratio = c[1] / w_before
    print(f"Rayleigh {fraction} at {centre} Hz: first impact at {tc:.5f} s, damped pivot "
          f"{t_pivot:.5f} ({tc / t_pivot - 1:+.2e}; undamped {t_free:.5f}); w before "
          f"{w_before:.4f} (pivot {w_pivot:.4f}); ratio across the impact {ratio:.4f} "
          f"(Housner {housner_restitution():.3f})")
    assert abs(tc / t_pivot - 1.0) < 5e-3
    assert abs(t_pivot / t_free - 1.0) > 5e-2  # the drag is seen, not within the tolerance
    assert ratio < 1.0


def test_a_dropped_pile_with_rayleigh_damping_balances():
    text = pile_scene(count=12, time=0.6).replace(
        "damping: none", "damping: {mode: rayleigh, fraction: 0.05, frequency: 10.0}")
    sim = make_simulation(text)
    sim.run()
    t = energy_totals(sim.state)
    err, put_in = balance(t, sim.runner.plugin("energy").e0)
    print(f"pile: gravity work {t['gravity_work']:.4g} J, damping took "
          f"{t['damping_dissipation']:.4g} J, joints {t['joint_dissipation']:.4g} J, balance "
          f"error {err:.3g} J ({err / put_in:+.2e} of what was put in)")
    assert t["damping_dissipation"] > 0.05 * put_in
    assert abs(err) < 1e-2 * put_in


ZONED_CUBE = """
name: zoned-cube-on-its-joint
gravity: [0, 0, -9.81]
materials:
  rock: {{density: 2000.0}}
  stiff: {{density: 2000.0, young: 1.0e11, poisson: 0.25}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 60.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - name: cube
    box: {{min: [-0.5, -0.5, {z0!r}], max: [0.5, 0.5, {z1!r}]}}
    material: stiff
    zones: {{size: 0.5}}
    velocity: [0, 0, -0.005]
solve: {{time: 0.05, damping: {damping}}}
"""


@pytest.mark.parametrize("centre", [1.0, 3.0])
def test_a_zoned_block_rings_on_its_joint_at_the_rayleigh_fraction(centre):
    """The zoned contact kernel's dashpots: a zoned cube (E = 1e11 Pa, 100 times the joint's
    kn A / 1 m) on the floor's joint, in free vertical vibration. Rayleigh damping is ``C =
    alpha M + beta K`` with ``K`` the zones' and the joint's stiffness together, so the mode
    has ``(alpha / w + beta w) / 2`` at its own frequency ``w`` (measured from the peaks,
    below the rigid block's by the zones' compliance). Without the joint's dashpot it would
    be nearly the mass term's alone (0.025 and 0.008)."""
    d = static_overlap()
    text = ZONED_CUBE.format(z0=-d, z1=1.0 - d, damping=rayleigh(FRACTION, centre * FREQ))
    sim = make_simulation(text)
    r = cube_row(sim)
    a = recorded(sim, lambda s: (s.blocks.v[r, 2],))
    zeta, peaks = decay_fraction(a[:, 0], a[:, 1])
    t, v = a[:, 0], a[:, 1]
    k = np.nonzero((v[1:-1] > v[:-2]) & (v[1:-1] >= v[2:]) & (v[1:-1] > 0.0))[0] + 1
    wd = 2.0 * math.pi / float(np.mean(np.diff(t[k])))
    w = wd / math.sqrt(1.0 - zeta * zeta)
    want = rayleigh_fraction(FRACTION, centre * FREQ, w / (2.0 * math.pi))
    print(f"zoned cube, centre {centre:g} x {FREQ:.2f} Hz: fraction {zeta:.6f} over {peaks} "
          f"peaks at {w / (2 * math.pi):.2f} Hz, closed form {want:.6f} ({zeta / want - 1:+.2e})"
          f"; step {sim.dt:.3e} s")
    assert peaks >= 5
    assert abs(zeta / want - 1.0) < TOL_DECAY


def test_a_dynamic_stage_puts_the_dashpots_on_and_lowers_the_step():
    """A static stage (no damping) then a Rayleigh stage: the joints' dashpots and the rigid
    step follow the stage's ``solve.damping`` (pdem.stages re-estimates the step)."""
    beta = FRACTION / OMEGA
    text = cube_on_floor(-static_overlap(), end="steps: 1").replace(
        "solve: {steps: 1, damping: none}",
        "solve: {damping: none}\nstages:\n  - {name: static, solve: {steps: 20}}\n"
        f"  - {{name: dynamic, solve: {{steps: 20, damping: {rayleigh(FRACTION, FREQ)}}}}}\n")
    sim = make_simulation(text)
    a = recorded(sim, lambda s: (s.stage, s.dt, s.joints.kernel_args.dash.ndim))
    static, dynamic = a[a[:, 1] == 0], a[a[:, 1] == 1]
    undamped = static[0, 2]
    frac = sim.state.scene.solve.timestep.frac
    assert len(static) == len(dynamic) == 20
    assert (static[:, 3] == 1).all() and (dynamic[:, 3] == 2).all()  # no dashpots, dashpots
    assert dynamic[0, 2] == pytest.approx(frac * rayleigh_limit(undamped / frac, beta),
                                          rel=1e-12)
    assert dynamic[0, 2] < undamped


@pytest.mark.parametrize("beta", [0.0, 1e-5, 4e-4])
def test_mass_scaling_aims_at_the_step_the_dashpots_allow(beta):
    """Mass scaling under Rayleigh damping scales the blocks for the undamped step whose
    damped limit is the step asked for (pdem.resolve.damped_target): ``frac`` times the
    damped limit of its critical step is ``dt`` again."""
    from pdem.resolve import damped_target

    dt, frac = 1e-4, 0.1
    target = damped_target(dt, frac, beta)
    assert frac * rayleigh_limit(target / frac, beta) == pytest.approx(dt, rel=1e-12)
    assert target >= dt and (target == dt) == (beta == 0.0)
