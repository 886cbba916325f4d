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
from support import TWO_RANKS_ONLY, compare_on_rank0, on_rank0, run, shared_dir, with_parallel

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
