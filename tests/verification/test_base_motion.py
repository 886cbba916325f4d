"""Rigid blocks under base motion against closed forms (pdem.cases.shaking; docs/dynamics.md,
"Verification: rigid blocks under base motion"). The base's whole motion is prescribed by a
velocity table; no damping.

Newmark's sliding block (a 1 x 1 x 0.2 m slab, friction 30 deg, kn = ks = 1e9 Pa/m): a
rectangular base acceleration pulse ``A`` for ``T = 0.1`` s, then constant base velocity.

* Horizontal base, ``A = 1.5`` and ``3 a_y`` (``a_y = g tan phi``): the permanent slip against
  Newmark's ``d = V^2/(2 a_y) (1 - a_y/A)`` within 3 % (the rigid-plastic form ignores the
  elastic start of the shear spring, which adds 2.0 % and 0.35 % here, predicted by
  pdem.cases.shaking.newmark_elastic_displacement), and against that elastic-start form within
  1e-3 (the slip's onset is resolved to a step: a relative velocity off by up to
  ``(A - a_y) dt`` for ``t1``, ~4e-4 of ``d``; measured <= 5e-5); the slab has stuck
  again by the end (its slip changes by < 1e-5 m over the last 30 ms).
* Horizontal base, ``A = 0.9 a_y``, ramped up over 20 ms (slow against the shear spring's
  2.8 ms period, so the load is quasi-static): no slip -- the relative displacement stays
  between 0.8 and 1.2 times the spring's ``F / (ks A_c) = m A / (ks A_c)`` (2 um), where any
  slip would be millimetres.
* A 10 deg incline (gravity tilted; a static stage with local damping loads the shear spring
  first, then the shaking stage), the same pulse ``|A| = 3 a_y(down)`` upslope and downslope:
  the slab slips downslope by Newmark's form with ``a_y = g (cos psi tan phi - sin psi)`` and
  upslope by the one with ``+ sin psi`` (3.3 times less): the same tolerances.

Housner's rocking block (b = 0.2, h = 1.0, 0.4 m deep, alpha = 11.3 deg, friction 60 deg):

* uplift: a base acceleration ramped over 0.5 s to ``0.9 g tan(alpha)`` and held tilts the
  block only on its springs (max tilt within 0.8-1.2 of ``m a h / (kn A_c b^2)``, the four
  corner springs' rotational stiffness); to ``1.2 g tan(alpha)`` it rocks: the tilt at 1 s is
  > 100 times that elastic tilt and within 5 % of the rigid block's (the ODE of
  pdem.cases.shaking, from lift-off; the elastic tilt at lift-off grows with the rocking
  instability: 3.0 % measured);
* free rocking from ``theta0 = alpha / 2`` at rest about a corner: the time to the first
  impact (the block upright again) within 0.5 % of the rigid pivot's (RK4 of the exact
  equation) and of Housner's small-angle ``(1/p) arccosh(1 / (1 - theta0/alpha))`` (the
  pivot is two point springs that sink 0.7 mm; the two closed forms differ by 0.11 %). The
  angular velocity ratio across the impact is printed, not asserted: pdem's contact springs
  have no dashpot, the impact is elastic and gives ~1, not Housner's plastic
  ``1 - 3/2 sin^2(alpha) = 0.94``.

Run: ``.venv/bin/python -m pytest -q -s tests/verification/test_base_motion.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdem.cases import make_simulation, rotation_matrix
from pdem.cases.shaking import (
    KN,
    PSI,
    RHO,
    SLAB_H,
    elastic_tilt,
    housner_impact_time,
    housner_restitution,
    newmark_displacement,
    newmark_elastic_displacement,
    pivot_impact_time,
    rocking_constants,
    sliding_scene,
    slip_time,
    tilt_about_y,
    tilted_scene,
    uplift_acceleration,
    uplift_scene,
    uplift_tilt,
    yield_acceleration,
)
from pdem.plugins.base import Plugin

PULSE = 0.1  # s, the rectangular pulse's duration
MARGIN = 0.05  # s run past Newmark's stick time
TOL_NEWMARK = 0.03  # rigid-plastic form: the elastic start adds 2.0 % at A = 1.5 a_y
TOL_ELASTIC = 1e-3  # with the elastic start: onset to a step, (A - a_y) dt t1 / d ~ 4e-4


class Recorder(Plugin):
    """``fn(state)`` (a tuple) after every step, with the time."""

    name = "recorder"

    def __init__(self, state, fn):
        self.state = state
        self.fn = fn
        self.rows = []

    def after_step(self, run):
        self.rows.append((self.state.time, *self.fn(self.state)))


def row_of(sim, gid: int) -> int:
    return int(np.nonzero(sim.blocks.gid == gid)[0][0])


def run_sliding(a: float, time: float, psi: float = 0.0, ramp: float = 0.0):
    """Times and the slab's slip relative to the base, along the slip (opposite the pulse
    ``a``), from the shaking's start."""
    sim = make_simulation(sliding_scene(a, PULSE, time, psi, ramp))
    base, slab = row_of(sim, 0), row_of(sim, 1)
    x_init = sim.blocks.x[:, 0].copy()
    rec = Recorder(sim.state, lambda s: (s.blocks.x[base, 0], s.blocks.x[slab, 0]))
    sim.runner.plugins.append(rec)
    sim.run()
    r = np.array(rec.rows)
    if psi:  # from the shaking stage's start
        t0 = sim.state.stage_times[1]
        k0 = int(np.nonzero(r[:, 0] <= t0 + 1e-12)[0][-1])
        ref, r = r[k0], r[k0 + 1:]
        r[:, 0] -= t0
    else:
        ref = np.array([0.0, x_init[base], x_init[slab]])
    slip = -math.copysign(1.0, a) * ((r[:, 2] - ref[2]) - (r[:, 1] - ref[1]))
    return r[:, 0], slip, sim.dt


def check_slip(t, slip, a, a_y, label):
    d_n = newmark_displacement(abs(a), PULSE, a_y)
    d_e = newmark_elastic_displacement(abs(a), PULSE, a_y)
    late = slip[t >= t[-1] - 0.03]
    d = float(late.mean())  # the stuck slab rings on its spring (~2e-6 m): the mean
    err_n, err_e = d / d_n - 1.0, d / d_e - 1.0
    print(f"{label}: A/a_y={abs(a) / a_y:.3f} slip {d:.6f} m, Newmark {d_n:.6f} "
          f"({err_n:+.2e}), with elastic start {d_e:.6f} ({err_e:+.2e}), "
          f"last 30 ms {np.ptp(late):.1e} m")
    assert abs(err_n) < TOL_NEWMARK
    assert abs(err_e) < TOL_ELASTIC
    assert np.ptp(late) < 1e-5  # stuck again


@pytest.mark.parametrize("ratio", [1.5, 3.0])
def test_newmark_horizontal(ratio):
    a_y = yield_acceleration()
    a = ratio * a_y
    t, slip, _ = run_sliding(a, slip_time(a, PULSE, a_y) + MARGIN)
    check_slip(t, slip, a, a_y, "horizontal")


def test_newmark_below_yield_no_slip():
    a = 0.9 * yield_acceleration()
    t, slip, _ = run_sliding(a, 0.15, ramp=0.02)
    elastic = RHO * SLAB_H * a / KN  # m A / (ks A_c), A_c = 1 m^2
    worst = float(np.abs(slip).max())
    print(f"A = 0.9 a_y: max relative displacement {worst:.3e} m, spring F/ks {elastic:.3e} m, "
          f"at the end {slip[-1]:.2e} m")
    assert 0.8 * elastic < worst < 1.2 * elastic


@pytest.mark.parametrize("slip", ["down", "up"])
def test_newmark_incline(slip):
    """Base pulse upslope (-x): the slab slips down; downslope (+x): up, 3.3 times less."""
    a_y = yield_acceleration(PSI, slip)
    a_mag = 3.0 * yield_acceleration(PSI, "down")
    a = -a_mag if slip == "down" else a_mag
    t, d, _ = run_sliding(a, slip_time(a_mag, PULSE, a_y) + MARGIN, psi=PSI)
    check_slip(t, d, a, a_y, f"incline {PSI} deg, slip {slip}")


def run_rocker(text: str):
    """Times, tilt about +y (rad, from the start) and angular velocity about y of the block."""
    sim = make_simulation(text)
    i = row_of(sim, 1)
    r0 = rotation_matrix(sim.blocks.q[i])
    rec = Recorder(sim.state, lambda s: (tilt_about_y(s.blocks.q[i], r0), s.blocks.w[i, 1]))
    sim.runner.plugins.append(rec)
    sim.run()
    r = np.array(rec.rows)
    return r[:, 0], r[:, 1], r[:, 2]


@pytest.mark.parametrize("frac", [0.9, 1.2])
def test_rocking_uplift_threshold(frac):
    ramp, end = 0.5, 1.0
    a = frac * uplift_acceleration()
    t, tilt, _ = run_rocker(uplift_scene(a, ramp, end))
    el = elastic_tilt(a)
    worst = float(np.abs(tilt).max())
    if frac < 1.0:
        print(f"a = {frac} g tan(alpha): max tilt {worst:.4e} rad, elastic {el:.4e} "
              f"({worst / el:.3f})")
        assert 0.8 * el < worst < 1.2 * el
    else:
        rigid = uplift_tilt(a, ramp, end)
        got = abs(float(tilt[-1]))
        print(f"a = {frac} g tan(alpha): tilt at {end} s {got:.5f} rad, rigid {rigid:.5f} "
              f"({got / rigid - 1:+.2e}), {got / el:.0f} x elastic")
        assert got > 100.0 * el
        assert abs(got / rigid - 1.0) < 0.05


def test_free_rocking_first_impact():
    alpha, _, _ = rocking_constants()
    theta0 = 0.5 * alpha
    t, beta, w = run_rocker(tilted_scene(theta0, 0.7))
    beta = beta + theta0
    k = int(np.nonzero(beta <= 0.0)[0][0])
    f = beta[k - 1] / (beta[k - 1] - beta[k])
    tc = t[k - 1] + f * (t[k] - t[k - 1])
    w_before = w[k - 1] + f * (w[k] - w[k - 1])
    t_pivot, w_pivot = pivot_impact_time(theta0)
    t_h = housner_impact_time(theta0)
    # after the impact: the mean trend of w (the springs ring), back to the impact time
    after = (t > tc + 0.005) & (t < tc + 0.04)
    c = np.polyfit(t[after] - tc, w[after], 1)
    r = c[1] / w_before
    print(f"first impact at {tc:.5f} s: rigid pivot {t_pivot:.5f} ({tc / t_pivot - 1:+.2e}), "
          f"Housner {t_h:.5f} ({tc / t_h - 1:+.2e}); w before {w_before:.4f} "
          f"(rigid {w_pivot:.4f}), ratio across the impact {r:.3f} "
          f"(Housner's plastic impact {housner_restitution():.3f})")
    assert abs(tc / t_pivot - 1.0) < 5e-3
    assert abs(tc / t_h - 1.0) < 5e-3
