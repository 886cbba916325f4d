"""A study's cases on 2 ranks give the 1-rank study's per-case results, bit for bit: as two
groups of one rank (two cases at a time) and as one group of two ranks (each case on both).

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_study_mpi.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from support import TWO_RANKS_ONLY, on_rank0, shared_dir

from pdem.cases.studies import planar_study_scene
from pdem.io.study_table import open_study
from pdem.study.runner import run_study

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(300, method="thread")]

CASES = 6


def _scene(base: str, stem: str, ranks_per_case: int = 1) -> str:
    text = planar_study_scene(CASES, study_file=f"{stem}.h5", output=f"{stem}-run.h5")
    text = text.replace("    sampling: monte_carlo",
                        f"    sampling: monte_carlo\n    ranks_per_case: {ranks_per_case}")
    path = f"{base}/{stem}.yaml"
    if MPI.COMM_WORLD.rank == 0:
        with open(path, "w") as f:
            f.write(text)
    MPI.COMM_WORLD.Barrier()
    return path


@pytest.mark.parametrize("ranks_per_case", [1, 2])
def test_study_cases_on_two_ranks_match_one_rank(tmp_path, ranks_per_case):
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    one = _scene(base, "one")
    table = run_study(_scene(base, "two", ranks_per_case), comm, echo=False)
    assert table.done.all()

    def same_as_one_rank():
        ref = run_study(one, MPI.COMM_SELF, echo=False)
        got = open_study(f"{base}/two.h5")
        assert np.array_equal(got.parameters["phi"], ref.parameters["phi"])
        assert np.array_equal(got.outputs["fos"], ref.outputs["fos"]), (
            got.outputs["fos"], ref.outputs["fos"])
        assert got.summary == ref.summary
        return int(got.done.sum())

    # rank 0 alone runs the 1-rank study (its scene written above, collectively)
    assert on_rank0(comm, same_as_one_rank) == CASES
