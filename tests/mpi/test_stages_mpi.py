"""A staged run (pdem.stages: a freed and pushed block, a weakened joint, an excavation and a
prescribed velocity at stage starts) gives bitwise the 1-rank run's output on several ranks,
stage index per snapshot included.

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_stages_mpi.py``.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from support import TWO_RANKS_ONLY, compare_on_rank0, on_rank0, restart_from, run, shared_dir, with_parallel

from pdem.cases.staged import stack_stages_scene

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(300, method="thread")]


def test_stages_match_one_rank(tmp_path):
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    path = f"{base}/stages.h5"
    scene = with_parallel(stack_stages_scene(path), [comm.size, 1, 1], path)
    run(scene, comm)
    compare_on_rank0(comm, path, scene, f"{base}/stages-ref.h5")

    def same_stages():
        with h5py.File(path) as a, h5py.File(f"{base}/stages-ref.h5") as b:
            return bool(np.array_equal(a["stage"][()], b["stage"][()])
                        and np.array_equal(a["blocks/removed"][()], b["blocks/removed"][()]))

    assert on_rank0(comm, same_stages)


# a row of cubes on a floor, of two sizes (their masses and timesteps differ), in two groups;
# its stages select by range, group and name among blocks spread over the ranks
ROW_STAGES = """
name: row-stages
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-1, -1, -0.5], max: [13, 2, 0]}, material: rock, fixed: true,
     group: base}
  - name: big
    array: {box: {min: [0, 0, 0], max: [1, 1, 1]}, count: [6, 1, 1], spacing: [2, 1, 1]}
    material: rock
    group: big
  - name: small
    array: {box: {min: [1.1, 0.2, 0], max: [1.6, 0.7, 0.5]}, count: [6, 1, 1],
            spacing: [2, 1, 1]}
    material: rock
    group: small
solve: {damping: local}
output: {file: OUT, every_steps: 50}
stages:
  - {name: settle, solve: {steps: 150}}
  - name: load
    fix: {range: {box: {min: [-1, -1, -1], max: [3, 2, 2]}}}
    force: [{groups: [small], range: {box: {min: [5, -1, -1], max: [13, 2, 2]}},
             force: [200.0, 0, 0]}]
    velocity: [{names: ["big[5]"], velocity: [0.05, 0, 0]}]
    solve: {steps: 150, mass_scaling: {timestep: 2.0e-4}}
"""


def _selections():
    from pdem.config.schema import Selection

    box = {"box": {"min": [3.0, -1.0, -1.0], "max": [9.0, 2.0, 2.0]}}
    return [Selection.model_validate(x) for x in (
        {"range": box}, {"groups": ["small"]}, {"names": ["big"], "range": box},
        {"names": ["small[2]", "floor"]}, {"groups": ["big", "base"], "range": box})]


@pytest.mark.timeout(300, method="thread")
def test_selections_and_stage_fields_gathered_from_the_owners():
    """Once the blocks are distributed no rank keeps the scene's centroids, masses or
    inertias (pdem.state.RUN_CATALOGUE). A selection by range, group or name is then made by
    each rank among the blocks it owns and gathered, and a stage's timestep fields are
    gathered from the owners: the same gids, and the same bits, as the whole scene's store
    built on one rank; the range selects blocks owned by several ranks."""
    from pdem.selection import TIMESTEP_FIELDS, selected
    from pdem.simulation import Simulation
    from pdem.state import ModelState

    comm = MPI.COMM_WORLD
    scene = with_parallel(ROW_STAGES, [comm.size, 1, 1], None)
    sim = Simulation(scene, comm, output=False)
    s = sim.state
    assert {"x", "mass", "inertia", "radius", "mscale"}.isdisjoint(vars(s.glob))
    # the reference, on every rank alike
    whole = ModelState.create(with_parallel(ROW_STAGES, [1, 1, 1], None), MPI.COMM_SELF,
                              whole=True)
    owners = np.zeros(s.glob.n, np.int64)
    for r, gids in enumerate(comm.allgather(s.owned_gids().copy())):
        owners[gids] = r
    for sel in _selections():
        got, want = selected(s, sel), selected(whole, sel)
        assert np.array_equal(got, want), (sel, got, want)
        assert 0 < len(want) < whole.glob.n
    spread = selected(whole, _selections()[0])
    assert len(set(owners[spread].tolist())) == min(comm.size, 3)
    g = s.scene_fields(TIMESTEP_FIELDS)
    for k in TIMESTEP_FIELDS:
        assert np.array_equal(getattr(g, k), getattr(whole.glob, k)), k


@pytest.mark.timeout(300, method="thread")
def test_range_and_group_stages_match_one_rank(tmp_path):
    """A stage fixing by range, loading a group in a range, moving one block by name and
    scaling masses (its timestep from fields gathered from the owners) gives bitwise the
    1-rank run's output."""
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    path = f"{base}/row.h5"
    scene = with_parallel(ROW_STAGES.replace("OUT", path), [comm.size, 1, 1], path)
    solver, *_ = run(scene, comm)
    assert solver.dt == 2.0e-4
    g = solver.state.scene_fields(("mscale", "fixed"))
    assert (g.mscale > 1.0).any() and g.fixed[:3].tolist() == [1, 1, 1]  # floor, big[0..1]
    compare_on_rank0(comm, path, scene, f"{base}/row-ref.h5")


# a fixed slab carrying a row of cubes across the rank split, above a fixed floor; a stage
# frees the slab: it settles onto the floor with its load
FREED_SLAB = """
materials: {rock: {density: 2500.0}}
joints: {default: {kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-3.5, -1.5, -1.0], max: [3.5, 1.5, -0.51]}, material: rock,
     fixed: true}
  - {name: slab, box: {min: [-3, -1, -0.5], max: [3, 1, 0]}, material: rock, fixed: true}
  - name: row
    array: {box: {min: [-2.2, -0.5, 0], max: [-1.2, 0.5, 1]}, count: [4, 1, 1],
            spacing: [1.1, 1, 1]}
    material: rock
solve: {damping: none}
stages:
  - {name: settle, solve: {steps: 300}}
  - {name: freed, free: {names: [slab]}, solve: {steps: 400}}
"""


@pytest.mark.timeout(300, method="thread")
def test_a_fixed_block_freed_by_a_stage_matches_one_rank(tmp_path):
    """While the slab is fixed its contacts with the cubes are computed by the cubes'
    owners only; freed, its own owner computes them all (pdem.parallel.migrate's
    hand_over_contacts gives it those it lacked, with their history) from forces summed
    afresh: bitwise the 1-rank run, stage by stage, and across a restart in the freed stage
    (the slab's owner held only its own contacts' forces, and the next search found the
    others fresh: the slab's vz differed after 3 steps)."""
    from pdem.config import parse_scene
    from pdem.io.checkpoint import read_checkpoint

    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    path = f"{base}/freed.h5"
    scene = with_parallel(FREED_SLAB, [comm.size, 1, 1], path, every_steps=50)
    scene = scene.model_copy(update={"checkpoint": parse_scene(
        FREED_SLAB + f"checkpoint: {{every_steps: 450, keep: 5, file: {base}/ck}}\n").checkpoint})
    sim, *_ = run(scene, comm)
    x = sim.state.scene_fields(("fixed",))
    assert x.fixed.tolist()[:2] == [1, 0]
    ck = read_checkpoint(f"{base}/ck-000000450.h5")  # (before the 1-rank run writes its own)
    compare_on_rank0(comm, path, scene, f"{base}/freed-ref.h5")
    again = f"{base}/again.h5"
    restart_from(comm, ck, again)

    def same_end():
        with h5py.File(path) as a, h5py.File(again) as b:
            return [k for k in ("centroid", "orientation", "velocity", "angular_velocity")
                    if not np.array_equal(a[f"blocks/{k}"][-1], b[f"blocks/{k}"][-1])]

    assert on_rank0(comm, same_end) == []
