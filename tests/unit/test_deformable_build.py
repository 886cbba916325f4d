"""Building zoned blocks: the block row's one piece is the surface grid, identity pose, mass
from the zones; the grid store maps rows and vertices to gridpoints; other rows unchanged."""

import numpy as np
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.model.build import block_store, expand_blocks
from pdem.state import ModelState

SCENE = """
name: t
materials:
  rock: {density: 2000}
  weak: {density: 2400, young: 5.0e9, poisson: 0.3, model: mohr_coulomb, cohesion: 2.0e6,
         friction: 35, tension: 0.5e6, dilation: 5}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
blocks:
  - {name: floor, box: {min: [-1, -1, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - name: pillar
    prism: {base: [[0, 0, 0], [1, 0, 0], [0.5, 0.8, 0]], extrude: [0.2, 0.1, 1.5]}
    material: weak
    zones: {size: 0.4}
  - {name: roof, box: {min: [0, 0, 1.5], max: [1, 1, 2]}, material: rock}
solve: {steps: 10}
"""


def test_zoned_row_is_its_surface_grid():
    scene = parse_scene(SCENE)
    specs = expand_blocks(scene)
    mesh, surf = specs[1].zoning
    store, _ = block_store(scene, specs)
    k = store.piece_start[1]
    v0, v1 = store.vert_start[k], store.vert_start[k + 1]
    f0, f1 = store.face_start[k], store.face_start[k + 1]
    assert v1 - v0 == len(surf) == mesh.on_surface.sum()
    assert f1 - f0 == len(mesh.surface)
    assert np.array_equal(store.q[1], [1.0, 0.0, 0.0, 0.0])
    # identity frame: local vertices are the gridpoints less the centroid
    assert np.allclose(store.verts_local[v0:v1] + store.x[1], mesh.nodes[surf], atol=1e-14)
    # the centroid and mass of the zones (lumped gridpoint masses: exact for tets)
    from pdem.deformable.mesh import signed_volumes

    vol = signed_volumes(mesh.nodes, mesh.tets)
    centre = (vol[:, None] * mesh.nodes[mesh.tets].mean(axis=1)).sum(axis=0) / vol.sum()
    assert np.allclose(store.x[1], centre, atol=1e-13)
    assert abs(store.mass[1] - 2400 * vol.sum()) < 1e-9 * store.mass[1]
    # each triangle's plane: the outward normal of the prism face it lies on
    tri = store.face_verts[store.fvert_start[f0]:store.fvert_start[f1]].reshape(-1, 3)
    p = store.verts_local[tri]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    assert np.allclose(n, store.normals_local[f0:f1], atol=1e-12)
    assert np.allclose(np.einsum("ij,ij->i", n, p[:, 0]), store.offsets_local[f0:f1], atol=1e-12)
    # its edge directions: one per set of parallel prism edges (3 of the base, 1 lateral),
    # each along the piece's edge of the same rank (the first edges), on a prism edge
    d = store.edirs_local[store.edir_start[k]:store.edir_start[k + 1]]
    base = np.array([[1, 0, 0], [-0.5, 0.8, 0], [-0.5, -0.8, 0], [0.2, 0.1, 1.5]])
    base /= np.linalg.norm(base, axis=1)[:, None]
    assert len(d) == 4
    assert np.allclose(np.sort(np.abs(d @ base.T).max(axis=1)), 1.0, atol=1e-12)
    e = store.edges[store.edge_start[k]:store.edge_start[k] + 4]
    chord = store.verts_local[e[:, 1]] - store.verts_local[e[:, 0]]
    assert np.allclose(chord / np.linalg.norm(chord, axis=1)[:, None], d, atol=1e-14)


def test_rigid_rows_as_without_zones():
    zoned = parse_scene(SCENE)
    plain = parse_scene(SCENE.replace("    zones: {size: 0.4}\n", ""))
    a, _ = block_store(zoned, expand_blocks(zoned))
    b, _ = block_store(plain, expand_blocks(plain))
    for r in (0, 2):
        for f in ("x", "q", "mass", "inertia", "radius"):
            assert np.array_equal(getattr(a, f)[r], getattr(b, f)[r]), f
        ka, kb = a.piece_start[r], b.piece_start[r]
        assert np.array_equal(a.verts_local[a.vert_start[ka]:a.vert_start[ka + 1]],
                              b.verts_local[b.vert_start[kb]:b.vert_start[kb + 1]])
        assert np.array_equal(a.edirs_local[a.edir_start[ka]:a.edir_start[ka + 1]],
                              b.edirs_local[b.edir_start[kb]:b.edir_start[kb + 1]])


def test_state_grids_and_timestep():
    state = ModelState.create(parse_scene(SCENE), MPI.COMM_SELF)
    g = state.grids
    assert len(g) == 1 and g.gids == [1]
    body = g.bodies[0]
    assert type(body.model).__name__ == "MohrCoulombTable"
    assert body.nodes.base is g.nodes  # a view of the flat store
    assert state.dt <= g.dt and 0.0 < g.dt < np.inf
    # a plain scene has no grids
    plain = ModelState.create(parse_scene(SCENE.replace("    zones: {size: 0.4}\n", "")),
                              MPI.COMM_SELF)
    assert plain.grids is None
