"""A scene with zoned blocks continues from a checkpoint bitwise as the uninterrupted run."""

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.io.checkpoint import open_checkpoint, read_checkpoint, write_checkpoint
from pdem.simulation import Simulation

SCENE = """
name: t
materials:
  rock: {density: 2000}
  soft: {density: 2000, young: 1.0e8, poisson: 0.2, model: mohr_coulomb, cohesion: 2.0e3,
         friction: 30, tension: 1.0e3}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 20}}
gravity: [2.0, 0.0, -9.81]
blocks:
  - {name: floor, box: {min: [-1, -1, -1], max: [3, 2, 0]}, material: rock, fixed: true}
  - {name: col, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: soft, zones: {size: 0.5}}
  - {name: cap, box: {min: [0.2, 0.2, 1], max: [0.8, 0.8, 1.3]}, material: rock}
solve: {steps: 10, damping: local}
"""


def state_of(sim):
    b, g, c = sim.blocks, sim.state.grids, sim.state.contacts
    out = {k: getattr(b, k)[:sim.state.n_owned].copy() for k in ("x", "q", "v", "w")}
    out.update(nodes=g.nodes.copy(), vel=g.vel.copy(), force=g.force.copy(),
               stress=np.concatenate([x.stress for x in g.bodies]),
               plastic=np.concatenate([x.plastic for x in g.bodies]))
    out.update({k: v.copy() for k, v in c.sub.items()})
    return out


# every gridpoint damping form: combined reads the gridpoints' forces of the step before
# (checkpointed), adaptive the servo's alpha (the state's, checkpointed) that the grids follow
@pytest.mark.parametrize("damping", ["local", "combined", "{mode: adaptive, alpha: 5}"])
def test_restart_is_bitwise(tmp_path, damping):
    scene = parse_scene(SCENE.replace("damping: local", f"damping: {damping}"))
    whole = Simulation(scene, MPI.COMM_SELF, output=False)
    for _ in range(700):
        whole.stepper.advance()
    first = Simulation(scene, MPI.COMM_SELF, output=False)
    for _ in range(300):
        first.stepper.advance()
    path = write_checkpoint(tmp_path / "ck.h5", first.state)
    for ck in (open_checkpoint(path), read_checkpoint(path)):
        again = Simulation(scene, MPI.COMM_SELF, output=False, checkpoint=ck)
        assert again.state.step == 300
        for _ in range(400):
            again.stepper.advance()
        a, b = state_of(whole), state_of(again)
        for k in a:
            assert np.array_equal(a[k], b[k]), k
    # the run did something: the grid moved and a zone yielded or the cap slid
    assert np.abs(a["vel"]).max() > 0.0 and np.abs(a["nodes"] - whole.state.grids.bodies[0]
                                                    .nodes0).max() > 1e-6
