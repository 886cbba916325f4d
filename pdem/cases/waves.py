"""Waves in zoned columns (tests/verification/test_dynamics_waves.py, docs/dynamics.md).

A zoned column ``WIDTH x WIDTH x height`` standing on z = 0, held to one-dimensional motion:
a shear (S) wave moves its gridpoints in x only (y and z held everywhere), a compressional (P)
wave in z only (x and y held: a constrained column, whose wave speed is the P-wave speed
``Cp = sqrt((K + 4G/3) / rho)``). Closed forms:

- a wave put in through a quiet base as the traction ``2 rho C v`` carries ``rho C A int v^2
  dt`` into the column (half what the traction does: the dashpot takes the rest); after it
  has gone up, reflected at the free top and come back down, a quiet base lets it out and the
  column is left at rest (a held base would reflect all of it);
- Rayleigh damping's fraction of critical at ``omega``: ``(alpha / omega + beta omega) / 2``
  with ``alpha = xi omega_c``, ``beta = xi / omega_c`` (``omega_c = 2 pi frequency``);
- a joint of specific stiffness ``kappa`` between two bars of impedance ``Z = rho C`` passes
  ``|T| = 1 / sqrt(1 + (omega Z / (2 kappa))^2)`` of a harmonic wave's amplitude
  (Pyrak-Nolte, Myer and Cook 1990, the displacement-discontinuity model).
"""

from __future__ import annotations

import math

import numpy as np

RHO, YOUNG, POISSON = 2000.0, 1.0e9, 0.25
SHEAR = YOUNG / (2.0 * (1.0 + POISSON))
BULK = YOUNG / (3.0 * (1.0 - 2.0 * POISSON))
CP = math.sqrt((BULK + 4.0 * SHEAR / 3.0) / RHO)
CS = math.sqrt(SHEAR / RHO)
WIDTH = 1.0

# the components a wave moves (the others held at every gridpoint) and its speed
WAVES = {"S": ("x", ["y", "z"], CS), "P": ("z", ["x", "y"], CP)}


def pulse_table(v0: float, duration: float, component: str, rows: int = 81) -> list:
    """A smooth velocity pulse ``v0 sin^2(pi t / duration)`` in ``component`` as a history
    table (zero after it)."""
    k = "xyz".index(component)
    out = []
    for t in np.linspace(0.0, duration, rows):
        row = [float(t), 0.0, 0.0, 0.0]
        row[1 + k] = float(v0 * math.sin(math.pi * t / duration) ** 2)
        out.append(row)
    out.append([duration + 1.0, 0.0, 0.0, 0.0])
    return out


def pulse_energy(v0: float, duration: float, impedance: float, area: float = WIDTH ** 2) -> float:
    """``Z A int v^2 dt`` of :func:`pulse_table`'s pulse: ``3/8 v0^2 duration Z A``."""
    return 0.375 * v0 * v0 * duration * impedance * area


def column_scene(wave: str, height: float, size: float, *, base: str = "quiet",
                 v0: float = 0.1, duration: float = 0.04, damping: str = "none",
                 time: float = 1.0) -> str:
    """A column of ``height`` zoned at ``size`` carrying a ``wave`` ("S" or "P") pulse put in
    at its base; ``base``: "quiet" (dashpots, the pulse as a wave traction) or "held" (the
    pulse as the base gridpoints' prescribed velocity, held at rest after it)."""
    moves, held, _ = WAVES[wave]
    bottom = "{box: {min: [-1, -1, -0.001], max: [2, 2, 0.001]}}"
    table = pulse_table(v0, duration, moves)
    if base == "quiet":
        conditions = f"""  quiet:
    - {{range: {bottom}}}
  stress:
    - {{range: {bottom}, wave: {{table: {table}}}}}"""
        drive = ""
    else:
        conditions = ""
        drive = f"""    - {{range: {bottom}, components: [{moves}], history: {{table: {table}}}}}
"""
    return f"""
name: column-{wave}
gravity: [0, 0, 0]
materials:
  rock: {{density: {RHO}, young: {YOUNG}, poisson: {POISSON}}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30}}}}
blocks:
  - {{name: col, box: {{min: [0, 0, 0], max: [{WIDTH}, {WIDTH}, {height}]}}, material: rock,
     zones: {{size: {size}}}}}
boundary:
  velocity:
    - {{names: [col], components: [{", ".join(held)}]}}
{drive}{conditions}
solve: {{time: {time}, damping: {damping}}}
output: {{energy_every: 10}}
"""


def rayleigh_fraction(omega: float, fraction: float, centre: float) -> float:
    """Rayleigh damping's fraction of critical at ``omega`` (rad/s) for ``fraction`` at the
    centre frequency ``centre`` (Hz): ``(alpha / omega + beta omega) / 2``."""
    oc = 2.0 * math.pi * centre
    return 0.5 * (fraction * oc / omega + fraction / oc * omega)


def transmission(omega: float, impedance: float, kappa: float) -> float:
    """Pyrak-Nolte's ``|T| = 1 / sqrt(1 + (omega Z / (2 kappa))^2)``."""
    return 1.0 / math.sqrt(1.0 + (omega * impedance / (2.0 * kappa)) ** 2)


def joint_bars_scene(wave: str, frequency: float, kappa: float, *, length: float = 10.0,
                     size: float = 0.5, v0: float = 0.01, time: float = 0.3,
                     other: float | None = None) -> str:
    """Two zoned bars of ``length`` stacked on z = 0 and joined at z = ``length`` by a joint
    of specific stiffness ``kappa`` (Pa/m; its normal stiffness for a P wave, shear for an
    S wave; strong enough not to slip or open), a harmonic ``wave`` of particle velocity
    ``v0 sin(2 pi frequency t)`` put in through the quiet base, the top quiet too: the upper
    bar carries the transmitted wave alone (:func:`transmission`). ``other``: the joint's
    other stiffness (shear for a P wave, normal for an S wave; default ``kappa``)."""
    moves, held, _ = WAVES[wave]
    amplitude = [0.0, 0.0, 0.0]
    amplitude["xyz".index(moves)] = v0
    kn = ks = kappa
    if other is not None:
        kn, ks = (kappa, other) if wave == "P" else (other, kappa)
    top = 2.0 * length
    return f"""
name: joint-{wave}
gravity: [0, 0, 0]
materials:
  rock: {{density: {RHO}, young: {YOUNG}, poisson: {POISSON}}}
joints: {{default: {{kn: {kn}, ks: {ks}, friction: 45, cohesion: 1.0e9, tension: 1.0e9}}}}
blocks:
  - {{name: lower, box: {{min: [0, 0, 0], max: [{WIDTH}, {WIDTH}, {length}]}}, material: rock,
     zones: {{size: {size}}}}}
  - {{name: upper, box: {{min: [0, 0, {length}], max: [{WIDTH}, {WIDTH}, {top}]}}, material: rock,
     zones: {{size: {size}}}}}
boundary:
  velocity:
    - {{names: [lower, upper], components: [{", ".join(held)}]}}
  quiet:
    - {{range: {{box: {{min: [-1, -1, -0.001], max: [2, 2, 0.001]}}}}}}
    - {{range: {{box: {{min: [-1, -1, {top - 0.001}], max: [2, 2, {top + 0.001}]}}}}}}
  stress:
    - {{range: {{box: {{min: [-1, -1, -0.001], max: [2, 2, 0.001]}}}},
       wave: {{harmonic: {{amplitude: {amplitude}, frequency: {frequency}}}}}}}
solve: {{time: {time}, damping: none}}
"""


def released_column_scene(height: float, size: float, *, release: bool = True,
                          time: float = 0.2) -> str:
    """A zoned column under gravity on a held base, brought to equilibrium (local damping,
    to a ratio), then made quiet at its base (``release``: its reactions kept as loads; else
    the base freed with no load, the column sinking on its dashpots at ``g H / Cp``, a 1-D
    column's terminal speed) and run undamped for ``time`` (a P column: x and y held)."""
    bottom = "{box: {min: [-1, -1, -0.001], max: [2, 2, 0.001]}}"
    second = f"    quiet: [{{range: {bottom}, release: true}}]" if release else \
        f"    free: {{range: {bottom}}}\n    quiet: [{{range: {bottom}}}]"
    return f"""
name: released-column
gravity: [0, 0, -9.81]
materials:
  rock: {{density: {RHO}, young: {YOUNG}, poisson: {POISSON}}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30}}}}
blocks:
  - {{name: col, box: {{min: [0, 0, 0], max: [{WIDTH}, {WIDTH}, {height}]}}, material: rock,
     zones: {{size: {size}}}}}
boundary:
  velocity:
    - {{names: [col], components: [x, y]}}
    - {{range: {bottom}}}
solve: {{damping: local}}
stages:
  - name: equilibrium
    solve: {{ratio: 1.0e-7, max_steps: 20000}}
  - name: quiet
{second}
    reset_displacements: true
    solve: {{time: {time}, damping: none}}
"""


def shaken_bars_text(out: str, checkpoint: str = "", *, settle: int = 60, shake: int = 120,
                     every: int = 60) -> str:
    """Two zoned bars (4 m each, joined by a cohesive joint) under gravity, settled on a held
    base, then shaken: the base made quiet (``release``) and a harmonic wave put in through
    it, the top quiet, Rayleigh damping, a recording station's acceleration at the top (the
    1- and several-rank comparisons and the restart of tests/mpi/test_dynamics_mpi.py)."""
    bottom = "{box: {min: [-1, -1, -0.001], max: [2, 2, 0.001]}}"
    top = "{box: {min: [-1, -1, 7.999], max: [2, 2, 8.001]}}"
    return f"""
name: shaken-bars
gravity: [0, 0, -9.81]
materials:
  rock: {{density: {RHO}, young: {YOUNG}, poisson: {POISSON}}}
joints: {{default: {{kn: 5.0e8, ks: 5.0e8, friction: 45, cohesion: 1.0e6, tension: 1.0e6}}}}
blocks:
  - {{name: lower, box: {{min: [0, 0, 0], max: [1, 1, 4]}}, material: rock, zones: {{size: 0.5}}}}
  - {{name: upper, box: {{min: [0, 0, 4], max: [1, 1, 8]}}, material: rock, zones: {{size: 0.5}}}}
boundary:
  velocity:
    - {{names: [lower, upper], components: [y]}}
    - {{range: {bottom}}}
solve: {{damping: local}}
stages:
  - name: settle
    solve: {{steps: {settle}}}
  - name: shake
    quiet: [{{range: {bottom}, release: true}}, {{range: {top}}}]
    stress:
      - {{range: {bottom}, wave: {{harmonic: {{amplitude: [0.01, 0, 0.005], frequency: 40}}}}}}
    solve: {{steps: {shake}, damping: {{mode: rayleigh, fraction: 0.05, frequency: 40}}}}
output:
  file: {out}
  every_steps: {every}
  contacts: false
  histories: [{{point: [0.5, 0.5, 8.0], quantity: acceleration}}]
{checkpoint}
"""


def decay_scene(height: float, fraction: float, centre: float | None,
                damping: str | None = None) -> str:
    """A held-base shear column of ``height`` (zones of 0.5 m) moving at 0.1 m/s at the
    start: Rayleigh damping ``fraction`` at ``centre`` Hz, or the ``damping`` given (the
    Rayleigh decay test, bench/dynamics.py, docs/make_figures.py waves)."""
    if damping is None:
        damping = f"{{mode: rayleigh, fraction: {fraction}, frequency: {centre}}}"
    return f"""
name: decay
gravity: [0, 0, 0]
materials:
  rock: {{density: {RHO}, young: {YOUNG}, poisson: {POISSON}}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30}}}}
blocks:
  - {{name: col, box: {{min: [0, 0, 0], max: [1, 1, {height}]}}, material: rock,
     zones: {{size: 0.5}}, velocity: [0.1, 0, 0]}}
boundary:
  velocity:
    - {{names: [col], components: [y, z]}}
    - {{range: {{box: {{min: [-1, -1, -0.001], max: [2, 2, 0.001]}}}}}}
solve: {{time: 10, damping: {damping}}}
"""
