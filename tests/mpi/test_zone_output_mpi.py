"""Zoned blocks in the output file under MPI: the same file whatever the rank count and whichever
rank owns which zoned block (interleaved, none, all on one), parallel and gathered."""

import traceback
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.io import OutputWriter, read_xdmf, zones_path
from pdem.io.zone_surfaces import boundary_of

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(120, method="thread")]

N_BLOCKS = 9
ZONED = [1, 2, 4, 5, 8]  # gids of the zoned blocks; the others rigid only


def make_scene():
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return {"block_names": [f"b{i}" for i in range(N_BLOCKS)],
            "body_vertices": [v * (1 + 0.1 * i) for i in range(N_BLOCKS)],
            "body_faces": [faces] * N_BLOCKS, "scene_yaml": "name: zones-mpi\n"}


def body(gid, snap):
    """Zoned block ``gid`` at snapshot ``snap``: the same numbers on every rank (seeded)."""
    rng = np.random.default_rng(100 * gid + 7)
    n, m = 5 + gid, 3 + 2 * gid
    x0 = rng.normal(size=(n, 3))
    tets = np.stack([rng.choice(n, 4, replace=False) for _ in range(m)])
    rng = np.random.default_rng(1000 * gid + snap)
    return SimpleNamespace(nodes0=x0, tets=tets, nodes=x0 + 0.01 * rng.normal(size=(n, 3)),
                           vel=rng.normal(size=(n, 3)), stress=1e5 * rng.normal(size=(m, 6)),
                           plastic=rng.integers(0, 16, m).astype(np.int32))


def write_run(path, comm, rigid, zoned, **kw):
    """This rank owns the rigid rows ``rigid`` and the zoned blocks ``zoned`` (any order)."""
    rigid = np.asarray(rigid, np.int64)
    with OutputWriter(path, comm, **make_scene(), zones=[(g, body(g, 0)) for g in zoned],
                      **kw) as w:
        for s in range(3):
            rng = np.random.default_rng(s)
            c, v, om = (rng.normal(size=(N_BLOCKS, 3)) for _ in range(3))
            q = np.tile([1.0, 0.0, 0.0, 0.0], (N_BLOCKS, 1))
            w.write_snapshot(s, 0.5 * s, rigid, {"centroid": c[rigid], "orientation": q[rigid],
                                                 "velocity": v[rigid],
                                                 "angular_velocity": om[rigid]},
                             zones=[(g, body(g, s)) for g in zoned])


def contents(path):
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            out[name + "@"] = {k: obj.attrs[k] for k in obj.attrs}
            if isinstance(obj, h5py.Dataset):
                out[name] = (obj.dtype, obj[()])
        out["/@"] = {k: f.attrs[k] for k in f.attrs}
        f.visititems(visit)
    return out


def check(tmp_path, rigid, zoned, **kw):
    comm = MPI.COMM_WORLD
    assert comm.size >= 2, "run under mpiexec -n 2 (or more) with MPICH's launcher"
    base = comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)
    write_run(f"{base}/run.h5", comm, rigid, zoned, **kw)
    err = None
    if comm.rank == 0:
        try:
            write_run(f"{base}/ref.h5", MPI.COMM_SELF, np.arange(N_BLOCKS), ZONED,
                      **{k: v for k, v in kw.items() if k == "zone_fields"})
            a, b = contents(f"{base}/run.h5"), contents(f"{base}/ref.h5")
            assert a.keys() == b.keys()
            for key in a:
                if key.endswith("@"):
                    assert all(np.array_equal(a[key][k], b[key][k]) for k in a[key]), key
                else:
                    assert a[key][0] == b[key][0] and np.array_equal(a[key][1], b[key][1]), key
            with h5py.File(f"{base}/run.h5", "r") as f:  # the values are the blocks'
                z = f["zones"]
                for k, g in enumerate(ZONED):
                    p = slice(*z["point_start"][k:k + 2])
                    zz = slice(*z["zone_start"][k:k + 2])
                    b2 = body(g, 2)
                    assert np.array_equal(z["points"][2, p], b2.nodes)
                    if "displacement" in z:  # float32 series: the values rounded once
                        assert np.array_equal(z["displacement"][2, p],
                                              (b2.nodes - b2.nodes0).astype(np.float32))
                    if "stress" in z:
                        assert np.array_equal(z["stress"][2, zz], b2.stress.astype(np.float32))
                    assert np.array_equal(z["connectivity"][zz], b2.tets + p.start)
                    # run.xdmf: the block's triangles are its grid's boundary at its gridpoints
                    nodes, tris = boundary_of(b2.tets)
                    conn = f["surface/connectivity"][()][f["surface/block_id"][()] == g]
                    assert np.array_equal(conn - conn.min(), tris)
                    assert np.array_equal(f["surface/points"][2][conn], b2.nodes[nodes][tris])
            grids = read_xdmf(zones_path(f"{base}/run.xdmf"))["zones"]
            assert [g["time"] for g in grids] == [0.0, 0.5, 1.0]
        except Exception:
            err = traceback.format_exc()
    err = comm.bcast(err, root=0)
    assert err is None, f"rank 0: {err}"


def mine(gids):
    comm = MPI.COMM_WORLD
    return [g for i, g in enumerate(gids) if i % comm.size == comm.rank]


def test_interleaved_ownership(tmp_path):
    if MPI.COMM_WORLD.size > 3:  # ~10-35 s each on the oversubscribed 4-rank tier
        pytest.skip("the writer's interleaving on the 2- and 3-rank tiers")
    # each rank's zoned blocks are not next to one another in gid order, and come reversed
    check(tmp_path, mine(range(N_BLOCKS))[::-1], mine(ZONED)[::-1])


def test_chosen_fields_interleaved(tmp_path):
    if MPI.COMM_WORLD.size > 3:
        pytest.skip("the writer's interleaving on the 2- and 3-rank tiers")
    check(tmp_path, mine(range(N_BLOCKS)), mine(ZONED)[::-1],
          zone_fields=["sigma3", "velocity", "plastic"])


def test_zoned_blocks_on_one_rank(tmp_path):
    comm = MPI.COMM_WORLD
    if comm.size > 2:
        pytest.skip("the 2-rank tier's (the layout does not depend on the rank count)")
    last = comm.rank == comm.size - 1  # the last rank owns every zoned block, no rigid row
    rigid = [] if last else [g for g in range(N_BLOCKS) if g % (comm.size - 1) == comm.rank]
    check(tmp_path, rigid, ZONED if last else [])


def test_gather_fallback(tmp_path):
    if MPI.COMM_WORLD.size > 2:
        pytest.skip("the 2-rank tier's (the gathered path does not depend on the rank count)")
    check(tmp_path, mine(range(N_BLOCKS)), mine(ZONED[::-1]), parallel=False)


def test_zoned_block_on_two_ranks_raises_everywhere(tmp_path):
    comm = MPI.COMM_WORLD
    base = comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)
    with pytest.raises(ValueError, match="two ranks"):
        OutputWriter(f"{base}/bad.h5", comm, **make_scene(),
                     zones=[(1, body(1, 0))] if comm.rank < 2 else [])
