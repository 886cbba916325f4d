"""Failures under MPI: an error on one rank aborts the whole job with that rank's message (no
hung job), and a blown-up model stops every rank with the same SimulationError naming the step,
the block and the probable cause."""

from __future__ import annotations

import os
import textwrap

import pytest
from mpi4py import MPI
from support import collective, launch_job, on_rank0, shared_dir, with_parallel

from pdem.errors import SimulationError

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(300, method="thread")]


def row_of_cubes(n: int, dims: str, dt: float | None = None, steps: int = 50) -> str:
    """``n`` 1 m cubes resting on a fixed floor, one every 2 m along x."""
    timestep = f", timestep: {{dt: {dt}}}" if dt else ""
    return f"""
name: row
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [{2 * n - 1}, 2, 0]}}, material: rock,
     fixed: true}}
  - name: cube
    array: {{box: {{min: [0, 0, 0], max: [1, 1, 1]}}, count: [{n}, 1, 1], spacing: [2, 1, 1]}}
    material: rock
parallel: {{dims: {dims}}}
solve: {{steps: {steps}, damping: local{timestep}}}
output: {{every_steps: 10}}
"""


CHILD = """
import sys
from pdem.stepper import Stepper
import pdem.cli

second_half = Stepper.second_half  # every step ends here, compiled runs of steps too

def failing_second_half(self, *args, **kwargs):
    if self.s.comm.rank == 1 and self.s.step >= 5:
        raise RuntimeError("boom on rank 1")
    return second_half(self, *args, **kwargs)

Stepper.second_half = failing_second_half
sys.exit(pdem.cli.main(["run", sys.argv[1], "-o", sys.argv[2], "-q"]))
"""


def run_child_job(launch_job, tmp: str):
    scene = os.path.join(tmp, "row.yaml")
    with open(scene, "w") as f:
        f.write(row_of_cubes(4, "[2, 1, 1]"))
    script = os.path.join(tmp, "child.py")
    with open(script, "w") as f:
        f.write(textwrap.dedent(CHILD))
    return launch_job(2, [script, scene, os.path.join(tmp, "row.h5")], timeout=60.0)


def test_error_on_one_rank_aborts_all(tmp_path):
    """RuntimeError on rank 1 only, at the end of step 5 (or of the first run of steps past
    it) of ``pdem run``: the job ends (rank 0 was waiting in the step's reduction) with a
    non-zero code and rank 1's message on stderr."""
    comm = MPI.COMM_WORLD
    rc, _, err, seconds = on_rank0(comm, run_child_job, launch_job, str(tmp_path))
    assert rc is not None, f"the 2-rank job hung (killed after {seconds:.0f} s); stderr:\n{err}"
    assert rc != 0, err
    assert "boom on rank 1" in err, err
    assert "rank 1" in err.replace("boom on rank 1", ""), err


def test_blow_up_stops_every_rank_with_the_same_message(tmp_path):
    """dt = 0.1 s with kn = 1e9 Pa/m: the cubes resting on the floor explode within a few steps.
    Every rank raises the SimulationError, with the message of the 1-rank run."""
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    text = row_of_cubes(2 * comm.size, f"[{comm.size}, 1, 1]", dt=0.1)
    scene = with_parallel(text, [comm.size, 1, 1], f"{base}/blowup.h5")

    def blow_up(scene, comm):
        from pdem.simulation import Simulation

        solver = Simulation(scene, comm, output=True)
        try:
            with pytest.raises(SimulationError) as info:
                solver.run()
        finally:
            solver.close()
        return str(info.value), solver.step

    with collective(comm, "the blow-up run"):
        message, step = blow_up(scene, comm)
    messages = comm.allgather(message)
    assert messages == [message] * comm.size, messages
    assert f"step {step}" in message and step < 50
    assert "block 'cube[" in message and "timestep" in message, message

    ref = with_parallel(text, [1, 1, 1], f"{base}/blowup-ref.h5")
    ref_message, _ = on_rank0(comm, blow_up, ref, MPI.COMM_SELF)
    assert message == ref_message
