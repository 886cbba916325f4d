"""How ranks wait for the per-step messages (pdem.mpi.configure_waits): spinning in
MPI where every rank has a core, testing and sleeping where the node is oversubscribed; the
halo and the step's reduction give the same values either way."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
from mpi4py import MPI
from support import collective

from pdem import mpi
from pdem.parallel.halo import Halo

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(300, method="thread")]


def decide(mode: str) -> bool:
    """configure_waits on COMM_WORLD under ``PDEM_MPI_WAIT=mode`` (collective)."""
    old = os.environ.get("PDEM_MPI_WAIT")
    os.environ["PDEM_MPI_WAIT"] = mode
    try:
        return mpi.configure_waits(MPI.COMM_WORLD)
    finally:
        if old is None:
            del os.environ["PDEM_MPI_WAIT"]
        else:
            os.environ["PDEM_MPI_WAIT"] = old


def cpu_share_of_a_wait(comm, mode: str, late: float = 0.6) -> float:
    """CPU time over wall time of rank 0 waiting in the step's reduction while the other
    ranks arrive ``late`` seconds later (they sleep meanwhile, leaving the cores free)."""
    decide(mode)
    comm.Barrier()
    if comm.rank == 0:
        w0, c0 = time.perf_counter(), time.process_time()
        mpi.allreduce_max_array(comm, np.zeros(3))
        share = (time.process_time() - c0) / (time.perf_counter() - w0)
    else:
        time.sleep(late)
        mpi.allreduce_max_array(comm, np.zeros(3))
        share = 0.0
    decide("auto")
    return comm.bcast(share, root=0)


def test_a_sleeping_wait_leaves_the_core_to_the_others():
    """Spinning, the waiting rank burns its core for the whole wait; sleeping, it takes a
    part of it: what one sleep of SLEEP_POLL costs in wake-ups depends on the machine's
    kernel and timers (a quiet machine measured ~1.0 and ~0.05; an AMD EPYC node ~1.0 and
    0.33-0.36, where a 20 us sleep takes 170 us of wall and a quarter of it in CPU), so the
    sleeping share is bounded against the spinning one, not absolutely."""
    comm = MPI.COMM_WORLD
    with collective(comm, "the waits"):
        spin = cpu_share_of_a_wait(comm, "spin")
        sleep = cpu_share_of_a_wait(comm, "sleep")
    assert spin > 0.3, f"a spinning wait used {spin:.2f} of its core"
    assert sleep < 0.6 * spin, f"a sleeping wait used {sleep:.2f} of its core ({spin:.2f} spinning)"


@pytest.mark.parametrize("mode", ["spin", "sleep"])
def test_halo_and_reduction_give_the_same_values_either_way(mode):
    """Every rank sends each other rank its rows; the ghosts hold the owners' values, and the
    reduction's maximum is every rank's, whichever way the ranks wait."""
    from pdem.model.fields import HALO

    comm = MPI.COMM_WORLD
    size, rank = comm.size, comm.rank
    with collective(comm, "the halo"):
        assert decide(mode) == (mode == "sleep")

        class Rows:  # one owned row, one ghost row per other rank (in rank order)
            pass

        rows = Rows()
        for f in HALO:
            a = np.zeros((size, f.width))
            a[0] = rank + 1 + np.arange(f.width) / 10
            setattr(rows, f.name, a.reshape(-1) if f.width == 1 else a)
        others = [r for r in range(size) if r != rank]
        halo = Halo(comm, {r: np.array([0]) for r in others},
                    {r: np.array([1 + k]) for k, r in enumerate(others)})
        halo.forward(rows)
        flags = mpi.allreduce_max_array(comm, np.array([float(rank), -float(rank)]))
        decide("auto")
    for f in HALO:
        a = getattr(rows, f.name).reshape(size, f.width)
        for k, r in enumerate(others):
            assert np.array_equal(a[1 + k], r + 1 + np.arange(f.width) / 10), f.name
    assert flags.tolist() == [size - 1.0, 0.0]


def test_auto_sleeps_only_where_the_node_has_fewer_cores_than_ranks():
    """``auto``: the ranks on this node against the CPUs they may run on, together."""
    comm = MPI.COMM_WORLD
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    cpus = set().union(*node.allgather(os.sched_getaffinity(0)))
    expected = node.size > len(cpus)
    node.Free()
    assert decide("auto") == expected


def test_a_bad_mode_is_one_line_naming_the_variable():
    from pdem.errors import UserError

    with pytest.raises(UserError, match=r"PDEM_MPI_WAIT: must be one of auto, spin, sleep "
                                        r"\(got 'busy'\)"):
        decide("busy")
