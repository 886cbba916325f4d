"""Partial mass scaling (``solve.mass_scaling: {timestep: DT}``) gives bitwise the 1-rank run
on 2 ranks: the factors come from the scene on every rank alike. A 1 m block slides down a
tilted-gravity incline across the rank split at x = 0 carrying a 1 cm pebble (scaled, in
contact with an unscaled block that migrates), with two more pebbles resting on either side.

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_mass_scaling_mpi.py``.
"""

from __future__ import annotations

import math

import pytest
from mpi4py import MPI
from support import TWO_RANKS_ONLY, compare_on_rank0, run, shared_dir, with_parallel

from pdem.cases import vec

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(300, method="thread")]

PSI = math.radians(20.0)
G = (9.81 * math.sin(PSI), 0.0, -9.81 * math.cos(PSI))
SCENE = f"""
gravity: {vec(G)}
materials: {{rock: {{density: 2000.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 10.0}}}}
blocks:
  - {{name: base, box: {{min: [-6, -2, -1], max: [6, 2, 0]}}, material: rock, fixed: true}}
  - {{name: big, box: {{min: [-0.52, -0.5, -2.0e-6], max: [0.48, 0.5, 0.999998]}}, material: rock}}
  - {{name: rider, box: {{min: [-0.025, -0.005, 0.999998], max: [-0.015, 0.005, 1.009998]}},
     material: rock}}
  - {{name: west, box: {{min: [-3.005, -0.005, -1.0e-7], max: [-2.995, 0.005, 0.0099999]}},
     material: rock}}
  - {{name: east, box: {{min: [2.995, -0.005, -1.0e-7], max: [3.005, 0.005, 0.0099999]}},
     material: rock}}
solve: {{time: 0.3, damping: none, mass_scaling: {{timestep: 9.0e-5}}}}
"""


def test_partial_mass_scaling_matches_one_rank(tmp_path):
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    path = f"{base}/pebbles.h5"
    scene = with_parallel(SCENE, [comm.size, 1, 1], path, every_steps=500)
    solver, *_ = run(scene, comm)
    assert solver.dt == 9.0e-5
    g = solver.state.scene_fields(("mscale", "fixed"))  # gathered from the owners
    assert (g.mscale[g.fixed == 0] > 1.0).sum() == 3  # the three pebbles, not the big block
    compare_on_rank0(comm, path, scene, f"{base}/pebbles-ref.h5")
