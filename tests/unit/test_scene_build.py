"""Scene -> blocks: geometry errors and initial overlaps are named by block, not traced back."""

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import ConfigError, parse_scene
from pdem.model.build import block_store, expand_blocks, quat_from_matrix
from pdem.simulation import Simulation

HEAD = """
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
solve: {steps: 1}
blocks:
  - {name: base, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
"""


def build(extra):
    return Simulation(parse_scene(HEAD + extra), MPI.COMM_SELF, output=False)


def test_non_convex_polyhedron_rejected_with_block_name():
    # an L-shaped outline: the re-entrant corner lies on the hull boundary
    l_shape = "[[0,0,1],[2,0,1],[2,1,1],[1,1,1],[1,2,1],[0,2,1]," \
              "[0,0,2],[2,0,2],[2,1,2],[1,1,2],[1,2,2],[0,2,2]]"
    with pytest.raises(ConfigError) as info:
        build(f"  - {{name: ell, polyhedron: {{vertices: {l_shape}}}, material: rock}}\n")
    (msg,) = info.value.messages
    assert msg.startswith("blocks[1] ('ell').polyhedron:") and "not convex" in msg


def test_zero_volume_polyhedron_rejected():
    flat = "[[0,0,1],[1,0,1],[1,1,1],[0,1,1]]"
    with pytest.raises(ConfigError, match=r"blocks\[1\] \('flat'\)\.polyhedron"):
        build(f"  - {{name: flat, polyhedron: {{vertices: {flat}}}, material: rock}}\n")


def test_initial_overlap_names_both_blocks():
    with pytest.raises(ConfigError, match="'base' and 'sunk' overlap by 0.2"):
        build("  - {name: sunk, box: {min: [0, 0, -0.2], max: [1, 1, 0.8]}, material: rock}\n")


def test_touching_blocks_accepted_and_in_contact():
    s = build("  - {name: cube, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}\n")
    assert s.contacts.n == 1
    assert s.contacts.sc_area.sum() == pytest.approx(1.0)


def test_mass_properties_and_body_frame():
    scene = parse_scene(HEAD + "  - {name: slab, box: {min: [0, 0, 0], max: [3, 2, 1]}, "
                        "material: rock}\n")
    specs = expand_blocks(scene)
    store, _ = block_store(scene, specs)
    m = 2000.0 * 6.0
    assert store.mass[1] == pytest.approx(m)
    np.testing.assert_allclose(store.x[1], [1.5, 1.0, 0.5])
    # principal moments ascending: about x (2^2+1^2), y (3^2+1^2), z (3^2+2^2)
    np.testing.assert_allclose(store.inertia[1], m / 12 * np.array([5.0, 10.0, 13.0]))
    # body vertices rotated by q reproduce the world corners
    w, x, y, z = store.q[1]
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    local = store.verts_local[store.vert_start[1]:store.vert_start[2]]
    world = local @ R.T + store.x[1]
    assert np.allclose(np.sort(world, axis=0), np.sort(specs[1].shape.vertices, axis=0))


def test_quaternion_from_matrix_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        Q *= np.sign(np.linalg.det(Q))
        q = quat_from_matrix(Q)
        w, x, y, z = q
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        np.testing.assert_allclose(R, Q, atol=1e-12)


def test_generators_expand_in_order():
    scene = parse_scene(HEAD + """  - name: stack
    array: {box: {min: [0, 0, 0], max: [1, 1, 1]}, count: [2, 1, 3], spacing: [1, 1, 1]}
    material: rock
  - name: rocks
    random: {count: 5, region: {min: [5, 5, 0], max: [8, 8, 3]}, size: [0.5, 0.8], seed: 3}
    material: rock
""")
    specs = expand_blocks(scene)
    assert [s.name for s in specs[:3]] == ["base", "stack[0]", "stack[1]"]
    assert len(specs) == 1 + 6 + 5
    again = expand_blocks(scene)
    assert all(np.array_equal(a.shape.vertices, b.shape.vertices) for a, b in zip(specs, again, strict=True))


def test_contact_types_from_touching_vertices():
    """Table 1: a cube face-down on the floor is face-face; a tetrahedron standing on its
    apex is vertex-face (numbers of vertices touching the common plane)."""
    from pdem.contact.common_plane import FACE_FACE, VERTEX_FACE

    s = build("  - {name: cube, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}\n")
    assert s.contacts.ctype.tolist() == [FACE_FACE]
    s = build("  - {name: tip, polyhedron: {vertices: [[0, 0, 0.0005], [1, 0, 1], [-1, 0.5, 1], "
              "[0, -1, 1]]}, material: rock}\n")
    assert s.contacts.ctype.tolist() == [VERTEX_FACE]
