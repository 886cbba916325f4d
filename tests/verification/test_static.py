"""Static solve (3DEC's `solve ratio`): damped relaxation to equilibrium.

A stack of two unit cubes on a fixed floor relaxes to the elastic equilibrium: the lower
joint carries both weights and the upper one the top cube's, so the overlaps are
delta_1 = 2 m g / (kn A) and delta_2 = m g / (kn A). Tolerance: 0.5% of each overlap once
the unbalanced-force ratio is below 1e-5, for local, combined and adaptive damping, with and
without mass scaling.
"""

import numpy as np
import pytest

from pdem.cases import make_simulation
from pdem.cases.static import overlaps, stack_scene


@pytest.mark.parametrize("damping,scaling", [("local", False), ("local", True),
                                             ("combined", False), ("adaptive", False)])
def test_stack_relaxes_to_elastic_equilibrium(damping, scaling):
    s = make_simulation(stack_scene(damping, scaling))
    s.run()
    assert s.state.ratio <= 1e-5, f"did not converge: ratio {s.state.ratio:.3g} after {s.step} steps"
    d1, d2 = overlaps()
    z = {s.specs[g].name: s.blocks.x[i, 2] for i, g in enumerate(s.blocks.gid)}
    sink_low = 0.5 - z["low"]
    sink_top = 1.5 - z["top"]
    assert sink_low == pytest.approx(d1, rel=5e-3)
    assert sink_top - sink_low == pytest.approx(d2, rel=5e-3)
    assert np.abs(s.blocks.v).max() < 1e-4
