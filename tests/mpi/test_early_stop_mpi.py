"""A solve that cannot reach its ratio stops on every rank after the same step, with the same
line as on one rank (pdem.plugins.no_progress): the stop is decided on the reduced ratio and
the step count, the blocks it names are gathered from their owners. No rank is left waiting.

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_early_stop_mpi.py``.
"""

from __future__ import annotations

import pytest
from mpi4py import MPI
from support import TWO_RANKS_ONLY, collective, on_rank0, shared_dir, with_parallel

from pdem.cases.runaway import slide_off_scene
from pdem.config import parse_scene
from pdem.errors import NoProgressError
from pdem.simulation import Simulation

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(600, method="thread")]

WINDOW = 10_000


def stalled(scene, comm) -> tuple[str, int]:
    """(the NoProgressError's message, the step it stopped at) of ``scene`` on ``comm``."""
    sim = Simulation(scene, comm)
    try:
        sim.run()
        return "not stopped", sim.step
    except NoProgressError as exc:
        return str(exc), sim.step
    finally:
        sim.close()


def test_a_stalled_stage_stops_every_rank_alike(tmp_path):
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    # (max_steps: without the watch the stage would end there, not hang)
    text = slide_off_scene(WINDOW, "ratio: 1.0e-5, max_steps: 60000")
    scene = with_parallel(text, [comm.size, 1, 1], f"{base}/off.h5", every_steps=1000)
    with collective(comm, "a stalled run"):  # any other error aborts the job, never hangs it
        got = stalled(scene, comm)
    everyone = comm.allgather(got)
    print(f"\n{comm.size} ranks: stopped at step {got[1]}: {got[0]}")
    assert all(g == everyone[0] for g in everyone), everyone
    assert "block 'slider' is falling with no contacts at" in got[0]
    # the same step and the same words as one rank (the same bits: the same numbers)
    one = parse_scene(text.replace("stages:", f"output: {{file: {base}/one.h5}}\nstages:", 1))
    assert on_rank0(comm, stalled, one, MPI.COMM_SELF) == got
