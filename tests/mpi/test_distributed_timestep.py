"""The timestep, the mass scaling and the start-up log read each rank's own blocks and reduce
over the ranks (pdem.resolve): no rank gathers every block's mass, inertia or radius.
On 2-4 ranks, against one process reading every block: the exact distributed k-th smallest
and first-extreme helpers (pdem.mpi), and for each way a scene sets its step (auto,
given, partial and static mass scaling) the step, every block's mass scale, the log's lines
and a refused partial scaling's message, at set-up (the build shares) and at a stage's start
(the blocks each rank owns).

Run with ``mpiexec -n N python -m mpi4py -m pytest --with-mpi tests/mpi/test_distributed_timestep.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.errors import UserError
from pdem.mpi import first_extreme, kth_smallest

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(300, method="thread")]


def test_kth_smallest_and_first_extreme_are_the_gathered_ones():
    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(11 + comm.rank)
    # ties, zeros (and a -0.0), tiny and huge values, and a rank with nothing
    mine = np.concatenate([rng.choice([0.0, -0.0, 1e-300, 2.5, 2.5, 7.0, 1e300], 5),
                           rng.random(rng.integers(0, 40))])
    if comm.rank == 1:
        mine = np.zeros(0)
    every = np.sort(np.concatenate(comm.allgather(mine)) + 0.0)
    for k in (0, 1, len(every) // 2, len(every) - 1):
        assert kth_smallest(comm, mine, k) == every[k]
    # smallest value, then smallest gid, wherever it lies
    found = None if comm.rank == 1 else (round(float(mine.min()), 1), 100 - comm.rank, comm.rank)
    gathered = [f for f in comm.allgather(found) if f is not None]
    assert first_extreme(comm, found) == min(gathered, key=lambda f: (f[0], f[1]))
    assert first_extreme(comm, None) is None


# a row of cubes of three sizes across the ranks' shares, one of them tiny (it limits the
# step), on a fixed floor; {solve} sets how the step is chosen
ROW = """
name: row
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [30, 2, 0]}}, material: rock, fixed: true}}
  - name: cube
    array: {{box: {{min: [0, 0, 0], max: [1, 1, 1]}}, count: [9, 1, 1], spacing: [1.5, 0, 0]}}
    material: rock
  - {{name: pebble, box: {{min: [14, 0, 0], max: [14.05, 0.05, 0.05]}}, material: rock}}
  - name: slab
    array: {{box: {{min: [16, 0, 0], max: [18, 1, 0.5]}}, count: [5, 1, 1], spacing: [2.5, 0, 0]}}
    material: rock
solve: {{steps: 1{solve}}}
stages:
  - {{name: load, free: {{names: [floor]}}, solve: {{steps: 1{stage}}}}}
"""

MODES = {
    "auto": ("", ""),
    "given": (", timestep: {dt: 1.0e-6}", ""),
    "partial": (", mass_scaling: {timestep: 2.0e-5}", ", mass_scaling: {timestep: 4.0e-5}"),
    "static": (", mass_scaling: true", ", mass_scaling: true"),
}


def _start(comm, text, caplog):
    """The state after set-up and its first stage's settings, the log's timestep lines, and
    every block's mass scale by gid (gathered here, for the comparison only)."""
    from pdem.config.stages import stage_scene
    from pdem.stages import _solve_settings
    from pdem.state import ModelState

    caplog.clear()
    scene = parse_scene(text)
    s = ModelState.create(scene, comm)
    s.distribute_initial()
    setup_dt = s.dt
    _solve_settings(s, stage_scene(scene, 0), 0)
    lines = [r.getMessage() for r in caplog.records
             if "step" in r.getMessage() or "mass scaling" in r.getMessage()]
    n = s.n_owned
    gid = np.concatenate(comm.allgather(s.blocks.gid[:n]))
    ms = np.concatenate(comm.allgather(s.blocks.mscale[:n]))
    ghosts = s.blocks.mscale[n:], s.blocks.gid[n:]
    return setup_dt, s.dt, lines, ms[np.argsort(gid)], ghosts


@pytest.mark.parametrize("mode", sorted(MODES))
def test_step_scaling_and_log_are_the_one_process_ones(mode, caplog):
    import logging

    caplog.set_level(logging.INFO, logger="pdem")
    comm = MPI.COMM_WORLD
    solve, stage = MODES[mode]
    text = ROW.format(solve=solve, stage=stage)
    many = _start(comm, text, caplog)
    one = _start(MPI.COMM_SELF, text, caplog)
    assert many[0] == one[0] and many[1] == one[1], (many[:2], one[:2])  # bitwise steps
    assert many[2] == one[2] and (mode == "static" or many[2]), many[2]  # the same lines
    assert np.array_equal(many[3], one[3])
    # a ghost's scale is its owner's (every rank computes every block it holds alike)
    assert np.array_equal(many[4][0], one[3][many[4][1]])
    if mode == "partial":
        # the stage scales the pebble (gid 10) and the floor it frees (gid 0: a large
        # surface on a thin slab), nothing else
        assert set(np.flatnonzero(many[3] > 1.0)) == {0, 10} and "pebble" in " ".join(many[2])
    if mode == "auto":
        assert "'pebble' limits the step" in " ".join(many[2])


def test_a_refused_partial_scaling_names_the_same_block_on_every_rank():
    from pdem.state import ModelState

    comm = MPI.COMM_WORLD
    text = ROW.format(solve=", mass_scaling: {timestep: 1.0e-3}", stage="")

    def refused(c):
        try:
            ModelState.create(parse_scene(text), c)
        except UserError as e:
            return str(e)
        return None

    mine, alone = refused(comm), refused(MPI.COMM_SELF)
    assert mine is not None and "no longer partial scaling" in mine
    assert mine == alone and len(set(comm.allgather(mine))) == 1
