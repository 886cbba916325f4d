"""A ``mesh`` block with ``zones: {}``: the user's tetrahedra are the zones as the mesh has them
(3DEC imports zoned meshes; docs/deformable.md, "Zoned mesh blocks"). Two columns of a
structured tetrahedral mesh (cell data ``body`` 1 and 2), one on the other, on gridpoint
rollers under a pressure on the top: the uniaxial answer ``p H / E`` at the top plus the joint's
closure ``p / kn``, ``sigma_zz = -p`` in every zone; the zones are the mesh's cells; what a
zoned mesh block cannot be is refused in one line naming the block."""

import itertools

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import ConfigError, parse_scene
from pdem.simulation import Simulation

E, NU, P, KN = 1.0e8, 0.25, 1.0e5, 1.0e10


def kuhn_tets(n: tuple[int, int, int], h: float, z0: float = 0.0):
    """Points and tets of a box of n cubes of side h from z0, each cube in the 6 tets along
    its main diagonal (Kuhn: conforming across the cubes)."""
    nx, ny, nz = n
    idx = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nx + 1, ny + 1, nz + 1)
    g = np.stack(np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1),
                             indexing="ij"), -1).reshape(-1, 3) * h + [0.0, 0.0, z0]
    tets = []
    for i, j, k in itertools.product(range(nx), range(ny), range(nz)):
        for perm in itertools.permutations(range(3)):
            c = np.array([i, j, k])
            t = [idx[tuple(c)]]
            for axis in perm:
                c = c.copy()
                c[axis] += 1
                t.append(idx[tuple(c)])
            tets.append(t)
    return g, np.array(tets)


def write_columns(path, shapes=((1, 0.0), (2, 1.0))):
    """Two 1 x 1 x 1 m columns of 0.25 m cubes, body 1 on body 2, as one mesh file."""
    points, cells, body = [], [], []
    for label, z0 in shapes:
        x, t = kuhn_tets((4, 4, 4), 0.25, z0)
        cells.append(t + sum(len(p) for p in points))
        points.append(x)
        body += [label] * len(t)
    meshio.write(str(path), meshio.Mesh(np.concatenate(points), [("tetra", np.concatenate(cells))],
                                        cell_data={"body": [np.array(body, np.int64)]}))
    return len(body)


SCENE = """
name: mesh-columns
gravity: [0, 0, 0]
materials:
  soft: {{density: 2000, young: {E}, poisson: {NU}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30}}}}
blocks:
  - {{name: col, mesh: {{file: {file}, cell_data_group: body}}, material: soft, zones: {zones}}}
boundary:
  velocity:
    - {{range: {{box: {{min: [-1, -1, -0.01], max: [2, 2, 0.01]}}}}, components: [z]}}
    - {{range: {{box: {{min: [-0.01, -1, -1], max: [0.01, 2, 3]}}}}, components: [x]}}
    - {{range: {{box: {{min: [-1, -0.01, -1], max: [2, 0.01, 3]}}}}, components: [y]}}
  stress:
    - {{range: {{box: {{min: [-1, -1, 1.99], max: [2, 2, 2.01]}}}}, pressure: {P}}}
solve: {{ratio: 1.0e-6, damping: local, mass_scaling: true}}
"""


def scene_text(file, zones="{}"):
    return SCENE.format(E=E, NU=NU, KN=KN, P=P, file=file, zones=zones)


def test_two_zoned_mesh_columns_settle_as_the_uniaxial_closed_form(tmp_path):
    n_cells = write_columns(tmp_path / "cols.vtu")
    sim = Simulation(parse_scene(scene_text(tmp_path / "cols.vtu")), MPI.COMM_SELF, output=False)
    g = sim.state.grids
    assert sim.state.glob.n == 2 and len(g.bodies) == 2
    # the zones are the mesh's cells, as it has them
    assert sum(len(b.tets) for b in g.bodies) == n_cells
    assert all(len(b.nodes) == 125 for b in g.bodies)
    summary = sim.run()
    assert summary["ratio"] <= 1e-6
    top = g.bodies[1] if g.bodies[1].nodes0[:, 2].max() > 1.5 else g.bodies[0]
    u = top.nodes - top.nodes0
    at_top = top.nodes0[:, 2] > 2.0 - 1e-9
    # each column shortens p H / E (H = 1 m each), the joint between them closes p / kn
    expected = -(P * 2.0 / E + P / KN)
    np.testing.assert_allclose(u[at_top, 2], expected, rtol=2e-3)
    for b in g.bodies:
        np.testing.assert_allclose(b.stress[:, 2], -P, rtol=2e-3)
    sim.close()


def test_what_a_zoned_mesh_block_cannot_be_is_refused_naming_it(tmp_path):
    with pytest.raises(ConfigError, match=r"zones\.size: a mesh block's zones are its "):
        parse_scene(scene_text("cols.vtu", zones="{size: 0.5}"))
    # a concave group: an L of two cubes' tets in one body
    x1, t1 = kuhn_tets((2, 1, 1), 0.5)
    x2, t2 = kuhn_tets((1, 1, 1), 0.5, z0=0.5)
    meshio.write(str(tmp_path / "l.vtu"), meshio.Mesh(
        np.concatenate([x1, x2]), [("tetra", np.concatenate([t1, t2 + len(x1)]))],
        cell_data={"body": [np.ones(len(t1) + len(t2), np.int64)]}))
    with pytest.raises(ConfigError, match=r"blocks\[0\] \('col\[1\]'\)\.zones: its 18 "
                                          r"tetrahedra make a concave body"):
        Simulation(parse_scene(scene_text(tmp_path / "l.vtu")), MPI.COMM_SELF, output=False)
    # a hexahedral cell
    x, _ = kuhn_tets((1, 1, 1), 1.0)
    meshio.write(str(tmp_path / "h.vtu"), meshio.Mesh(
        x[[0, 4, 6, 2, 1, 5, 7, 3]], [("hexahedron", np.array([[0, 1, 2, 3, 4, 5, 6, 7]]))],
        cell_data={"body": [np.ones(1, np.int64)]}))
    with pytest.raises(ConfigError, match=r"cell 0 of the block has 8 corners"):
        Simulation(parse_scene(scene_text(tmp_path / "h.vtu")), MPI.COMM_SELF, output=False)
