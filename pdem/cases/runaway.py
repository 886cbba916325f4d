"""Solves to a ratio that cannot succeed, and one that does (tests/unit/test_early_stop.py,
docs/workflow.md "Solves that cannot succeed"): the watch of ``solve.no_progress_steps``
(pdem.plugins.no_progress) must stop the first two and leave the third alone.

The incline is tilted gravity as in :mod:`pdem.cases.incline` (psi = 20 deg, the slope
along +x): a unit cube on a fixed base, equilibrium stage under local damping to a ratio.

* ``slide_off``: friction 10 deg < psi on a short base, the cube starting near its downhill
  edge: it slides, tips over the edge and falls with no contacts (issue 39's run);
* ``slide``: the same on a long base: it slides for ever (speeding up: local damping takes
  only part of the constant unbalanced force ``m g (sin psi - cos psi tan phi)``);
* ``settle``: a cube dropped onto a flat floor (friction 30 deg): it bounces and rings down to
  the ratio, through transients that a too eager watch would take for a stall;
* ``cohesive_slab``: the slab of :mod:`pdem.cases.staged` on the same incline, held by cohesion
  (friction 12 deg < psi): the trap of docs/workflow.md "Equilibrium first". Brought to
  equilibrium with its real strength, its joint fails in the dynamic overshoot of the shear
  force and the slab slides, however safe it is statically (below FS ~1.3 under local
  damping); with strong joints first and the real strength after, its factor of safety is the
  closed form's.
"""

from __future__ import annotations

import math

from pdem.cases import vec
from pdem.cases.staged import slab_fos_scene

G = 9.81
RHO = 2000.0
KN = 1.0e9
PSI = 20.0  # incline, degrees


def _incline(base_x: tuple[float, float], x0: float, window: int, stage_solve: str,
             output: str | None) -> str:
    psi = math.radians(PSI)
    g = (G * math.sin(psi), 0.0, -G * math.cos(psi))
    delta = RHO * G * math.cos(psi) / KN  # static overlap, m g cos(psi) / (kn A)
    out = f"output: {{file: {output}, every_steps: 1000}}\n" if output else ""
    return f"""
name: runaway
gravity: {vec(g)}
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 10.0}}}}
blocks:
  - {{name: base, box: {{min: [{base_x[0]}, -2, -1], max: [{base_x[1]}, 2, 0]}}, material: rock,
     fixed: true}}
  - name: slider
    box: {{min: {vec((x0 - 0.5, -0.5, -delta))}, max: {vec((x0 + 0.5, 0.5, 1.0 - delta))}}}
    material: rock
solve: {{damping: local, no_progress_steps: {window}}}
{out}stages:
  - {{name: equilibrium, solve: {{{stage_solve}}}}}
"""


def slide_off_scene(window: int, stage_solve: str = "ratio: 1.0e-5",
                    output: str | None = None) -> str:
    """The cube near the downhill edge of a 2 m base: it slides off and falls. ``window``:
    the scene's ``solve.no_progress_steps``; ``stage_solve``: the stage's ``solve`` keys."""
    return _incline((-1.0, 1.0), 0.95, window, stage_solve, output)


def slide_scene(window: int, stage_solve: str = "ratio: 1.0e-5",
                output: str | None = None) -> str:
    """The cube on a 100 m base: it slides down it, speeding up."""
    return _incline((-50.0, 50.0), 0.0, window, stage_solve, output)


def settle_scene(window: int, ratio: float = 1.0e-7, drop: float = 0.01) -> str:
    """A cube dropped ``drop`` m onto a floor: it settles (local damping) to ``ratio``."""
    return f"""
name: settle
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [-0.5, -0.5, {drop!r}], max: [0.5, 0.5, {1.0 + drop!r}]}},
     material: rock}}
solve: {{ratio: {ratio:.6e}, damping: local, no_progress_steps: {window}}}
"""


SLAB_FRICTION = 12.0  # degrees, below PSI: the slab holds by its cohesion


def cohesive_slab_scene(cohesion: float, strong_first: bool, window: int = 4_000,
                        output: str | None = None) -> str:
    """The slab held by ``cohesion`` (Pa): an equilibrium stage, then its factor of safety.
    ``strong_first``: the equilibrium stage has strong joints (cohesion and tension 1e9 Pa)
    and a stage with the real strength follows it, 3DEC's remedy."""
    text = slab_fos_scene(SLAB_FRICTION, cohesion, output=output)
    settle = "  - {name: settle, solve: {ratio: 1.0e-6, max_steps: 20000}}\n"
    assert settle in text
    solve = f"{{ratio: 1.0e-6, max_steps: 20000, no_progress_steps: {window}}}"
    if strong_first:
        stages = (f"  - {{name: equilibrium, joints: {{default: {{cohesion: 1.0e9, tension: "
                  f"1.0e9}}}}, solve: {solve}}}\n"
                  f"  - {{name: real-strength, joints: {{default: {{cohesion: {cohesion!r}, "
                  f"tension: 0.0}}}}, solve: {solve}}}\n")
    else:
        stages = f"  - {{name: equilibrium, solve: {solve}}}\n"
    return text.replace(settle, stages)
