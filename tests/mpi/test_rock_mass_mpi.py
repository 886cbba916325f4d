"""Rock-mass scenes (cuts, a joined block, an excavation at a model time) give bitwise the
same block states on several ranks as on one: an L-shaped joined block (two convex pieces)
spinning down onto a stack cut by two joint sets, across the 2-rank split at x = 0, while a
cell of the stack is excavated mid-run (pdem.cases.rock_mass.l_on_stack_scene).

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_rock_mass_mpi.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from support import TWO_RANKS_ONLY, compare_on_rank0, run, shared_dir, with_parallel

from pdem.cases.rock_mass import l_on_stack_scene

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(300, method="thread")]


def test_l_block_on_cut_stack_matches_one_rank(tmp_path):
    """Every output snapshot (centroid, orientation, velocities of every block) equals the
    1-rank run's (np.array_equal); the L touches the stack on both ranks' sides, and the
    excavated cell is deleted on every rank."""
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    scene = with_parallel(l_on_stack_scene(), [comm.size, 1, 1], f"{base}/lstack.h5",
                          every_steps=200)
    solver, _, _, report = run(scene, comm)
    specs = solver.specs
    gone = [g for g, sp in enumerate(specs) if sp.excavate_at is not None]
    out = solver.state.glob.out
    leader = next(g for g, sp in enumerate(specs) if sp.n_pieces == 2)
    keys = np.unique(np.concatenate(comm.allgather(solver.contacts.keys())))
    if comm.rank == 0:
        print(f"\nL on cut stack, {comm.size} ranks: {len(specs)} blocks ({len(gone)} excavated), "
              f"owned {report['owned']}, ghosts {report['ghosts']}, contacts "
              f"{report['contacts']} ({len(keys)} distinct), steps {solver.step}")
    assert specs[leader].name == "a"
    assert len(gone) == 1 and out[gone[0]] == 2
    assert len(keys) > 10
    compare_on_rank0(comm, f"{base}/lstack.h5", scene, f"{base}/lstack-ref.h5")


def test_joined_blocks_and_a_pending_excavation_restart_bitwise(tmp_path):
    """A checkpoint taken before the excavation time, restarted on every rank of the job,
    reaches the straight run's final state bitwise: the joined block's pieces, the contacts
    keyed by piece, and the excavation still pending are all in the checkpoint."""
    import glob

    import h5py

    from pdem.config import parse_scene
    from pdem.io.checkpoint import read_checkpoint
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    text = l_on_stack_scene(time=0.3, excavate_at=0.15) + (
        f"output: {{file: {base}/straight.h5, every_steps: 500}}\n"
        f"checkpoint: {{every_steps: 800, keep: 5, file: {base}/ck}}\n")
    s = Simulation(parse_scene(text), comm)
    s.run()
    s.close()
    first = sorted(glob.glob(f"{base}/ck-*.h5"))[0]
    ck = read_checkpoint(first)
    assert float(ck["attrs"]["time"]) < 0.15  # the excavation is still to come
    scene = parse_scene(ck["attrs"]["scene"])
    out = f"{base}/restarted.h5"
    sc = scene.model_copy(update={"output": scene.output.model_copy(update={"file": out}),
                                  "checkpoint": None})
    r = Simulation(sc, comm, checkpoint=ck)
    r.run()
    r.close()
    comm.Barrier()
    if comm.rank == 0:
        with h5py.File(f"{base}/straight.h5") as a, h5py.File(out) as b:
            assert a["step"][-1] == b["step"][-1]
            for k in ("centroid", "orientation", "velocity", "angular_velocity", "removed"):
                assert np.array_equal(a[f"blocks/{k}"][-1], b[f"blocks/{k}"][-1]), k
            assert b["blocks/removed"][-1].max() == 2
