"""Inactive blocks (``solve.inactive``, pdem.dynamics.inactive): blocks at rest are held, their
contacts keep their forces, and they wake when loaded again.

Closed forms: a column of n unit cubes (mass m, joint stiffness kn, area A = 1 m2) rests with
the joint under cube k (0 at the bottom) closed by ``(n - k) m g / (kn A)``."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from mpi4py import MPI

from pdem.cases import make_simulation
from pdem.cases.stacks import cube_stack_scene
from pdem.config import parse_scene
from pdem.io.checkpoint import read_checkpoint
from pdem.plugins.energy import balance, energy_totals
from pdem.simulation import Simulation

RHO, KN, G = 2500.0, 1.0e9, 9.81
INACTIVE = {"speed": 1.0e-4, "steps": 100, "force": 0.01}


def stack(n: int, **solve) -> str:
    d = yaml.safe_load(cube_stack_scene(n, "fast"))
    d["solve"].update({"inactive": INACTIVE, **solve})
    return yaml.safe_dump(d)


def rest_heights(n: int) -> np.ndarray:
    """Centroid heights of the cubes of a column at elastic rest, bottom first."""
    closure = np.array([(n - k) * RHO * G / KN for k in range(n)])
    return np.arange(n) + 0.5 - np.cumsum(closure)


def test_a_settled_stack_is_held_at_its_elastic_rest():
    """Every cube of a 3 x 3 x 3 stack is held after settling, the floor carries the stack's
    weight, and each cube rests at the closed-form height to 1% of the stack's compression
    (the hold threshold is 1% of a block's weight)."""
    n = 3
    sim = make_simulation(stack(n))
    sim.run(steps=4000)
    b = sim.blocks
    free = b.fixed == 0
    assert (b.calm[free] >= INACTIVE["steps"]).all() and (b.still[free] == 1).all()
    assert (b.v[free] == 0.0).all() and (b.w[free] == 0.0).all()
    c = sim.contacts
    assert c.frozen.all()  # every joint keeps its force
    layer = np.round(b.x[free, 2] - 0.5).astype(int)
    compression = n * (n + 1) / 2 * RHO * G / KN
    err = np.abs(b.x[free, 2] - rest_heights(n)[layer]).max()
    assert err < 0.01 * compression, (err, compression)
    floor = (c.ga == 0) | (c.gb == 0)
    fz = np.abs(sim.blocks.force[0, 2])
    weight = n**3 * RHO * G
    assert abs(fz - weight) < 1e-2 * weight, (fz, weight, int(floor.sum()))
    # holding dissipates the kinetic energy it takes: the budget's balance error is that of the
    # same run without holding (the scheme's own, from local damping's bookkeeping)
    t = energy_totals(sim.state)
    err, put_in = balance(t, sim.runner.plugin("energy").e0)
    plain = make_simulation(cube_stack_scene(n, "fast"))
    plain.run(steps=4000)
    err0, put_in0 = balance(energy_totals(plain.state), plain.runner.plugin("energy").e0)
    assert abs(err - err0) < 1e-4 * put_in, (err, err0, put_in)


def test_a_held_column_wakes_when_a_block_lands_on_it():
    """A column of two cubes is held before a third, dropped from 0.3 m, lands: the column
    wakes, and the three come to rest held at the closed-form heights of a 3-cube column."""
    text = f"""
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: c0, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
  - {{name: c1, box: {{min: [-0.5, -0.5, 1], max: [0.5, 0.5, 2]}}, material: rock}}
  - {{name: c2, box: {{min: [-0.5, -0.5, 2.3], max: [0.5, 0.5, 3.3]}}, material: rock}}
solve: {{steps: 1, damping: local, inactive: {INACTIVE}}}
"""
    sim = make_simulation(text)
    b = sim.blocks
    sim.run(steps=1500)  # the column settles and is held; the third cube is still falling
    assert b.calm[1] >= 100 and b.calm[2] >= 100 and b.calm[3] == 0
    assert b.x[3, 2] > 2.5
    woke = False
    for _ in range(60):
        sim.run(steps=100)
        woke |= bool(b.calm[1] < 100)
    assert woke
    sim.run(steps=6000)
    assert (b.calm[1:] >= 100).all()
    err = np.abs(b.x[1:, 2] - rest_heights(3)).max()
    assert err < 0.01 * 6 * RHO * G / KN, err


def test_held_blocks_restart_bitwise(tmp_path):
    """The hold state (calm, still, the contacts' held forces) is in the checkpoint: a restart
    from mid-run ends where the straight run ends."""
    d = yaml.safe_load(stack(2, steps=3000))
    d["checkpoint"] = {"file": str(tmp_path / "ck"), "every_steps": 1700, "keep": 2}
    d["output"] = {"file": str(tmp_path / "straight.h5"), "every_steps": 500}
    straight = Simulation(parse_scene(yaml.safe_dump(d)), MPI.COMM_SELF)
    straight.run()
    straight.close()
    ck = read_checkpoint(str(tmp_path / "ck-000001700.h5"))
    assert ck["blocks"]["calm"].max() >= 100  # some were held at the checkpoint
    scene = parse_scene(ck["attrs"]["scene"])
    scene = scene.model_copy(update={"output": scene.output.model_copy(
        update={"file": str(tmp_path / "again.h5")}), "checkpoint": None})
    again = Simulation(scene, MPI.COMM_SELF, checkpoint=ck)
    again.run()
    again.close()
    for k in ("x", "q", "v", "w", "calm", "still", "work"):
        assert np.array_equal(getattr(again.blocks, k), getattr(straight.blocks, k)), k
    assert np.array_equal(again.contacts.held, straight.contacts.held)


@pytest.mark.parametrize("bad", [{"speed": 0.0}, {"speed": 1e-4, "steps": 0},
                                 {"speed": 1e-4, "force": -1.0}, {"steps": 10}])
def test_bad_inactive_settings_are_refused_naming_the_key(bad):
    from pdem.config import ConfigError

    d = yaml.safe_load(cube_stack_scene(1, "fast"))
    d["solve"]["inactive"] = bad
    with pytest.raises(ConfigError, match="solve.inactive"):
        parse_scene(yaml.safe_dump(d))


def test_beside_a_zoned_block_rigid_blocks_are_held_and_the_grid_steps_on():
    """``solve.inactive`` in a scene with a zoned block: a 2-cube rigid column settles and is
    held at its closed-form rest heights; the zoned cube beside it is never held (its grid
    keeps stepping) and carries its weight: its zones' mean vertical stress is its weight over
    its base, to 1 %."""
    text = f"""
materials:
  rock: {{density: {RHO}}}
  soft: {{density: {RHO}, young: 1.0e8, poisson: 0.25}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [4, 2, 0]}}, material: rock, fixed: true}}
  - {{name: c0, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
  - {{name: c1, box: {{min: [-0.5, -0.5, 1], max: [0.5, 0.5, 2]}}, material: rock}}
  - {{name: z, box: {{min: [2, -0.5, 0], max: [3, 0.5, 1]}}, material: soft, zones: {{size: 0.5}}}}
solve: {{steps: 1, damping: local, inactive: {INACTIVE}}}
"""
    sim = make_simulation(text)
    sim.run(steps=4000)
    b = sim.blocks
    assert b.calm[1] >= 100 and b.calm[2] >= 100 and (b.still[1:3] == 1).all()
    assert b.calm[3] == 0  # the zoned block: never counted as at rest
    err = np.abs(b.x[1:3, 2] - rest_heights(2)).max()
    assert err < 0.01 * 3 * RHO * G / KN, err
    body = sim.state.grids.bodies[0]
    szz = float(np.sum(body.stress[:, 2] * body.vol) / body.vol.sum())
    assert szz == pytest.approx(-0.5 * RHO * G, rel=1e-2)
