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
from support import TWO_RANKS_ONLY, differences, on_rank0, reference, run, shared_dir, with_parallel

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(600, method="thread")]

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
    scene = with_parallel(wall_scene(comm.size), [comm.size, 1, 1], f"{base}/wall.h5",
                          contacts=True)
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


def synthetic(n_blocks: int, n_snap: int, seed: int = 7):
    """Per snapshot, contacts between random block pairs with 0..5 sub-contacts each."""
    rng = np.random.default_rng(seed)
    snaps = []
    for i in range(n_snap):
        pairs = sorted({tuple(sorted(rng.choice(n_blocks, 2, replace=False).tolist()))
                        for _ in range(3 * i)})  # snapshot 0 has none
        k = len(pairs)
        nsub = rng.integers(1, 6, k)
        m = int(nsub.sum())
        snaps.append({
            "piece": np.array(pairs, np.int64).reshape(-1, 2),
            "block": np.array(pairs, np.int64).reshape(-1, 2), "joint": np.zeros(k, np.int32),
            "point": rng.normal(size=(k, 3)), "normal": rng.normal(size=(k, 3)), "n_sub": nsub,
            "sub": {"point": rng.normal(size=(m, 3)), "area": rng.random(m),
                    "overlap": rng.normal(size=m), "normal_force": rng.normal(size=m),
                    "shear_force": rng.normal(size=(m, 3)),
                    "shear_displacement": rng.normal(size=(m, 3)),
                    "state": rng.integers(0, 8, m)}})
    return snaps


def share(snap: dict, mask: np.ndarray) -> dict:
    """The contacts ``mask`` of a snapshot (reversed: any order is allowed), subs carried."""
    idx = np.nonzero(mask)[0][::-1]
    start = np.concatenate([[0], np.cumsum(snap["n_sub"])])
    sub_idx = np.concatenate([np.arange(start[j], start[j + 1]) for j in idx] or
                             [np.zeros(0, np.int64)]).astype(np.int64)
    out = {k: v[idx] for k, v in snap.items() if k != "sub"}
    out["sub"] = {k: v[sub_idx] for k, v in snap["sub"].items()}
    return out


@pytest.mark.parametrize("parallel", [True, False])
def test_writer_contacts_any_split(tmp_path, parallel):
    """OutputWriter alone: contacts split over the ranks any way (rank 1 passing none in one
    snapshot), mpio and the gather fallback, give the 1-rank file's datasets."""
    from pdem.io import OutputWriter

    if parallel and not h5py.get_config().mpi:
        pytest.skip("h5py without MPI")
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    n = 9
    v = np.array([[x, y, z] for x in (-.5, .5) for y in (-.5, .5) for z in (-.5, .5)])
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    kw = {"block_names": [f"b{i}" for i in range(n)], "body_vertices": [v] * n,
          "body_faces": [faces] * n, "scene_yaml": "name: x\n", "contacts": True,
          "joint_names": ["default"]}
    snaps = synthetic(n, 5)

    def write(path, comm, parallel):
        with OutputWriter(path, comm, parallel=parallel, **kw) as w:
            for i, snap in enumerate(snaps):
                gids = np.arange(n)[comm.rank::comm.size]
                k = len(gids)
                fields = {"centroid": np.zeros((k, 3)) + gids[:, None],
                          "orientation": np.tile([1.0, 0, 0, 0], (k, 1)),
                          "velocity": np.zeros((k, 3)), "angular_velocity": np.zeros((k, 3))}
                rank = np.arange(len(snap["n_sub"])) % comm.size
                if i == 2:
                    rank[:] = 0  # the other ranks pass nothing
                w.write_snapshot(i, 0.1 * i, gids, fields, contacts=share(snap, rank == comm.rank))

    write(f"{base}/w.h5", comm, parallel)

    def check():
        write(f"{base}/w-ref.h5", MPI.COMM_SELF, False)
        a, b = read_joints(f"{base}/w.h5"), read_joints(f"{base}/w-ref.h5")
        bad = [k for k in a if a[k].shape != b[k].shape or not np.array_equal(a[k], b[k])]
        with h5py.File(f"{base}/w.h5", "r") as f:
            counts = np.diff(f["contacts/offset"][()]).tolist()
        return bad, counts, a["contacts/n_sub"].sum() == len(a["subcontacts/area"])

    bad, counts, consistent = on_rank0(comm, check)
    assert not bad and consistent, bad
    assert counts == [len(s["n_sub"]) for s in snaps] and counts[0] == 0


def test_writer_streams_each_ranks_rows(tmp_path, monkeypatch):
    """Issue 39: each rank writes only the rows of its gid range (no rank gathers the model)
    and the contacts of its range's blocks A, in several rounds when they exceed ROUND_ROWS,
    and the file is the one written whole on one rank. A spy on the low-level write records
    every selection each rank writes."""
    import pdem.io.contact_series as contact_series
    from pdem.io import OutputWriter
    from pdem.io.h5core import H5Core

    if not h5py.get_config().mpi:
        pytest.skip("h5py without MPI: the fallback gathers on rank 0 by design")
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    n = 11
    v = np.array([[x, y, z] for x in (-.5, .5) for y in (-.5, .5) for z in (-.5, .5)])
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    kw = {"block_names": [f"b{i}" for i in range(n)], "body_vertices": [v] * n,
          "body_faces": [faces] * n, "scene_yaml": "name: x\n", "contacts": True,
          "joint_names": ["default"]}
    snaps = synthetic(n, 6, seed=3)

    def write(path, comm):
        with OutputWriter(path, comm, parallel=comm.size > 1 or None, **kw) as w:
            for i, snap in enumerate(snaps):
                gids = np.arange(n)[::-1][comm.rank::comm.size]  # not the writer's ranges
                k = len(gids)
                fields = {"centroid": np.zeros((k, 3)) + gids[:, None],
                          "orientation": np.tile([1.0, 0, 0, 0], (k, 1)),
                          "velocity": np.zeros((k, 3)), "angular_velocity": np.zeros((k, 3))}
                rank = (np.arange(len(snap["n_sub"])) + 1) % comm.size
                w.write_snapshot(i, 0.1 * i, gids, fields,
                                 contacts=share(snap, rank == comm.rank))
            return w._lo, w._hi, w._blocks.vlo, w._blocks.vhi

    writes = []
    real = H5Core.write

    def spy(self, dset, start, data):
        if data is not None and data.size:
            writes.append((dset.name, tuple(int(s) for s in start), data.shape))
        return real(self, dset, start, data)

    monkeypatch.setattr(H5Core, "write", spy)
    monkeypatch.setattr(contact_series, "ROUND_ROWS", 8)
    lo, hi, vlo, vhi = write(f"{base}/s.h5", comm)
    monkeypatch.setattr(H5Core, "write", real)
    monkeypatch.setattr(contact_series, "ROUND_ROWS", 1 << 16)
    assert 0 < hi - lo < n
    for name, start, shape in writes:
        if name.startswith("/blocks/") and len(shape) > 1 and shape[0] == 1:  # a series
            assert start[1] == lo and shape[1] <= hi - lo, (name, start, shape, lo, hi)
        if name == "/surface/points":
            assert start[1] == vlo and start[1] + shape[1] <= vhi, (name, start, vlo, vhi)
    mine = [(s[0], shape[0]) for name, s, shape in writes if name == "/contacts/block"]
    all_mine = comm.allgather(mine)
    ranges = comm.allgather((lo, hi))

    def check():
        write(f"{base}/s-ref.h5", MPI.COMM_SELF)
        a, b = read_joints(f"{base}/s.h5"), read_joints(f"{base}/s-ref.h5")
        bad = [k for k in a if a[k].shape != b[k].shape or not np.array_equal(a[k], b[k])]
        with h5py.File(f"{base}/s.h5", "r") as f:
            block_a = f["contacts/block"][:, 0]
        outside = [(r, s, c) for r, rows in enumerate(all_mine) for s, c in rows
                   if not ((block_a[s:s + c] >= ranges[r][0])
                           & (block_a[s:s + c] < ranges[r][1])).all()]
        return bad, outside

    bad, outside = on_rank0(comm, check)
    assert not bad, bad
    assert not outside, f"contacts written by a rank whose range does not hold block A: {outside}"
    # the contacts went out in rounds: more non-empty writes than snapshots with contacts
    assert sum(len(m) for m in all_mine) > len(snaps), all_mine
