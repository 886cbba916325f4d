"""Every damping mode at the gridpoints of zoned blocks, against closed forms
(docs/deformable.md, "Damping"):

(a) viscous damping (eq. 49, inertial mass) decays a free block's rigid motion as
    ``((1 - alpha dt/2) / (1 + alpha dt/2))^n`` = ``exp(-alpha t)`` to O((alpha dt)^2), at
    every gridpoint alike although mass scaling made their masses differ (no strain), and a
    vibration's amplitude as ``exp(-alpha t / 2)``;
(b) combined damping (eq. 83) leaves a push that grows along the motion undamped (its
    ``sgn(v) - sgn(dF/dt)`` is 0) where local damping takes ``alpha`` of it; under a constant
    force it takes half of local's;
(c) every mode books what it takes out: kinetic energy's change + the work on the zones + the
    damping's (``GW_DAMPING``) is nil to round-off;
(d) the timestep bound of each mode holds: viscous damping keeps the undamped limit, combined
    needs local's ``(1 + alpha)``;
(e) a zoned column on a floor settles to ``rho g H^2 / 2E`` plus the joint closure under each
    mode (scene level), and a stage may change the mode.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.deformable.body import DeformableBody
from pdem.deformable.mesh import tetrahedralise
from pdem.deformable.motion import GW_DAMPING, GW_ZONE, VISCOUS
from pdem.geometry import box
from pdem.simulation import Simulation

E, NU, RHO = 1.0e9, 0.25, 1000.0
BAR_L, BAR_W = 1.0, 0.25


@pytest.fixture(scope="module")
def bar_mesh():
    return tetrahedralise(box([0, 0, 0], [BAR_W, BAR_W, BAR_L]), 0.125)


def test_viscous_decays_a_free_blocks_motion_uniformly():
    alpha = 0.01  # 1/s, with the mass-scaled step dt = 1: alpha dt = 0.01
    b = DeformableBody(box([0, 0, 0], [1, 1, 2]), dict(density=RHO, young=E, poisson=NU),
                       size=0.5, damping=alpha, damping_mode="viscous", mass_scaling=True)
    assert np.ptp(b.mass) > 0.1 * b.mass.max()  # scaled: the gridpoints' masses differ
    v0 = np.array([0.3, -0.2, 0.1])
    b.vel[:] = v0
    ke0 = b.kinetic_energy()
    n = 500
    b.step(n, 1.0)
    r = (1.0 - 0.5 * alpha) / (1.0 + 0.5 * alpha)
    got = b.vel / v0
    exact = math.exp(-alpha * n)
    print(f"viscous: v/v0 {got.mean():.12f}, discrete {r ** n:.12f}, exp(-alpha t) {exact:.12f}")
    assert np.abs(got - r ** n).max() < 1e-12
    # the eq. 49 factor is exp(-alpha dt) to (alpha dt)^3 / 12 a step
    assert abs(r ** n / exact - 1.0) < n * alpha ** 3 / 12 * 1.01
    # damped alike: no strain but round-off's (E 1e-15); a decay at alpha m / m_inertial
    # would part the gridpoints at tenths of their speed
    assert np.abs(b.stress).max() < 1e-4
    assert abs(b.work[GW_DAMPING] - (ke0 - b.kinetic_energy())) < 1e-12 * ke0


def _bar(bar_mesh, mode, alpha):
    """The first axial mode of a bar on rollers (tests/unit/test_deformable_elastic.py)."""
    b = DeformableBody(bar_mesh, dict(density=RHO, young=E, poisson=0.0), damping=alpha,
                       damping_mode=mode)
    x0 = b.nodes0
    b.fix(np.isclose(x0[:, 2], 0.0), dofs=(2,))
    b.fix(np.isclose(x0, [BAR_W / 2, BAR_W / 2, 0.0]).all(axis=1))
    b.vel[:, 2] = 0.01 * np.sin(np.pi * x0[:, 2] / (2 * BAR_L))
    return b


def test_viscous_vibration_amplitude_decays_at_half_alpha(bar_mesh):
    omega = math.pi * math.sqrt(E / RHO) / (2 * BAR_L)
    alpha = 0.05 * omega
    b = _bar(bar_mesh, "viscous", alpha)
    top = np.isclose(b.nodes0[:, 2], BAR_L)
    dt = b.timestep()
    n = int(4.3 * 2 * math.pi / omega / dt)
    u = np.empty(n)
    for k in range(n):
        b.step(1, dt)
        u[k] = b.displacement[top, 2].mean()
    t = dt * np.arange(1, n + 1)
    # the amplitude at the displacement's extremes (parabola through the three samples)
    peaks = [k for k in range(1, n - 1) if abs(u[k]) >= abs(u[k - 1]) and abs(u[k]) > abs(u[k + 1])]
    amp, when = [], []
    for k in peaks:
        a, c = 0.5 * (u[k + 1] + u[k - 1]) - u[k], 0.5 * (u[k + 1] - u[k - 1])
        amp.append(abs(u[k] - c * c / (4 * a)))
        when.append(t[k] - c / (2 * a) * dt)
    rate = -np.polyfit(when, np.log(amp), 1)[0]
    # a damped oscillator's amplitude decays at alpha/2 whatever its frequency
    print(f"viscous bar: amplitude decay rate {rate:.4g} 1/s, alpha/2 {alpha / 2:.4g} "
          f"({rate / (alpha / 2) - 1:+.2%}) over {len(amp)} extremes")
    assert len(amp) >= 8
    assert abs(rate / (alpha / 2) - 1.0) < 0.02


@pytest.mark.parametrize("mode, alpha", [("local", 0.8), ("combined", 0.8), ("viscous", 400.0),
                                         ("none", 0.0)])
def test_damping_is_booked(bar_mesh, mode, alpha):
    """The leap-frog's exact balance: the kinetic energy's change is the work of the zone
    forces (-GW_ZONE) less the damping's (GW_DAMPING) to round-off, for every mode."""
    b = _bar(bar_mesh, mode, alpha)
    ke0 = b.kinetic_as_integrated()
    b.step(3000)
    lost = b.work[GW_DAMPING]
    gap = b.kinetic_as_integrated() - ke0 + b.work[GW_ZONE] + lost
    print(f"{mode}: damping took {lost / ke0:.4f} of the start's energy; balance {gap / ke0:.1e}")
    assert abs(gap) < 1e-9 * ke0
    if mode == "none":
        assert lost == 0.0
    else:  # it dissipated: most of the vibration's energy is gone
        assert lost > 0.5 * ke0


def _free_pushed(mode, alpha, push):
    """A free zoned block (no gravity, true masses) moving along +x at 0.1 m/s, pushed along
    +x by the acceleration ``push(t)`` (a force spread by mass: no strain); its velocity gain
    after 400 steps and the undamped one."""
    b = DeformableBody(box([0, 0, 0], [1, 1, 1]), dict(density=RHO, young=E, poisson=NU),
                       size=0.5, damping=alpha, damping_mode=mode)
    b.vel[:, 0] = 0.1
    dt = b.timestep()
    undamped = 0.0
    for k in range(400):
        b.applied[:, 0] = b.gravity_mass * push(k * dt)
        undamped += push(k * dt) * dt
        b.step(1, dt)
    return b.vel[:, 0] - 0.1, undamped


def test_combined_leaves_a_growing_push_undamped():
    """A push growing along the motion (dF/dt and v of one sign): eq. 83's
    ``sgn(v) - sgn(dF/dt)`` is 0, no damping force; local damping takes alpha of it. (Steady
    motion without force is damped by neither.)"""
    ramp = lambda t: 1.0e3 * t  # noqa: E731  (m/s^3)
    got_c, undamped = _free_pushed("combined", 0.8, ramp)
    got_l, _ = _free_pushed("local", 0.8, ramp)
    print(f"growing push: combined keeps {got_c.mean() / undamped:.12f} of the velocity gain, "
          f"local {got_l.mean() / undamped:.12f}")
    assert np.abs(got_c / undamped - 1.0).max() < 1e-9
    assert np.abs(got_l / undamped - 0.2).max() < 1e-9  # (1 - alpha)
    still, _ = _free_pushed("combined", 0.8, lambda t: 0.0)
    assert np.abs(still).max() < 1e-12


def test_timestep_bound_of_each_mode(bar_mesh):
    spec = dict(density=RHO, young=E, poisson=NU)
    dts = {}
    for mode, alpha in (("none", 0.0), ("local", 0.8), ("combined", 0.8), ("viscous", 0.0)):
        dts[mode] = DeformableBody(bar_mesh, spec, damping=alpha, damping_mode=mode).timestep()
    assert dts["combined"] == dts["local"] == pytest.approx(dts["none"] / math.sqrt(1.8), 1e-12)
    # viscous damping keeps the undamped limit for any alpha (here alpha dt = 1.5): an
    # all-mode start at 0.98 of it stays bounded, and so does combined at its bound
    for mode, alpha, dt in (("viscous", 1.5 / dts["none"], 0.98 * dts["none"]),
                            ("combined", 0.8, 0.98 * dts["combined"])):
        b = DeformableBody(bar_mesh, spec, damping=alpha, damping_mode=mode)
        b.vel[:] = np.random.default_rng(0).normal(size=b.vel.shape) * 1e-4
        ke0 = b.kinetic_energy()
        b.step(3000, dt)
        assert b.kinetic_energy() + b.strain_energy() < ke0, mode


# --- scenes ---------------------------------------------------------------------------------
G = 9.81
KN = 1.0e9
COLUMN = """
name: column
materials:
  rock: {{density: {rho}}}
  soft: {{density: {rho}, young: {E}, poisson: 0.0}}
joints: {{default: {{kn: {kn}, ks: {kn}, friction: 30}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: column, box: {{min: [0, 0, 0], max: [1, 1, {H}]}}, material: soft, zones: {{size: 0.5}}}}
solve: {{damping: {damping}}}
stages: {stages}
"""


def settle(damping: str, stages: str):
    E, H = 1.0e8, 2.0
    sim = Simulation(parse_scene(COLUMN.format(rho=RHO, E=E, kn=KN, H=H, damping=damping,
                                               stages=stages)), MPI.COMM_SELF, output=False)
    sim.run()
    body = sim.state.grids.bodies[0]
    top = body.nodes0[:, 2] > H - 1e-9
    settle = RHO * G * H ** 2 / (2.0 * E) + RHO * G * H / KN
    err = -body.displacement[top, 2].mean() / settle - 1.0
    return sim, body, err


# viscous: alpha near critical for the column's first mode (omega = pi c / 2H = 250 1/s)
@pytest.mark.parametrize("damping", ["combined", "{mode: viscous, alpha: 400}",
                                     "{mode: adaptive, alpha: 10}"])
def test_column_settles_under_each_mode(damping):
    sim, body, err = settle(damping, "[{name: settle, solve: {steps: 6000}}]")
    print(f"{damping}: top settlement error {err:+.2e}, speed {body.max_speed():.2e}, "
          f"alpha {sim.state.alpha:.4g}")
    assert abs(err) < 1e-3
    assert body.max_speed() < 1e-4
    if "adaptive" in damping:  # the grids followed the servo's alpha (one update behind)
        assert body.damping != 10.0
        assert abs(body.damping / sim.state.alpha - 1.0) <= 0.1
    sim.close()


def test_a_stage_changes_the_grids_damping():
    stages = ("[{name: a, solve: {steps: 300}}, "
              "{name: b, solve: {steps: 5700, damping: {mode: viscous, alpha: 400}}}]")
    sim, body, err = settle("local", stages)
    assert body.damping_mode == VISCOUS and body.damping == 400.0
    assert abs(err) < 1e-3
    sim.close()
