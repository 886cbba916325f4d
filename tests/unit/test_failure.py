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


UNSTABLE_ROCKING = """
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, 0.0], max: [0.5, 0.5, 1.0]}, material: rock,
     velocity: [0.0, 0.0, -0.01], angular_velocity: [0.01, 0.0, 0.0]}
solve: {steps: 3000, timestep: {frac: 1.0}}
output: {file: OUT, every_steps: 100, energy_every: 10}
"""


def test_energy_guard_stops_an_unstable_step_and_blames_the_timestep(tmp_path):
    """frac 1.0 puts the rocking mode of a cube on four corner springs past the leap-frog's
    stability limit (omega dt = 2.4 > 2): the energy grows and the guard stops the run long
    before any speed is noticeably wrong, naming the block and the timestep."""
    s = Simulation(parse_scene(UNSTABLE_ROCKING.replace("OUT", str(tmp_path / "r.h5"))),
                   MPI.COMM_SELF)
    with pytest.raises(SimulationError) as info:
        s.run()
    s.close()
    msg = str(info.value)
    assert "energy balance error grew" in msg and "block 'cube'" in msg
    assert "timestep" in msg and "solve.energy_tolerance" in msg
    assert s.step < 3000


def _totals(**kw):
    """energy_totals' dict (every budget column but the balance error), zeros but ``kw``."""
    from pdem.plugins.energy import COLUMNS

    t = dict.fromkeys(COLUMNS[:-1], 0.0)
    t.update(kw)
    return t


def test_diagnosis_tells_the_source_of_created_energy():
    """The cause named follows the budget: energy from contact geometry updates points at
    detect_every / point_area, from the time stepping at the timestep, none at the loads."""
    from pdem.dynamics.diagnosis import explain

    s = Simulation(parse_scene(UNSTABLE.replace("checkpoint: {every_steps: 1000, file: CK}\n",
                                                "")), MPI.COMM_SELF, output=False)
    start = (0.0, 0.0)
    # 100 J released by gravity; 30 J more kinetic energy than that, all made at updates
    geometry = _totals(kinetic=130.0, gravity_work=100.0, contact_work=30.0,
                       strain=-30.0 + 30.0, geometry_created=30.0)
    msg = explain(s.state, geometry, start, 1)
    assert "contact geometry updates" in msg and "detect_every" in msg and "timestep 0" not in msg
    stepping = _totals(kinetic=130.0, gravity_work=100.0)
    assert "timestep" in explain(s.state, stepping, start, 1)
    balanced = _totals(kinetic=100.0, gravity_work=100.0)
    assert "loads" in explain(s.state, balanced, start, 1)
