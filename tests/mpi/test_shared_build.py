"""The ranks share the build of a rock mass (its cuts, sliver joining, excavations and a mesh's
cells, each rank on its slice: pdem.model.spread) and, gathered, every rank gets the very
blocks one process builds: names, parents, pieces' vertices and face tags, excavation times,
fixed flags, bit for bit, on 2, 3 and 4 ranks. A bad cell in one rank's share is the same
scene error on every rank (none is left waiting; tests/mpi/test_spread_build.py for the
error path itself).

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


def test_one_rank_reads_the_mesh_file_and_a_bad_file_is_refused_on_every_rank(tmp_path,
                                                                              monkeypatch):
    """Under MPI one rank reads a scene's mesh file (pdem.mpi.on_root), not every
    rank at once from a cluster's shared file system; the blocks are those of one process. A
    file that is not a mesh is the same one-line scene error on every rank."""
    from pdem.geometry import mesh_import

    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    if comm.rank == 0:
        hex_mesh(f"{base}/good.vtu", 4)
        with open(f"{base}/junk.vtu", "w") as f:
            f.write("not a mesh\n")
    comm.Barrier()
    reads = []
    real = mesh_import._read
    monkeypatch.setattr(mesh_import, "_read", lambda path: reads.append(path) or real(path))
    scene = parse_scene(MESHED.format(path=f"{base}/good.vtu"))
    shared = expand_blocks(scene, 10**6, None, comm)
    assert comm.allgather(len(reads)) == [1] + [0] * (comm.size - 1)
    digests = comm.allgather(build_digest(shared))
    alone = comm.bcast(build_digest(expand_blocks(scene, 10**6)) if comm.rank == 0 else None)
    assert len(set(digests)) == 1 and digests[0] == alone
    junk = parse_scene(MESHED.format(path=f"{base}/junk.vtu"))
    with pytest.raises(ConfigError) as err:
        expand_blocks(junk, 10**6, None, comm)
    text = str(err.value)
    assert "cannot read mesh" in text and "junk.vtu" in text
    assert len(set(comm.allgather(text))) == 1
    comm.Barrier()
