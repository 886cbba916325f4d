"""A run that blows up stops with a message naming block, step and cause, after a final
checkpoint; a bad checkpoint path is a clear error."""

import os

import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.errors import SimulationError
from pdem.io.checkpoint import read_checkpoint
from pdem.simulation import Simulation

UNSTABLE = """
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e12, ks: 1.0e12}}
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, -0.001], max: [0.5, 0.5, 0.999]}, material: rock}
contact: {overlap_tolerance: 0.01}
solve: {steps: 2000, timestep: {dt: 0.01}}
checkpoint: {every_steps: 1000, file: CK}
"""


def test_runaway_names_block_step_and_cause_after_final_checkpoint(tmp_path):
    prefix = os.path.join(tmp_path, "ck")
    s = Simulation(parse_scene(UNSTABLE.replace("CK", prefix)), MPI.COMM_SELF, output=False)
    with pytest.raises(SimulationError) as info:
        s.run()
    msg = str(info.value)
    assert "block 'cube'" in msg and f"step {s.step}" in msg and "timestep" in msg
    failed = f"{prefix}-{s.step:09d}-failed.h5"
    ck = read_checkpoint(failed)
    assert int(ck["attrs"]["step"]) == s.step


def test_missing_or_foreign_checkpoint(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_checkpoint(tmp_path / "nope.h5")
    import h5py

    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(ValueError, match="not a pdem checkpoint"):
        read_checkpoint(tmp_path / "other.h5")
