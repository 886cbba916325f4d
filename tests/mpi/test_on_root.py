"""pdem.mpi.on_root: one rank's work sent to every rank (a scene's mesh file read
once), in chunks of raw bytes when large; a failure there, or a result that does not pickle,
raised on every rank, none left waiting.

Run with ``mpiexec -n N python -m mpi4py -m pytest --with-mpi tests/mpi/test_on_root.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from pdem import mpi

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(120, method="thread")]


def test_the_roots_result_reaches_every_rank_in_chunks(monkeypatch):
    comm = MPI.COMM_WORLD
    monkeypatch.setattr(mpi, "BCAST_CHUNK", 1000)  # a ~80 KB pickle in ~80 pieces
    calls = []
    got = mpi.on_root(comm, lambda: calls.append(1) or {"a": np.arange(10_000.0), "b": "x"})
    assert comm.allgather(len(calls)) == [1] + [0] * (comm.size - 1)
    assert got["b"] == "x" and np.array_equal(got["a"], np.arange(10_000.0))


def test_a_failure_on_the_root_is_raised_on_every_rank():
    comm = MPI.COMM_WORLD

    def work():
        raise ValueError("cannot read mesh m.vtu: broken")

    with pytest.raises(ValueError, match="cannot read mesh m.vtu: broken"):
        mpi.on_root(comm, work)
    comm.Barrier()


def test_a_result_that_does_not_pickle_is_an_error_on_every_rank():
    comm = MPI.COMM_WORLD
    with pytest.raises(Exception) as err:
        mpi.on_root(comm, lambda: (lambda: 1))  # a lambda does not pickle
    assert "pickle" in str(err.value).lower() or "lambda" in str(err.value)
    assert len(set(comm.allgather(type(err.value).__name__))) == 1
    comm.Barrier()
