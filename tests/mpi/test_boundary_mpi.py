"""Boundary conditions (pdem.boundary) give bitwise the 1-rank run on several ranks: a base
shaken by a harmonic velocity history (or an earthquake record, a history file) under a row
of cubes that spans the rank split at x = 0, with a boundary pressure on one cube's exposed
faces and one cube's z velocity prescribed.

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_boundary_mpi.py``.
"""

from __future__ import annotations

import pytest
from mpi4py import MPI
from support import TWO_RANKS_ONLY, shared_dir, slabs_match_one_rank

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(300, method="thread")]

SCENE = """
materials: {rock: {density: 2500.0}}
joints: {default: {kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
blocks:
  - {name: base, box: {min: [-3, -1, -0.5], max: [3, 1, 0]}, material: rock, group: base}
  - name: row
    array: {box: {min: [-2.2, -0.5, 0], max: [-1.2, 0.5, 1]}, count: [4, 1, 1], spacing: [1.1, 1, 1]}
    material: rock
boundary:
  velocity:
    - groups: [base]
      history: {harmonic: {amplitude: [0.3, 0.1, 0], frequency: 3.0, phase: 20}}
    - {names: ["row[3]"], components: [z], velocity: [0, 0, -0.01]}
  stress:
    - {names: ["row[1]"], pressure: 1.0e4}
solve: {time: 0.25, damping: none}
"""


def test_shaken_row_matches_one_rank(tmp_path):
    slabs_match_one_rank(tmp_path, SCENE, "shake", 100)


def test_row_shaken_by_a_record_matches_one_rank(tmp_path):
    """The base driven by the shipped AT2 record (every rank reads the file, the same bits)
    along a tilted direction, at 20 times its scale (its first 0.25 s is the envelope's
    rise: peaks of about 0.4 g then)."""
    from pathlib import Path

    at2 = Path(__file__).resolve().parents[2] / "configs/records/synthetic-0.3g.at2"
    text = SCENE.replace(
        "history: {harmonic: {amplitude: [0.3, 0.1, 0], frequency: 3.0, phase: 20}}",
        f"history: {{file: {at2}, quantity: acceleration, direction: [3, 1, 0], "
        "scale: 196.2}")
    assert str(at2) in text
    slabs_match_one_rank(tmp_path, text, "record", 100)


def test_shaken_row_restarts_bitwise(tmp_path):
    """A checkpoint taken mid-shake, restarted on every rank of the job, ends where the
    straight run ends: the history's clock and the stress faces come back with the model."""
    import glob

    import h5py
    import numpy as np

    from pdem.config import parse_scene
    from pdem.io.checkpoint import read_checkpoint
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    text = SCENE + (f"output: {{file: {base}/straight.h5, every_steps: 200}}\n"
                    f"checkpoint: {{every_steps: 300, keep: 5, file: {base}/ck}}\n")
    s = Simulation(parse_scene(text), comm)
    s.run()
    s.close()
    ck = read_checkpoint(sorted(glob.glob(f"{base}/ck-*.h5"))[0])
    scene = parse_scene(ck["attrs"]["scene"])
    out = f"{base}/again.h5"
    scene = scene.model_copy(update={"output": scene.output.model_copy(update={"file": out}),
                                     "checkpoint": None})
    r = Simulation(scene, comm, checkpoint=ck)
    r.run()
    r.close()
    comm.Barrier()
    if comm.rank == 0:
        with h5py.File(f"{base}/straight.h5") as a, h5py.File(out) as b:
            for k in ("centroid", "orientation", "velocity", "angular_velocity"):
                assert np.array_equal(a[f"blocks/{k}"][-1], b[f"blocks/{k}"][-1]), k
