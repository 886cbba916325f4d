"""Waves in zoned blocks against closed forms (issue 41; pdem.cases.waves, docs/dynamics.md):
quiet boundaries and wave input, Rayleigh damping, transmission across a joint.

- A shear and a compressional pulse put in through a quiet base of a 20 m zoned column go up,
  reflect at the free top and leave through the base: the column holds ``rho C A int v^2 dt``
  while the pulse is in it (measured 0.9997, asserted 1 %) and is left with 1e-6 of it
  (asserted < 2 %, the issue's bound); a held base keeps all of it (the same pulse driven by
  the base's velocity). The energy budget books what the dashpots absorb (twice the pulse:
  half the wave traction's work as it goes in, the pulse as it leaves) and balances to 1e-15.
- Rayleigh damping: the free vibration of a held-base shear column (uniform start velocity)
  projected on its fundamental mode decays at ``(alpha / omega + beta omega) / 2`` of the
  measured frequency, with the centre frequency at the fundamental (the requested fraction)
  and at three times it (5/3 of it): measured to 1e-5, asserted 1 %.
- Pyrak-Nolte's joint: a harmonic P or S wave through two zoned bars joined by a joint of
  specific stiffness kappa, quiet at both ends: the upper bar's velocity amplitude over the
  incident one, against ``1 / sqrt(1 + (omega Z / 2 kappa)^2)`` at omega Z / 2 kappa = 1
  (20 Hz) and 2 (40 Hz): measured within 0.6 %, asserted 2 %.
"""

import math

import numpy as np
import pytest
from mpi4py import MPI

from pdem.cases.waves import (
    RHO,
    WAVES,
    column_scene,
    decay_scene,
    joint_bars_scene,
    pulse_energy,
    rayleigh_fraction,
    released_column_scene,
    transmission,
)
from pdem.config import ConfigError, parse_scene
from pdem.plugins.energy import balance, energy_totals
from pdem.simulation import Simulation


def simulation(text: str) -> Simulation:
    return Simulation(parse_scene(text), MPI.COMM_SELF, output=False)


def layer(nodes0: np.ndarray, z: float) -> np.ndarray:
    """The gridpoints of the mesh layer nearest to height ``z``."""
    near = nodes0[np.argmin(np.abs(nodes0[:, 2] - z)), 2]
    return np.nonzero(np.abs(nodes0[:, 2] - near) < 1e-9)[0]


# ------------------------------------------------------------------ quiet base
HEIGHT = 20.0


@pytest.mark.parametrize("wave", ["S", "P"])
@pytest.mark.parametrize("base", ["quiet", "held"])
def test_a_pulse_leaves_through_a_quiet_base(wave, base):
    duration = 0.04 if wave == "S" else 0.025  # 18 and 19 m long, 36-56 zones
    c = WAVES[wave][2]
    sim = simulation(column_scene(wave, HEIGHT, 0.5, base=base, duration=duration))
    s = sim.state
    t0 = energy_totals(s)
    e0 = t0["kinetic"] + t0["strain"]
    pulse = pulse_energy(0.1, duration, RHO * c)
    held, worst = 0.0, 0.0
    while s.time < duration + 2.0 * HEIGHT / c + 0.02:  # up, back down, and out
        sim.stepper.advance()
        if s.step % 10:
            continue
        t = energy_totals(s)
        held = max(held, t["kinetic"] + t["zone_strain"])
        err, put_in = balance(t, e0)
        worst = max(worst, abs(err) / put_in)
    left = (t["kinetic"] + t["zone_strain"]) / held
    print(f"{wave} pulse, {base} base: {s.step} steps, held {held / pulse:.5f} of rho C A int "
          f"v^2, left {left:.2e} of it, quiet absorbed {t['quiet_absorbed'] / pulse:.5f}, "
          f"balance {worst:.1e}")
    assert abs(held / pulse - 1.0) < 0.01
    assert worst < 1e-9
    if base == "quiet":
        assert left < 0.02
        assert abs(t["quiet_absorbed"] / pulse - 2.0) < 0.02
    else:
        assert left > 0.98 and t["quiet_absorbed"] == 0.0


# ------------------------------------------------------------------ Rayleigh damping
@pytest.mark.parametrize("centre_over_f1", [1.0, 3.0])
def test_rayleigh_damping_decays_the_fundamental_mode_at_its_fraction(centre_over_f1):
    height, fraction = 10.0, 0.05
    f1 = WAVES["S"][2] / (4.0 * height)  # a held-base shear column's fundamental
    sim = simulation(decay_scene(height, fraction, centre_over_f1 * f1))
    s = sim.state
    body = s.grids.bodies[0]
    shape = np.sin(math.pi * body.nodes0[:, 2] / (2.0 * height))
    m = body.gravity_mass
    ts, qs = [], []
    while s.time < 4.0 / f1:
        sim.stepper.advance()
        u = body.nodes[:, 0] - body.nodes0[:, 0]
        ts.append(s.time)
        qs.append(float(np.sum(m * shape * u) / np.sum(m * shape * shape)))
    ts, q = np.array(ts), np.abs(np.array(qs))
    k = np.nonzero((q[1:-1] > q[:-2]) & (q[1:-1] >= q[2:]))[0] + 1  # half-cycle peaks
    dec = float(np.mean(np.log(q[k][:-1] / q[k][1:])))  # pi xi / sqrt(1 - xi^2)
    xi = dec / math.sqrt(math.pi ** 2 + dec ** 2)
    omega = math.pi / float(np.mean(np.diff(ts[k]))) / math.sqrt(1.0 - xi * xi)
    want = rayleigh_fraction(omega, fraction, centre_over_f1 * f1)
    print(f"centre {centre_over_f1:g} f1: {s.step} steps of {s.dt:.3g} s, f {omega / 2 / math.pi:.4f}"
          f" Hz (continuum {f1:.4f}), fraction {xi:.6f} against {want:.6f}, {len(k)} peaks")
    assert len(k) >= 6
    assert abs(xi / want - 1.0) < 0.01
    assert abs(omega / (2 * math.pi * f1) - 1.0) < 0.01


def test_rayleigh_damping_keys_are_checked():
    base = decay_scene(10.0, 0.05, 10.0)
    for bad, words in ((base.replace("fraction: 0.05, ", ""), "needs fraction"),
                       (base.replace("mode: rayleigh, ", "mode: viscous, alpha: 1, "),
                        "only with mode: rayleigh"),
                       (base.replace("fraction: 0.05", "fraction: 1.5"), "fraction")):
        with pytest.raises(ConfigError, match=words):
            parse_scene(bad)


# ------------------------------------------------------------------ a joint in the path
@pytest.mark.parametrize("wave,frequency,ratio,other", [
    ("P", 20.0, 1.0, None), ("P", 40.0, 2.0, None), ("S", 40.0, 2.0, None),
    # a shear stiffness 1000 x the normal one: the step counts it (it raised the joint's
    # gridpoint masses instead, and |T| fell to 0.46 at ks 1e12)
    ("P", 20.0, 1.0, 1.0e11)])
def test_a_joint_transmits_pyrak_noltes_share_of_a_harmonic_wave(wave, frequency, ratio, other):
    c = WAVES[wave][2]
    k = "xyz".index(WAVES[wave][0])
    omega, impedance, length, v0 = 2.0 * math.pi * frequency, RHO * c, 10.0, 0.01
    kappa = omega * impedance / (2.0 * ratio)
    sim = simulation(joint_bars_scene(wave, frequency, kappa, length=length, v0=v0,
                                      other=other))
    s = sim.state
    d = s.grids.names.index("upper")
    probe = layer(s.grids.bodies[d].nodes0, 1.5 * length)
    end = 1.5 * length / c + 5.0 / frequency  # five cycles past the wave front
    ts, vs = [], []
    while s.time < end:
        sim.stepper.advance()
        ts.append(s.time)
        vs.append(float(s.grids.bodies[d].vel[probe, k].mean()))
    v = np.array(vs)[np.array(ts) > end - 2.0 / frequency]
    got = 0.5 * (v.max() - v.min()) / v0
    want = transmission(omega, impedance, kappa)
    print(f"{wave} {frequency:g} Hz, omega Z / 2 kappa = {ratio:g}: |T| {got:.4f} against "
          f"{want:.4f} ({s.step} steps)")
    assert abs(got / want - 1.0) < 0.02


# ------------------------------------------------------------------ recording stations
def test_a_station_at_the_free_top_records_twice_the_incident_pulse(tmp_path):
    """The free surface doubles a pulse's particle velocity: a station at the column's top
    (its nearest gridpoint) records ``2 v0`` when the pulse's middle arrives, ``H / Cs +
    duration / 2``; its acceleration is its velocity's change per step; a station in the
    rigid cap records that block."""
    import h5py

    duration, v0 = 0.04, 0.1
    text = column_scene("S", HEIGHT, 0.5, base="quiet", duration=duration, v0=v0,
                        time=HEIGHT / WAVES["S"][2] + duration)
    text = text.replace("output: {energy_every: 10}", f"""output:
  file: {tmp_path / "out.h5"}
  every: 1.0
  histories:
    - {{point: [0.5, 0.5, {HEIGHT + 0.01}], quantity: velocity}}
    - {{point: [0.5, 0.5, {HEIGHT + 0.01}], quantity: acceleration}}
    - {{point: [0.3, 0.2, 5.0], quantity: displacement, every: 0.01}}""")
    sim = Simulation(parse_scene(text), MPI.COMM_SELF)
    sim.run()
    sim.close()
    with h5py.File(tmp_path / "out.h5") as f:
        h = f["histories"]
        t = h["point-0.velocity/time"][()]
        v = h["point-0.velocity/value"][:, 0]
        a = h["point-1.acceleration/value"][:, 0]
        assert h["point-0.velocity"].attrs["at"] == "gridpoint"
        assert len(h["point-2.displacement/time"]) == int(round(t[-1] / 0.01)) + 1
    peak = float(v.max())
    when = float(t[np.argmax(v)])
    want_t = HEIGHT / WAVES["S"][2] + 0.5 * duration
    dt = float(np.diff(t).min())
    print(f"top station: peak {peak / v0:.4f} v0 at {when:.5f} s (closed form {want_t:.5f} s)")
    assert abs(peak / (2.0 * v0) - 1.0) < 0.02
    assert abs(when - want_t) < 0.02 * want_t
    np.testing.assert_allclose(a[1:], np.diff(v) / dt, rtol=1e-9, atol=1e-9 * abs(a).max())


# ------------------------------------------------------------------ static, then dynamic
@pytest.mark.parametrize("release", [True, False])
def test_a_static_base_made_quiet_with_release_keeps_its_equilibrium(release):
    """A 10 m zoned column brought to equilibrium under gravity on a held base, then made
    quiet: with ``release: true`` its reactions stay on as loads and it stays at rest
    (measured 2e-9 m/s, asserted 1e-4 of the terminal speed); without them (the base freed)
    it sinks on its dashpots at about ``g H / Cp``, a 1-D column's terminal speed (measured
    1.04 of it after 0.2 s)."""
    sim = simulation(released_column_scene(10.0, 0.5, release=release))
    sim.run()
    body = sim.state.grids.bodies[0]
    terminal = 9.81 * 10.0 / WAVES["P"][2]
    top = float(np.abs(body.vel).max())
    print(f"release {release}: largest speed {top:.3g} m/s ({top / terminal:.3g} of g H / Cp)")
    if release:
        assert top < 1e-4 * terminal
    else:
        assert 0.9 < top / terminal < 1.2
