"""Per-block columns gathered as runs (pdem.model.runs.RunColumn.gathered): each rank sends
its runs, not its rows, and every rank gets the column a gather of the rows would give, bit
for bit (runs that continue across a rank's boundary merged, NaN and -0.0 runs kept apart,
a rank with no rows, a column too varied for runs gathered plain).

Run with ``mpiexec -n N python -m mpi4py -m pytest --with-mpi tests/mpi/test_gathered_columns.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from pdem.model.runs import RunColumn
from pdem.mpi import allgather_rows

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(120, method="thread")]


def _mine(kind: str, rank: int) -> np.ndarray:
    rng = np.random.default_rng(rank)
    if kind == "array":  # one value across every rank: one run in all
        return np.full(1000 + 7 * rank, 0.125)
    if kind == "runs":  # long runs, some crossing the boundaries, NaN and -0.0 runs
        vals = np.array([1.0, 1.0, np.nan, -0.0, 0.0, 2.0])[rng.integers(0, 6, 8)]
        return np.repeat(vals, rng.integers(1, 300, 8))
    if kind == "varied":
        return rng.random(500)
    return np.repeat(np.array([3, 3, 4], np.int32), 50 + rank)  # int32 runs


@pytest.mark.parametrize("kind", ["array", "runs", "varied", "int"])
def test_gathered_runs_are_the_column_of_the_gathered_rows(kind):
    comm = MPI.COMM_WORLD
    mine = _mine(kind, comm.rank) if comm.rank != 1 else _mine(kind, 1)[:0]  # rank 1: none
    got = RunColumn.gathered(comm, mine)
    rows = allgather_rows(comm, mine)
    ref = RunColumn(rows)
    assert got.is_runs == ref.is_runs and len(got) == len(ref) == len(rows)
    assert got.is_runs == (kind != "varied")
    bits = np.dtype(f"u{rows.dtype.itemsize}")
    assert np.array_equal(np.asarray(got).view(bits), rows.view(bits))
    if got.is_runs:
        assert np.array_equal(got._starts, ref._starts)
        assert np.array_equal(got._values.view(bits), ref._values.view(bits))
