"""A long undamped run's energy drift (issue 10): a 1 m cube bouncing on a fixed floor under
gravity, no damping, for PDEM_EXTREME_STEPS steps (default 1 000 000: 94 s of model time,
about 1000 bounces). The leapfrog conserves a shadow energy and pdem's budget books the work
with the mid-step velocity, so the balance error (pdem.plugins.energy) must stay at round-off
and the bounce must not grow or decay.

    PDEM_EXTREME_STEPS=20000 pytest tests/extremes/test_extreme_energy.py   # quick

10^6 steps: 116 s stepping one step at a time (8 600 steps/s, a loaded 2-core machine), 13.5 s
in the compiled loop (pdem/cycle.py, 74 000 steps/s; the same balance error to the bit).
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

from pdem.cases import make_simulation
from pdem.cases.oscillator import KN, RHO, G, cube_on_floor
from pdem.plugins.energy import balance, energy_totals

STEPS = int(os.environ.get("PDEM_EXTREME_STEPS", "1000000"))
DROP = 0.01  # m: the cube's bottom starts 1 cm above the floor


def test_undamped_bouncing_cube_energy_balance():
    """After STEPS steps the balance error is below 1e-6 of the bounce's energy m g h = 196 J
    (measured 2e-15 after 2e4 steps), the cube still bounces to its start height (0.5 %) and
    sinks into the floor by the closed-form overlap of the impact under gravity,
    (m g + sqrt((m g)^2 + 2 kn A m g h)) / (kn A) = 0.646 mm (1 %); it does not turn or
    drift sideways."""
    sim = make_simulation(cube_on_floor(DROP, end=f"steps: {STEPS + 10**6}"))
    b = sim.blocks
    x0 = b.x[1].copy()
    t0 = time.perf_counter()
    sim.run(steps=STEPS)
    wall = time.perf_counter() - t0
    lowest, highest = math.inf, -math.inf
    for _ in range(int(2.2 * math.sqrt(2 * DROP / G) / sim.dt)):  # one more bounce, sampled
        sim.advance()
        z = b.x[1, 2] - 0.5
        lowest, highest = min(lowest, z), max(highest, z)
    t = energy_totals(sim.state)
    err, _ = balance(t, sim.runner.plugin("energy").e0)
    m = RHO * 1.0
    energy = m * G * DROP
    depth = (m * G + math.sqrt((m * G) ** 2 + 2 * KN * m * G * DROP)) / KN
    print(f"{STEPS} steps in {wall:.1f} s ({STEPS / wall:.0f} steps/s), t = {sim.time:.3f} s: "
          f"balance error {err:.3e} J ({err / energy:.2e} of {energy:.4g} J); bounce top "
          f"{highest:.6f} m, lowest {lowest:.6e} m (closed form {-depth:.6e})")
    assert abs(err) < 1e-6 * energy
    assert highest == pytest.approx(DROP, rel=5e-3)
    assert -lowest == pytest.approx(depth, rel=1e-2)
    assert np.abs(b.x[1, :2] - x0[:2]).max() < 1e-9 and np.abs(b.w[1]).max() < 1e-9
