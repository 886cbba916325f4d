"""Static solve (3DEC's `solve ratio`): damped relaxation to equilibrium.

A stack of two unit cubes on a fixed floor relaxes to the elastic equilibrium: the lower
joint carries both weights and the upper one the top cube's, so the overlaps are
delta_1 = 2 m g / (kn A) and delta_2 = m g / (kn A). Tolerance: 0.5% of each overlap once
the unbalanced-force ratio is below 1e-5, for local, combined and adaptive damping, with and
without mass scaling.
"""

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.simulation import Simulation

RHO, KN, G = 2500.0, 1.0e9, 9.81

SCENE = f"""
gravity: [0, 0, -{G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: low, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
  - {{name: top, box: {{min: [-0.5, -0.5, 1], max: [0.5, 0.5, 2]}}, material: rock}}
solve: {{ratio: 1.0e-5, max_steps: 200000, damping: DAMP, mass_scaling: SCALE}}
"""


@pytest.mark.parametrize("damping,scaling", [("local", False), ("local", True),
                                             ("combined", False), ("adaptive", False)])
def test_stack_relaxes_to_elastic_equilibrium(damping, scaling):
    s = Simulation(parse_scene(SCENE.replace("DAMP", damping).replace("SCALE", str(scaling).lower())),
               MPI.COMM_SELF, output=False)
    s.run()
    assert s.ratio <= 1e-5, f"did not converge: ratio {s.ratio:.3g} after {s.step} steps"
    m = RHO * 1.0
    d1 = 2 * m * G / KN
    d2 = m * G / KN
    z = {s.specs[g].name: s.blocks.x[i, 2] for i, g in enumerate(s.blocks.gid)}
    sink_low = 0.5 - z["low"]
    sink_top = 1.5 - z["top"]
    assert sink_low == pytest.approx(d1, rel=5e-3)
    assert sink_top - sink_low == pytest.approx(d2, rel=5e-3)
    assert np.abs(s.blocks.v).max() < 1e-4
