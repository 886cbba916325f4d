"""Translational dynamics of one block: contact oscillator, free fall, elastic bounce.

A unit cube (side 1 m, density rho, so m = rho) rests face-on on a fixed floor box; the
contact area is A = 1 m^2 and the joint normal stiffness kn (Pa/m), so the contact is a
linear spring of stiffness kn A on the overlap un > 0 and nothing when open. No damping.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdem.cases import crossing_times, make_simulation
from pdem.cases.oscillator import (
    KN,
    RHO,
    G,
    contact_duration,
    cube_on_floor,
    free_fall_scene,
    period,
    static_overlap,
)


@pytest.mark.parametrize("algorithm", ["fast", "cundall"])
def test_vertical_period(algorithm):
    """Cube under gravity started at twice its static overlap ``delta = m g / (kn A)`` with
    zero velocity: it oscillates about the static position with amplitude delta, the contact
    never opens, and the period is ``T = 2 pi sqrt(m / (kn A))``. Measured from the upward
    zero crossings of the vertical velocity over ~30 periods; tolerance 1 %. (The leapfrog
    itself shortens the period by (omega dt)^2 / 24 ~ 0.02 % at the automatic step.)"""
    m = RHO
    delta = static_overlap(m, KN)
    s = make_simulation(cube_on_floor(-2.0 * delta, algorithm=algorithm))
    b = s.blocks
    i = int(np.nonzero(b.fixed == 0)[0][0])
    T = period(m, KN)
    n = int(30 * T / s.dt)
    t = np.empty(n)
    vz = np.empty(n)
    for k in range(n):
        s.advance()
        t[k] = s.time - 0.5 * s.dt  # v is at the half step
        vz[k] = b.v[i, 2]
    tc = crossing_times(t, vz)
    assert len(tc) >= 25
    measured = (tc[-1] - tc[0]) / (len(tc) - 1)
    err = abs(measured / T - 1.0)
    # amplitude: max speed omega * delta
    v_amp = math.sqrt(KN / m) * delta
    print(f"{algorithm}: period {measured:.6e} s, exact {T:.6e} s, rel.err {err:.2e}; "
          f"speed amplitude {vz.max():.4e} vs {v_amp:.4e}")
    assert err < 1e-2
    assert abs(vz.max() / v_amp - 1.0) < 1e-2
    assert np.abs(b.w[i]).max() < 1e-9


def test_contact_duration_zero_gravity():
    """Zero gravity, the cube just above the floor moving down at v0: the contact is half a
    cycle of the spring, lasting ``pi sqrt(m / (kn A))`` (1 %), and the cube leaves with
    velocity +v0 (1 %)."""
    m = RHO
    v0 = 0.05
    s = make_simulation(cube_on_floor(1e-4, gravity=(0, 0, 0), velocity=(0, 0, -v0)))
    b = s.blocks
    i = int(np.nonzero(b.fixed == 0)[0][0])
    half = contact_duration(m, KN)
    bottom = b.x[i, 2] - 0.5  # bottom face height (the cube does not turn)
    touch = 1e-4 / v0
    n = int((touch + 2.0 * half) / s.dt)
    z = np.empty(n)
    t = np.empty(n)
    for k in range(n):
        s.advance()
        t[k] = s.time
        z[k] = b.x[i, 2] - 0.5
    # closing and opening times, where the bottom face crosses z = 0
    down = crossing_times(t, -z)
    up = crossing_times(t, z)
    assert len(down) == 1 and len(up) == 1
    duration = up[0] - down[0]
    err = abs(duration / half - 1.0)
    print(f"contact duration {duration:.6e} s, exact {half:.6e} s, rel.err {err:.2e}; "
          f"rebound v {b.v[i, 2]:.6f} (v0 {v0}); start {bottom:.1e}")
    assert err < 1e-2
    assert abs(b.v[i, 2] / v0 - 1.0) < 1e-2


def test_free_fall_exact():
    """No contacts (one block in space): the central-difference scheme started with the
    staggered velocity is exact for constant acceleration, so
    ``x(t) = x0 + v0 t + g t^2 / 2`` to 1e-9 relative (of the displacement) at every step,
    and the half-step velocity is ``v0 + g (t - dt/2)``."""
    g = np.array([1.5, -2.0, -G])
    v0 = np.array([0.7, 0.3, 4.0])
    s = make_simulation(free_fall_scene(g, v0))
    b = s.blocks
    x0 = b.x0[0].copy()
    worst_x = 0.0
    worst_v = 0.0
    for _ in range(3000):
        s.advance()
        t = s.time
        exact = x0 + v0 * t + 0.5 * g * t * t
        worst_x = max(worst_x, np.linalg.norm(b.x[0] - exact) / np.linalg.norm(exact - x0))
        ve = v0 + g * (t - 0.5 * s.dt)
        worst_v = max(worst_v, np.linalg.norm(b.v[0] - ve) / np.linalg.norm(ve))
    print(f"free fall: max rel. position error {worst_x:.2e}, velocity {worst_v:.2e}, "
          f"t = {s.time:.4f} s")
    assert s.contacts.n == 0
    assert worst_x < 1e-9
    assert worst_v < 1e-9
    assert np.abs(b.w[0]).max() == 0.0


def test_static_start_stays_at_rest():
    """The cube placed at its static overlap ``m g / (kn A)`` with zero velocity is in
    equilibrium at t = 0 and must stay at rest: |v| < 1e-9 m/s over 2000 steps (the
    stagger bug gives it g dt / 2 ~ 5e-4 m/s)."""
    s = make_simulation(cube_on_floor(-RHO * G / KN))
    b = s.blocks
    i = int(np.nonzero(b.fixed == 0)[0][0])
    vmax = 0.0
    for _ in range(2000):
        s.advance()
        vmax = max(vmax, float(np.abs(b.v[i]).max()))
    print(f"resting cube: max speed {vmax:.2e} m/s (g dt / 2 = {0.5 * G * s.dt:.2e})")
    assert vmax < 1e-9


def test_elastic_bounce():
    """A cube dropped face-on from h = 1 cm onto the floor, friction 60 deg, no damping.

    Total energy ``E = K + m g z + sum 1/2 kn A_s un_s^2`` (elastic energy over sub-contacts
    with un > 0, from ``contacts.sc_un`` and ``sc_area``) is conserved across the bounce to
    0.5 % of the drop energy m g h, and the rebound height equals h within 0.5 %.

    The kinetic energy at step time t uses the leapfrog's time-centred form
    ``K = 1/2 m v(t - dt/2) . v(t + dt/2)``, the quantity the central-difference scheme
    conserves exactly for a linear spring; ``1/2 m |v_mean|^2`` would differ from it by
    ``m a^2 dt^2 / 8``, ~0.5 % of the contact energy at this step.
    """
    h = 0.01
    m = RHO
    s = make_simulation(cube_on_floor(h, end="time: 1.0"))
    b = s.blocks
    i = int(np.nonzero(b.fixed == 0)[0][0])
    assert np.all(s.state.joints.kn == KN)

    def elastic() -> float:
        c = s.contacts
        kn = s.state.joints.kn[np.repeat(c.joint, np.diff(c.sc_start))]
        un = np.maximum(c.sc_un, 0.0)
        return 0.5 * float(np.sum(kn * c.sc_area * un * un))

    n = int((2.0 * math.sqrt(2.0 * h / G) + 0.02) / s.dt)
    energy = np.empty(n)
    bottom = np.empty(n)
    for k in range(n):
        v_minus = b.v[i].copy()
        z = b.x[i, 2]
        pot = m * G * z + elastic()
        s.advance()
        energy[k] = 0.5 * m * float(v_minus @ b.v[i]) + pot
        bottom[k] = z - 0.5
    e_drop = m * G * h
    drift = (energy.max() - energy.min()) / e_drop
    lowest = int(np.argmin(bottom))
    rebound = bottom[lowest:].max() / h
    print(f"bounce: energy variation {drift:.2e} of m g h, rebound/drop {rebound:.6f}, "
          f"max overlap {-bottom.min():.2e} m")
    assert bottom.min() < 0.0  # it did hit the floor
    assert bottom[-1] > 0.5 * h  # and came back up
    assert drift < 5e-3
    assert abs(rebound - 1.0) < 5e-3
    assert np.abs(b.w[i]).max() < 1e-9
