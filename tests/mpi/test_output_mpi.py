"""OutputWriter under MPI: the file is the same whatever the rank count and ownership."""

import itertools
import traceback

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.io import OutputWriter, read_xdmf


def rows(centroid, quat, velocity, angular_velocity) -> dict:
    return {"centroid": centroid, "orientation": quat, "velocity": velocity,
            "angular_velocity": angular_velocity}

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(120, method="thread")]

ATTRS = {"pdem_version": "0.1.0", "run_id": "mpi-test"}


def box(a, b, c):
    v = np.array([[sx * a, sy * b, sz * c] for sx, sy, sz in itertools.product((-1, 1), repeat=3)])
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return v, faces


def tet():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    return v - v.mean(axis=0), [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]


def make_scene(n):
    shapes = [box(0.5 + 0.1 * i, 0.4, 0.3) if i % 2 == 0 else tet() for i in range(n)]
    return {
        "block_names": [f"block-{i}" for i in range(n)],
        "body_vertices": [s[0] for s in shapes],
        "body_faces": [s[1] for s in shapes],
        "scene_yaml": f"name: mpi-{n}\n",
        "attrs": ATTRS,
    }


def make_snapshots(n, n_snap=3, seed=7):
    """The same global data on every rank (seeded)."""
    rng = np.random.default_rng(seed)
    snaps = []
    for s in range(n_snap):
        q = rng.normal(size=(n, 4))
        snaps.append(
            (100 * s, 0.5 * s, rng.normal(size=(n, 3)), q / np.linalg.norm(q, axis=1)[:, None],
             rng.normal(size=(n, 3)), rng.normal(size=(n, 3)))
        )
    return snaps


def write_run(path, comm, n, owned, hist_owner, **kw):
    """Write a run where this rank owns the gids ``owned`` (any order)."""
    owned = np.asarray(owned, dtype=np.int64)
    # viewer fields too: group/fixed static, displacement from the first snapshot (collective)
    viewer = {"group": np.arange(n) % 2, "group_names": ["even", "odd"], "fixed": np.arange(n) == 0}
    with OutputWriter(path, comm, **make_scene(n), **viewer, **kw) as w:
        w.add_history("z0", 1, {"block": "block-0"})
        for step, t, c, q, v, om in make_snapshots(n):
            w.write_snapshot(step, t, owned, rows(c[owned], q[owned], v[owned], om[owned]))
            w.write_history("z0", t, c[0, 2:3] if comm.rank == hist_owner else None)


def h5_contents(path):
    out = {}
    with h5py.File(path, "r") as f:
        out["/@"] = {k: f.attrs[k] for k in f.attrs}

        def visit(name, obj):
            out[name + "@"] = {k: obj.attrs[k] for k in obj.attrs}
            if isinstance(obj, h5py.Dataset):
                out[name] = (obj.dtype, obj[()])

        f.visititems(visit)
    return out


def assert_same_contents(a, b):
    ca, cb = h5_contents(a), h5_contents(b)
    assert ca.keys() == cb.keys()
    for key in ca:
        if key.endswith("@"):
            assert ca[key].keys() == cb[key].keys(), key
            for k in ca[key]:
                assert np.array_equal(ca[key][k], cb[key][k]), (key, k)
        else:
            assert ca[key][0] == cb[key][0], key
            assert ca[key][1].shape == cb[key][1].shape, key
            assert np.array_equal(ca[key][1], cb[key][1]), key


def check_against_reference(tmp_path, comm, n, owned, hist_owner, **kw):
    assert comm.size >= 2, "run under mpiexec -n 2 (or more) with MPICH's launcher"
    base = comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)
    path = f"{base}/run.h5"
    write_run(path, comm, n, owned, hist_owner, **kw)
    err = None
    if comm.rank == 0:
        try:
            ref = f"{base}/ref.h5"
            write_run(ref, MPI.COMM_SELF, n, np.arange(n), 0)
            assert_same_contents(path, ref)
            steps = read_xdmf(f"{base}/run.xdmf")["surface"]
            assert [s["time"] for s in steps] == [0.0, 0.5, 1.0]
        except Exception:
            err = traceback.format_exc()
    err = comm.bcast(err, root=0)
    assert err is None, f"rank 0: {err}"


def test_interleaved_ownership(tmp_path):
    comm = MPI.COMM_WORLD
    n = 11
    owned = np.arange(n)[np.arange(n) % comm.size == comm.rank][::-1]
    check_against_reference(tmp_path, comm, n, owned, hist_owner=comm.size - 1)


def test_one_rank_owns_nothing(tmp_path):
    comm = MPI.COMM_WORLD
    n = 9
    # the last rank owns nothing; the others share the blocks in scrambled order
    owners = np.random.default_rng(3).integers(0, comm.size - 1, n)
    owned = np.flatnonzero(owners == comm.rank)[::-1] if comm.rank < comm.size - 1 else []
    check_against_reference(tmp_path, comm, n, owned, hist_owner=int(owners[0]))


def test_fewer_blocks_than_ranks(tmp_path):
    comm = MPI.COMM_WORLD
    n = comm.size - 1  # some rank writes an empty range in every dataset
    owned = [comm.size - 1 - comm.rank] if comm.rank > 0 else []
    check_against_reference(tmp_path, comm, n, owned, hist_owner=comm.size - 1)


def test_gather_fallback(tmp_path):
    comm = MPI.COMM_WORLD
    n = 7
    owned = np.arange(n)[np.arange(n) % comm.size == comm.rank]
    check_against_reference(tmp_path, comm, n, owned, hist_owner=comm.size - 1, parallel=False)


def test_bad_ownership_raises_on_every_rank(tmp_path):
    comm = MPI.COMM_WORLD
    assert comm.size >= 2
    base = comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)
    n = 4
    snap = make_snapshots(n)[0]
    with OutputWriter(f"{base}/bad.h5", comm, **make_scene(n)) as w:
        owned = np.array([0]) if comm.rank < 2 else np.array([], dtype=np.int64)
        if comm.rank == 0:
            owned = np.array([0, 1, 2, 3])  # rank 1 also claims gid 0
        _, t, c, q, v, om = snap
        with pytest.raises(ValueError, match="exactly one rank"):
            w.write_snapshot(0, t, owned, rows(c[owned], q[owned], v[owned], om[owned]))
        w.add_history("h", 1)
        with pytest.raises(ValueError, match="exactly one rank"):
            w.write_history("h", t, [1.0])  # every rank claims it
        # the writer is still usable after a collective error
        owned = np.arange(n)[np.arange(n) % comm.size == comm.rank]
        w.write_snapshot(0, t, owned, rows(c[owned], q[owned], v[owned], om[owned]))
    comm.Barrier()
    if comm.rank == 0:
        with h5py.File(f"{base}/bad.h5", "r") as f:
            assert f["time"].shape == (1,)
            assert np.array_equal(f["blocks/centroid"][0], c)


def test_writer_keeps_its_range_of_the_static_fields(tmp_path):
    """Of every block's group, fixed flag and initial centroid a writer keeps only its gid
    range once the file is open (no rank keeps 32 bytes of every block); a snapshot without
    stage origins, from blocks owned across the ranks' ranges, still records every block's
    initial centroid as its origin."""
    comm = MPI.COMM_WORLD
    n = 11
    base = comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)
    x0 = np.random.default_rng(3).normal(size=(n, 3))
    owned = np.arange(n)[np.arange(n) % comm.size == (comm.rank + 1) % comm.size]
    viewer = {"group": np.arange(n) % 2, "group_names": ["even", "odd"],
              "fixed": np.arange(n) == 0, "initial_centroid": x0}
    path = f"{base}/range.h5"
    with OutputWriter(path, comm, **make_scene(n), **viewer) as w:
        lo, hi = w._lo, w._hi
        assert w._group is None and w._fixed is None and w._x0.shape == (hi - lo, 3)
        assert hi - lo < n
        for step, t, c, q, v, om in make_snapshots(n):
            w.write_snapshot(step, t, owned, rows(c[owned], q[owned], v[owned], om[owned]))
    err = None
    if comm.rank == 0:  # every rank learns of a failed check (none left waiting)
        try:
            with h5py.File(path, "r") as f:
                assert np.array_equal(f["blocks/initial_centroid"][()], x0)
                origin = f["blocks/stage_origin"][()]
                assert origin.shape == (3, n, 3)
                assert np.array_equal(origin, np.broadcast_to(x0, origin.shape))
                assert np.array_equal(f["blocks/fixed"][()], (np.arange(n) == 0).astype(np.int32))
                assert np.array_equal(f["blocks/group"][()], np.arange(n) % 2)
        except Exception:
            err = traceback.format_exc()
    err = comm.bcast(err, root=0)
    assert err is None, f"rank 0: {err}"
