"""Probabilistic studies with closed-form answers (tests/verification/test_studies.py,
docs/studies.md):

1. A planar slide: the slab of :mod:`pdem.cases.staged` on a plane of dip ``psi`` = 20 deg,
   its joint's friction angle normal (mean, std). Its factor of safety is
   ``FS = tan(phi) / tan(psi)``, so ``P(FS < 1) = P(phi < psi) = Phi((psi - mean) / std)``.
2. The Hoek-Bray wedge of :func:`pdem.cases.rock_mass.wedge_slope_scene`, its two joint sets'
   orientations Fisher-scattered about their mean planes; each case's factor of safety is
   :func:`pdem.analysis.wedge.wedge_factor_of_safety` of the case's orientations.

Both bring the model to equilibrium with strong joints first, then search the factor of
safety at the case's real strength, below 1 too (``factor_of_safety.low``): a case that fails
is a failure of the design, not of the run.
"""

from __future__ import annotations

import math

from pdem.cases.rock_mass import WEDGE_SETS, wedge_slope_scene
from pdem.cases.staged import KN, PSI, slab_on_incline

PLANAR_MEAN, PLANAR_STD = 22.0, 3.0  # the friction angle's distribution, degrees
# the search: a stable trial comes to rest in ~50 steps, a failing one is judged by 1000
SEARCH = "{tolerance: 0.01, low: 0.25, high: 4.0, ratio: 1.0e-5, max_steps: 1000, " \
         "max_displacement: 0.02}"


def planar_study_scene(samples: int = 200, *, seed: int = 1, mean: float = PLANAR_MEAN,
                       std: float = PLANAR_STD, output: str = "planar.h5",
                       study_file: str | None = None, latin: bool = False) -> str:
    """The planar slide with a study ``friction`` of ``samples`` cases."""
    file = f"\n    file: {study_file}" if study_file else ""
    sampling = "latin_hypercube" if latin else "monte_carlo"
    return f"""
name: planar-slide
{slab_on_incline(f"{{kn: {KN}, ks: {KN}, friction: {mean!r}}}")}solve: {{damping: local}}
output: {{file: {output}, contacts: false}}
stages:
  - {{name: settle, joints: {{default: {{friction: 60.0}}}}, solve: {{ratio: 1.0e-6, max_steps: 5000}}}}
  - name: strength
    joints: {{default: {{friction: {mean!r}}}}}
    factor_of_safety: {SEARCH}
studies:
  friction:
    samples: {samples}
    seed: {seed}
    sampling: {sampling}{file}
    parameters:
      phi:
        at: [joints.default.friction, stages.strength.joints.default.friction]
        normal: {{mean: {mean!r}, std: {std!r}}}
    outputs:
      fos: factor_of_safety
"""


def planar_probability(mean: float = PLANAR_MEAN, std: float = PLANAR_STD) -> float:
    """P(FS < 1) = Phi((psi - mean) / std)."""
    return 0.5 * math.erfc(-(PSI - mean) / std / math.sqrt(2.0))


WEDGE_PHI = 22.0  # friction of both sets, degrees: FS 1.13 at the mean orientations
WEDGE_KAPPA = 150.0  # 63 % of the poles within 6.6 deg of the mean (81 / sqrt(kappa))


def wedge_study_scene(samples: int, *, seed: int = 3, phi: float = WEDGE_PHI,
                      kappa: float = WEDGE_KAPPA, output: str = "wedge.h5",
                      study_file: str | None = None) -> str:
    """The cut wedge with a study ``orientation``: sets JA and JB Fisher-scattered (kappa)
    about their mean planes ``WEDGE_SETS``; the slope face stays the mean wedge's."""
    text = wedge_slope_scene(phi, other_friction=phi)
    strong = "{friction: 60.0}"
    file = f"\n    file: {study_file}" if study_file else ""
    stages = f"""output: {{file: {output}, contacts: false}}
stages:
  - {{name: settle, joints: {{jA: {strong}, jB: {strong}, default: {strong}}},
     solve: {{ratio: 1.0e-6, max_steps: 8000}}}}
  - name: strength
    joints: {{jA: {{friction: {phi!r}}}, jB: {{friction: {phi!r}}}, default: {{friction: {phi!r}}}}}
    factor_of_safety: {SEARCH}
studies:
  orientation:
    samples: {samples}
    seed: {seed}{file}
    parameters:
      JA: {{at: cuts.JA, fisher: {{kappa: {kappa!r}}}}}
      JB: {{at: cuts.JB, fisher: {{kappa: {kappa!r}}}}}
    outputs:
      fos: factor_of_safety
"""
    head, _, _ = text.partition("solve:")
    # no sliver joining: a scattered wedge can be a few tenths of the mean one's volume, which
    # join_slivers' 5 % of the cut rock would merge into its neighbour (no wedge left)
    return head + "join_slivers: 0.0\nsolve: {damping: local}\n" + stages


__all__ = ["PLANAR_MEAN", "PLANAR_STD", "WEDGE_KAPPA", "WEDGE_PHI", "WEDGE_SETS",
           "planar_probability", "planar_study_scene", "wedge_study_scene"]
