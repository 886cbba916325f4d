"""Zoned blocks on several ranks are refused (not yet distributed): every rank raises the same
one-line error before any rank waits in a collective."""

import pytest
from mpi4py import MPI

from pdem.config import ConfigError, parse_scene
from pdem.simulation import Simulation

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(300, method="thread")]

SCENE = """
name: t
materials:
  rock: {density: 2000}
  soft: {density: 2000, young: 1.0e8, poisson: 0.0}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
blocks:
  - {name: floor, box: {min: [-1, -1, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: col, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: soft, zones: {size: 0.5}}
solve: {steps: 10}
"""


def test_zoned_scene_refused_on_every_rank():
    comm = MPI.COMM_WORLD
    with pytest.raises(ConfigError) as info:
        Simulation(parse_scene(SCENE), comm, output=False)
    assert info.value.messages == [
        f"blocks: zoned blocks run on one rank yet (got {comm.size} ranks)"]
    comm.Barrier()  # every rank got here: none is left in a collective
