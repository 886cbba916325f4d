"""Unconfined compression of a zoned Mohr-Coulomb specimen between rigid platens (issue 12's
verification list), through the scene entry points (``parse_scene``, ``Simulation``).

A 1 m cube (E = 1 GPa, nu = 0.25, c = 1 MPa, phi = 30 deg, psi = 0; 192 zones at size 0.5)
stands on a fixed rigid base; a rigid top platen is driven down at a constant ``velocity``
with ``velocity_fixed``. The platen contacts are frictionless (the specimen is unconfined),
gravity is off, damping local, and the loading slow: 0.032 m/s, the yield reached after ~260
transits of the specimen's P wave (16000 steps, ~6 s).

- axial stress: the volume mean of the zones' sigma_zz, and the platens' reactions (their
  contact forces, ``blocks.force``) over the specimen's current mean cross-section (it bulges
  ~0.7 % on the plateau), both smoothed over 250 steps (the specimen rings at ~62 steps, +-3 %
  of the stress, which local damping does not kill while every gridpoint moves one way);
- the reaction is the mean of the top and the base one: under steady loading they differ by
  1.6 % of the strength in the elastic part (0.04 % on the plateau). The specimen's momentum is
  steady then, so that difference is the net local-damping force on its gridpoints: a drag,
  ``alpha |F| sgn(v)`` with every gridpoint moving down (FLAC's combined damping is the cure);
- axial strain: the platen's travel over H (the specimen's own: its top and bottom gridpoints);
- the elastic slope is the specimen in series with the two joints (kn per unit area each):
  ``1 / (1/E + 2/(kn H))`` against the platen's travel, E against the specimen's strain;
- the peak axial stress is the uniaxial strength ``2 c cos(phi) / (1 - sin(phi))``
  (perfectly plastic: a plateau at it).

Measured: slope +2.2e-3 (zones) / -5.2e-3 (reactions), E +1.7e-3, peak (zones) +4.8e-3,
plateau (reactions) +3.1e-4; asserted 1e-2 each.
"""

import math

import numpy as np
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.simulation import Simulation

E, NU, RHO = 1.0e9, 0.25, 2000.0
C, PHI = 1.0e6, 30.0
H = 1.0
KN = 20.0 * E / H  # joint compliance 2/(kn H) = 10 % of the specimen's 1/E
UCS = 2.0 * C * math.cos(math.radians(PHI)) / (1.0 - math.sin(math.radians(PHI)))

SCENE = """
name: ucs
gravity: [0, 0, 0]
materials:
  steel: {{density: {rho}}}
  weak: {{density: {rho}, young: {E}, poisson: {nu}, model: mohr_coulomb, cohesion: {c},
          friction: {phi}, tension: 1.0e6, dilation: 0}}
joints: {{default: {{kn: {kn}, ks: {kn}, friction: 0}}}}
blocks:
  - {{name: base, box: {{min: [-0.5, -0.5, -0.5], max: [1.5, 1.5, 0]}}, material: steel, fixed: true}}
  - {{name: specimen, box: {{min: [0, 0, 0], max: [1, 1, {H}]}}, material: weak, zones: {{size: 0.5}}}}
  - {{name: platen, box: {{min: [-0.5, -0.5, {H}], max: [1.5, 1.5, {top}]}}, material: steel,
     velocity: [0, 0, {v}], velocity_fixed: true}}
solve: {{steps: 1000000000, damping: local}}
"""


def smooth(x, w=250):
    """Running mean over ``w`` steps (~4 periods of the specimen's ringing, 62 steps)."""
    return np.convolve(x, np.ones(w) / w, "valid")


def test_unconfined_compression_slope_and_peak():
    # platen travel 2.5 x the yield displacement over STEPS steps: v = 0.032 m/s, the yield
    # reached after ~260 transits of the specimen's P wave
    steps = 16000
    text0 = SCENE.format(rho=RHO, E=E, nu=NU, c=C, phi=PHI, kn=KN, H=H, top=H + 0.5, v=0.0)
    dt = Simulation(parse_scene(text0), MPI.COMM_SELF, output=False).state.dt
    e_series = 1.0 / (1.0 / E + 2.0 / (KN * H))
    v = -2.5 * UCS / e_series * H / (steps * dt)
    sim = Simulation(parse_scene(SCENE.format(rho=RHO, E=E, nu=NU, c=C, phi=PHI, kn=KN, H=H,
                                              top=H + 0.5, v=v)), MPI.COMM_SELF, output=False)
    s = sim.state
    assert s.dt == dt
    base, platen = s.owned_row(0), s.owned_row(2)
    body = s.grids.bodies[0]
    top = body.nodes0[:, 2] > H - 1e-9
    bottom = body.nodes0[:, 2] < 1e-9
    z0 = s.blocks.x[platen, 2]
    rows = []
    for _ in range(steps):
        sim.stepper.advance()
        u = body.displacement[:, 2]
        zone = -np.dot(body.vol, body.stress[:, 2]) / body.vol.sum()  # compression > 0
        # the mean cross-section now (the specimen bulges: ~0.7 % more area on the plateau)
        area = body.vol.sum() / (body.nodes[top, 2].mean() - body.nodes[bottom, 2].mean())
        # the reactions on the platens (the specimen pushes the top one up, the base down)
        rows.append(((z0 - s.blocks.x[platen, 2]) / H, (u[bottom].mean() - u[top].mean()) / H,
                     s.blocks.force[platen, 2] / area, -s.blocks.force[base, 2] / area, zone))
    strain, sample, top_f, base_f, zone = np.array(rows).T
    # reaction: the mean of the two platens' (see the docstring on local damping's drag)
    react = smooth(0.5 * (top_f + base_f))
    diff = smooth(top_f - base_f) / UCS
    drag = (diff[len(diff) // 4:len(diff) // 3].mean(), diff[-steps // 10:].mean())
    peak_i = int(np.argmax(zone))
    lin = (zone > 0.2 * UCS) & (zone < 0.7 * UCS) & (np.arange(steps) < peak_i)
    slope = np.polyfit(strain[lin], zone[lin], 1)[0]
    young = np.polyfit(sample[lin], zone[lin], 1)[0]
    lin_r = (react > 0.2 * UCS) & (react < 0.7 * UCS) & (np.arange(len(react)) < peak_i)
    slope_r = np.polyfit(smooth(strain)[lin_r], react[lin_r], 1)[0]
    peak = zone.max()
    plateau = react[-steps // 10:].mean()
    print(f"ucs: zones {len(body.tets)}, dt {dt:.3g} s, v {v:.3g} m/s; slope (zones) "
          f"{slope / e_series - 1:+.2e}, (reactions) {slope_r / e_series - 1:+.2e} of "
          f"{e_series:.4g}; specimen E {young / E - 1:+.2e}; peak (zones) {peak / UCS - 1:+.2e}, "
          f"plateau (reactions) {plateau / UCS - 1:+.2e} of {UCS:.4g}; top - base reaction "
          f"{drag[0]:.2e} (elastic), {drag[1]:.2e} (plateau) of the strength")
    assert abs(slope / e_series - 1.0) < 1e-2
    assert abs(young / E - 1.0) < 1e-2
    assert abs(slope_r / e_series - 1.0) < 1e-2
    assert abs(peak / UCS - 1.0) < 1e-2
    assert abs(plateau / UCS - 1.0) < 1e-2
