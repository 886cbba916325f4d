"""Rayleigh damping's dashpots at the joints (pdem.contact.forces.dashpot) on several ranks: a
pile of blocks dropped under Rayleigh damping gives block states bitwise identical to the
1-rank run (the dashpots' forces are summed in contact order, as the springs', and their
dissipation booked per block), and its energy budget balances."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from support import compare_on_rank0, on_rank0, run, shared_dir, with_parallel
from test_deformable_mpi import energy_history

from pdem.cases.collapse import pile_scene

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(900, method="thread")]


def rayleigh_pile() -> str:
    return pile_scene(count=16, time=0.3).replace(
        "damping: none", "damping: {mode: rayleigh, fraction: 0.05, frequency: 10.0}")


def test_a_rayleigh_damped_pile_is_bitwise_the_one_rank_run(tmp_path):
    comm = MPI.COMM_WORLD
    d = shared_dir(comm, tmp_path)
    path = f"{d}/pile.h5"
    scene = with_parallel(rayleigh_pile(), "auto", path, every_steps=200)
    run(scene, comm)
    compare_on_rank0(comm, path, scene, f"{d}/pile-ref.h5")
    e = on_rank0(comm, energy_history, path)
    assert e["damping_dissipation"][-1] > 0.0
    assert np.abs(e["balance_error"]).max() < 1e-2 * e["gravity_work"][-1]
