"""The joint state in the output (contacts/, subcontacts/) is the same, bit for bit, on any
number of ranks: contacts across a subdomain boundary are held by both owners and written
once, and every snapshot's contacts are in key order.

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_joint_output_mpi.py``.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from support import differences, on_rank0, reference, run, shared_dir, with_parallel

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(600, method="thread")]

RHO, KN, G = 2500.0, 1.0e9, 9.81


def wall_scene(size: int) -> str:
    """Two courses of unit cubes on a fixed floor, the lower one's joints at integer x (one at
    x = 0, the [2, 1, 1] split), the upper one offset by half a cube: face and edge contacts
    across the subdomain boundaries, settling under gravity with local damping."""
    d = RHO * G / KN
    lower = [(-2.5 + k, -d) for k in range(6)]
    upper = [(-2.0 + k, 1.0 - 2 * d) for k in range(5)]
    cubes = "\n".join(
        f"  - {{name: c{i}, box: {{min: [{x - 0.5!r}, -0.5, {z!r}], "
        f"max: [{x + 0.5!r}, 0.5, {z + 1.0!r}]}}, material: rock}}"
        for i, (x, z) in enumerate(lower + upper))
    return f"""
name: wall
gravity: [0, 0, -{G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0, cohesion: 1.0e4, tension: 1.0e4}}}}
blocks:
  - {{name: floor, box: {{min: [-4, -1, -1], max: [4, 1, 0]}}, material: rock, fixed: true}}
{cubes}
parallel: {{dims: [{size}, 1, 1]}}
solve: {{steps: 600, damping: local}}
output: {{every_steps: 50}}
"""


def read_joints(path: str) -> dict:
    with h5py.File(path, "r") as f:
        return {f"{g}/{k}": f[f"{g}/{k}"][()] for g in ("contacts", "subcontacts")
                for k in f[g]}


def test_contacts_identical_on_any_rank_count(tmp_path):
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    scene = with_parallel(wall_scene(comm.size), [comm.size, 1, 1], f"{base}/wall.h5")
    run(scene, comm)

    def check():
        reference(scene, f"{base}/wall-ref.h5")
        a, b = read_joints(f"{base}/wall.h5"), read_joints(f"{base}/wall-ref.h5")
        bad = differences(f"{base}/wall.h5", f"{base}/wall-ref.h5")
        if a.keys() != b.keys():
            bad.append(f"datasets differ: {sorted(a.keys() ^ b.keys())}")
        for k in sorted(a.keys() & b.keys()):
            if a[k].shape != b[k].shape or not np.array_equal(a[k], b[k]):
                bad.append(f"{k}: shape {a[k].shape} vs {b[k].shape} or values differ")
        with h5py.File(f"{base}/wall.h5", "r") as f:
            lo, hi = f["contacts/offset"][-2:]
            blocks = f["contacts/block"][lo:hi]
            x = f["blocks/centroid"][-1, :, 0]
            fn = f["contacts/normal_force"][lo:hi]
            n_snap = len(f["time"])
        free = blocks[:, 0] > 0  # the floor is gid 0
        across = int(np.sum(((x[blocks[:, 0]] < 0) != (x[blocks[:, 1]] < 0)) & free))
        return bad, across, len(blocks), float(fn.sum()), n_snap

    bad, across, n, fn_sum, n_snap = on_rank0(comm, check)
    assert not bad, f"{comm.size}-rank contacts differ from the 1-rank run:\n" + "\n".join(bad)
    assert n_snap == 13 and n >= 6 + 5 + 5 + 4, n
    assert across >= 2, "no contact between free blocks across x = 0"
    if comm.rank == 0:
        print(f"\nwall on {comm.size} ranks: {n} contacts in the last snapshot, {across} across "
              f"x = 0; floor + joints carry {fn_sum:.6g} N")
