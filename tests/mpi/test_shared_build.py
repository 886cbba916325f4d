"""The ranks share the build of a rock mass (each joint set's cutting and sliver joining's face
areas, pdem.parallel.mpi.shared_work) and every rank gets the very blocks one process builds:
names, parents, pieces' vertices and face tags, excavation times, fixed flags, bit for bit, on
2, 3 and 4 ranks. An error on one rank is raised on every rank (none is left waiting).

Run with ``mpiexec -n N python -m mpi4py -m pytest --with-mpi tests/mpi/test_shared_build.py``.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from mpi4py import MPI
from support import shared_dir

from pdem.cases.rock_mass import tunnel_scene
from pdem.config import ConfigError, parse_scene
from pdem.model.build import expand_blocks
from pdem.parallel.mpi import SHARE_CHUNK, shared_work

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(300, method="thread")]

# a region cut by three joint sets, its corner pieces joined as slivers (~660 blocks, ~100 of
# them joined from several pieces)
JOINTED = """
name: jointed
materials:
  granite: {density: 2600}
joints:
  default: {kn: 5.0e9, ks: 2.5e9, friction: 35}
blocks:
  - {name: rock, box: {min: [0, 0, 0], max: [40, 40, 30]}, material: granite, group: rock}
  - {name: base, box: {min: [-5, -5, -5], max: [45, 45, 0]}, material: granite, group: base,
     fixed: true}
cuts:
  - {name: J1, dip: 60, dip_direction: 120, origin: [20, 20, 15], spacing: 4, groups: [rock]}
  - {name: J2, dip: 50, dip_direction: 220, origin: [20, 20, 15], spacing: 4, groups: [rock]}
  - {name: B, dip: 5, dip_direction: 180, origin: [20, 20, 15], spacing: 4, groups: [rock]}
solve: {steps: 2}
"""


def build_digest(specs) -> str:
    h = hashlib.sha256()
    for s in specs:
        h.update(f"{s.name}|{s.parent}|{s.excavate_at}|{s.excavate_stage}|{len(s.pieces)}|"
                 f"{s.spec.fixed}|{s.group}".encode())
        for p in s.pieces:
            h.update(np.ascontiguousarray(p.vertices).tobytes())
            h.update(np.asarray(p.face_tag if p.face_tag is not None else []).tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("text", [JOINTED, tunnel_scene(0.1, 0.2)], ids=["jointed", "tunnel"])
def test_shared_build_is_the_one_process_build(text):
    comm = MPI.COMM_WORLD
    scene = parse_scene(text)
    shared = expand_blocks(scene, 10**6, None, comm)
    digests = comm.allgather(build_digest(shared))
    alone = build_digest(expand_blocks(scene, 10**6)) if comm.rank == 0 else None
    alone = comm.bcast(alone, root=0)
    joined = sum(len(s.pieces) > 1 for s in shared)
    assert len(set(digests)) == 1 and digests[0] == alone, (len(shared), joined)
    assert len(shared) > 40 and joined > 0


def hex_mesh(path, n: int, warp: int | None = None) -> None:
    """An n x n x n lattice of unit hexahedra; cell data ``pair`` joins cells two by two
    along x; ``warp``: that cell's first node is pushed out of its face's plane."""
    import meshio

    x = np.arange(n + 1, dtype=float)
    pts = np.stack(np.meshgrid(x, x, x, indexing="ij"), axis=-1).reshape(-1, 3)

    def node(i, j, k):
        return (i * (n + 1) + j) * (n + 1) + k

    cells = np.array([[node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                       node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1),
                       node(i, j + 1, k + 1)]
                      for i in range(n) for j in range(n) for k in range(n)])
    if warp is not None:
        pts = np.concatenate([pts, [pts[cells[warp, 0]] + [0.0, 0.0, 0.3]]])
        cells[warp, 0] = len(pts) - 1
    pair = np.array([(i // 2) * n * n + j * n + k for i in range(n) for j in range(n)
                     for k in range(n)], float)
    meshio.write(path, meshio.Mesh(pts, [("hexahedron", cells)], cell_data={"pair": [pair]}))


MESHED = """
name: meshed
materials:
  granite: {{density: 2600}}
joints:
  default: {{kn: 5.0e9, ks: 2.5e9, friction: 35}}
blocks:
  - {{name: rock, mesh: {{file: {path}, cell_data_group: pair}}, material: granite}}
solve: {{steps: 1}}
"""


def test_a_meshs_cells_are_shared_and_a_bad_cell_named_on_every_rank(tmp_path):
    """A volume mesh's cells are made into blocks in shares: the same blocks as one process
    (cells joined two by two); a warped cell in the last share is the same one-line scene
    error on every rank, naming that cell."""
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    if comm.rank == 0:
        hex_mesh(f"{base}/good.vtu", 6)
        hex_mesh(f"{base}/warped.vtu", 6, warp=200)
    comm.Barrier()
    scene = parse_scene(MESHED.format(path=f"{base}/good.vtu"))
    shared = expand_blocks(scene, 10**6, None, comm)
    digests = comm.allgather(build_digest(shared))
    alone = comm.bcast(build_digest(expand_blocks(scene, 10**6)) if comm.rank == 0 else None)
    assert len(set(digests)) == 1 and digests[0] == alone
    assert len(shared) == 108 and all(len(s.pieces) == 2 for s in shared)
    bad = parse_scene(MESHED.format(path=f"{base}/warped.vtu"))
    with pytest.raises(ConfigError) as err:
        expand_blocks(bad, 10**6, None, comm)
    assert "cell 200 (hexahedron)" in str(err.value)
    comm.Barrier()


def test_an_error_on_one_rank_is_raised_on_every_rank():
    """A scene error raised by the last rank's share reaches every rank as that error, with
    its messages; an exception that does not pickle reaches the others as a RuntimeError
    naming the rank; the results come back in item order."""
    comm = MPI.COMM_WORLD
    last = comm.size - 1
    assert shared_work(comm, np.ones(10), lambda lo, hi: list(range(lo, hi))) == list(range(10))

    def scene_error(lo, hi):
        if comm.rank == last:
            raise ConfigError([f"cuts[0]: rank {last} failed on items {lo}-{hi}"])
        return list(range(lo, hi))

    with pytest.raises(ConfigError) as err:
        shared_work(comm, np.ones(10), scene_error)
    assert err.value.messages[0].startswith(f"cuts[0]: rank {last} failed")

    class Unpicklable(Exception):
        def __reduce__(self):
            raise TypeError("no")

    def odd_error(lo, hi):
        if comm.rank == last:
            raise Unpicklable("a local failure")
        return list(range(lo, hi))

    expected = Unpicklable if comm.rank == last else RuntimeError
    with pytest.raises(expected, match="a local failure"):
        shared_work(comm, np.ones(10), odd_error)
    comm.Barrier()  # every rank got here: none was left waiting


def test_shares_larger_than_a_chunk_arrive_whole_and_a_short_share_is_refused():
    """Shares of several broadcast chunks (uneven weights: the ranks' shares differ in size and
    in their number of chunks) come back in item order on every rank; a share that returns
    fewer results than its items is an error on every rank, not a wait for what never comes."""
    comm = MPI.COMM_WORLD
    n = 3 * SHARE_CHUNK + 17
    weights = np.random.default_rng(2).random(n) ** 3
    got = shared_work(comm, weights, lambda lo, hi: [(i, i * i) for i in range(lo, hi)])
    assert got == [(i, i * i) for i in range(n)]

    def short(lo, hi):
        return list(range(lo, hi - 1 if comm.rank == 0 and hi > lo else hi))

    with pytest.raises(RuntimeError, match="results for items"):
        shared_work(comm, weights, short)
    comm.Barrier()  # every rank got here: none was left waiting
