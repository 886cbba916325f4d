"""Quiet faces and wave input on rigid blocks (pdem.dynamics.quiet) give bitwise the 1-rank run
on two ranks, and a restart ends where the straight run ends: a free rigid slab whose bottom
face is quiet takes a harmonic wave (tilted: P and S) through it and shakes a row of cubes
that spans the rank split at x = 0, one cube's side faces quiet too (shear only); the output
(block states and the energy history, its ``quiet_absorbed`` column in) is compared whole.

A held slab released to its quiet face by a stage (``release``: the force and moment that
held it kept as its load) and shaken through it steps bitwise as on one rank too.

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_rigid_quiet_mpi.py``.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from support import TWO_RANKS_ONLY, restart_from, shared_dir, slabs_match_one_rank, straight_with_checkpoint

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(300, method="thread")]

SCENE = """
gravity: [0, 0, 0]
materials: {rock: {density: 2500.0, young: 2.0e9, poisson: 0.25}}
joints: {default: {kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
blocks:
  - {name: slab, box: {min: [-3, -1, -0.5], max: [3, 1, 0]}, material: rock}
  - name: row
    array: {box: {min: [-2.2, -0.5, 0], max: [-1.2, 0.5, 1]}, count: [4, 1, 1], spacing: [1.1, 1, 1]}
    material: rock
boundary:
  quiet:
    - {names: [slab], range: {box: {min: [-4, -2, -0.6], max: [4, 2, -0.4]}}}
    - {names: ["row[2]"], directions: [shear]}
  stress:
    - names: [slab]
      range: {box: {min: [-4, -2, -0.6], max: [4, 2, -0.4]}}
      wave: {harmonic: {amplitude: [0.05, 0.02, 0.03], frequency: 8.0, phase: 30}}
solve: {time: 0.2, damping: none}
output: {energy_every: 25}
"""

def test_a_slab_shaken_through_its_quiet_face_matches_one_rank(tmp_path):
    slabs_match_one_rank(tmp_path, SCENE, "rigid-quiet", 100)


RELEASED = """
gravity: [0, 0, -9.81]
materials: {rock: {density: 2500.0, young: 2.0e9, poisson: 0.25}}
joints: {default: {kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
blocks:
  - {name: slab, box: {min: [-3, -1, -0.5], max: [3, 1, 0]}, material: rock, fixed: true}
  - name: row
    array: {box: {min: [-2.2, -0.5, 0], max: [-1.2, 0.5, 1]}, count: [4, 1, 1], spacing: [1.1, 1, 1]}
    material: rock
solve: {damping: local}
stages:
  - {name: settle, solve: {steps: 300}}
  - name: shaken
    quiet: [{names: [slab], range: {box: {min: [-4, -2, -0.6], max: [4, 2, -0.4]}}, release: true}]
    stress:
      - names: [slab]
        range: {box: {min: [-4, -2, -0.6], max: [4, 2, -0.4]}}
        wave: {harmonic: {amplitude: [0.02, 0.0, 0.03], frequency: 8.0}}
    solve: {steps: 400, damping: none}
output: {energy_every: 25}
"""


def test_a_held_slab_released_to_its_quiet_face_matches_one_rank(tmp_path):
    """The slab's reaction (summed contact by contact) and, once it is free, its contacts
    with the cubes its owner did not compute while it was fixed (handed over at the stage
    start, pdem.stages.apply_stage): bitwise the 1-rank run."""
    slabs_match_one_rank(tmp_path, RELEASED, "released", 50)


def test_a_slab_shaken_through_its_quiet_face_restarts_bitwise(tmp_path):
    """A checkpoint taken mid-run, restarted on every rank of the job: the quiet faces, the
    wave's clock and the absorbed energy (the blocks' ``work``) come back with the model
    (a released block's load: tests/verification/test_rigid_quiet.py, on one rank)."""
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    ck = straight_with_checkpoint(comm, base, SCENE, 450)
    out = f"{base}/again.h5"
    restart_from(comm, ck, out)
    if comm.rank == 0:
        with h5py.File(f"{base}/straight.h5") as a, h5py.File(out) as b:
            for k in ("centroid", "orientation", "velocity", "angular_velocity"):
                assert np.array_equal(a[f"blocks/{k}"][-1], b[f"blocks/{k}"][-1]), k
            ea, eb = a["histories/energy/value"][()], b["histories/energy/value"][()]
            cols = a["histories/energy"].attrs["columns"].split(",")
            q = cols.index("quiet_absorbed")
            assert ea[-1, q] > 0.0
            assert np.array_equal(ea[-1], eb[-1]), (ea[-1], eb[-1])
