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


# set-up is vectorised over the blocks (issue 11); these pin it to the per-block definitions,
# bit for bit: the areas, principal frames and edge directions feed the timestep, the masses
# and every contact
BITWISE_SCENE = """
name: bitwise
materials: {rock: {density: 2650.0}}
joints: {default: {kn: 3.0e8, ks: 1.0e8, friction: 30.0}}
solve: {steps: 1}
blocks:
  - name: b
    array: {box: {min: [1000.3, 2000.7, 0.1], max: [1001.03, 2001.41, 0.77]},
            count: [5, 4, 3], spacing: [1.1, 0.9, 0.67]}
    material: rock
    angular_velocity: [0.0, 0.3, 0.1]
  - name: r
    random: {count: 12, region: {min: [0, 0, 5], max: [4, 4, 8]}, size: [0.45, 0.6],
             vertices: 10, seed: 3}
    material: rock
  - name: pr
    prism: {base: [[20.5, 0.1, 0], [21.3, 0.2, 0], [21.6, 0.8, 0], [21.0, 1.5, 0],
                   [20.4, 1.0, 0], [20.3, 0.5, 0]], extrude: [0.1, 0.05, 0.7]}
    material: rock
  - name: ell
    polyhedron:
      vertices: [[30,0,0],[32,0,0],[32,1,0],[31,1,0],[31,2,0],[30,2,0],
                 [30,0,1],[32,0,1],[32,1,1],[31,1,1],[31,2,1],[30,2,1]]
      faces: [[0,5,4,3,2,1],[6,7,8,9,10,11],[0,1,7,6],[1,2,8,7],[2,3,9,8],[3,4,10,9],
              [4,5,11,10],[5,0,6,11]]
    material: rock
"""


def _bits(a):
    return np.ascontiguousarray(a, np.float64).view(np.uint64)


def test_vectorised_setup_is_bitwise_the_per_block_definition():
    from pdem.geometry import box
    from pdem.model.build import unique_directions
    from pdem.model.shapes import _array
    from pdem.resolve import surface_areas

    scene = parse_scene(BITWISE_SCENE)
    specs = expand_blocks(scene)
    assert any(len(s.pieces) > 1 for s in specs)  # a joined block is among them
    # array members: one transformed() call each
    a = scene.blocks[0].array
    base = box(a.box.min, a.box.max)
    for k, member in _array(a):
        idx = np.array([k % 5, k // 5 % 4, k // 20], float)
        ref = base.transformed(np.eye(3), idx * np.array(a.spacing))
        for f in ("vertices", "normals", "offsets", "centroid", "inertia"):
            assert np.array_equal(_bits(getattr(member, f)), _bits(getattr(ref, f))), (k, f)
    # face areas (batched Newell) and surfaces (row sums)
    surf = surface_areas(specs)
    for r, s in enumerate(specs):
        per_face = [p.face_area(f) for p in s.pieces for f in range(p.n_faces)]
        assert np.array_equal(_bits(s.face_areas), _bits(per_face))
        assert _bits(surf[r]) == _bits(np.array(per_face).sum())
    # the store: principal frames and edge directions as one block at a time
    glob, _ = block_store(scene, specs)
    for r, s in enumerate(specs):
        bodies, c, R, moments = s.principal_frame()
        rho = scene.materials[s.material].density
        assert np.array_equal(_bits(glob.x[r]), _bits(c))
        assert np.array_equal(_bits(glob.q[r]), _bits(quat_from_matrix(R)))
        assert np.array_equal(_bits(glob.inertia[r]), _bits(rho * moments))
        for j, body in enumerate(bodies):
            k = glob.piece_start[r] + j
            v = glob.verts_local[glob.vert_start[k]:glob.vert_start[k + 1]]
            assert np.array_equal(_bits(v), _bits(body.vertices))
            nrm = glob.normals_local[glob.face_start[k]:glob.face_start[k + 1]]
            assert np.array_equal(_bits(nrm), _bits(body.normals))
            d = glob.edirs_local[glob.edir_start[k]:glob.edir_start[k + 1]]
            ref = unique_directions(body.vertices[body.edges[:, 1]]
                                    - body.vertices[body.edges[:, 0]])
            assert np.array_equal(_bits(d), _bits(ref))


SHARE_SCENE = """
name: shares
materials: {rock: {density: 2500}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30}}
blocks:
  - {name: floor, box: {min: [-1, -1, -1], max: [12, 12, 0]}, material: rock, fixed: true}
  - {name: cubes, array: {box: {min: [0, 0, 0], max: [0.9, 0.8, 0.7]}, count: [5, 4, 3],
     spacing: [1.0, 1.0, 1.0]}, material: rock}
  - {name: tilted, polyhedron: {vertices: [[0, 0, 5], [1, 0, 5], [0, 1, 5], [0.2, 0.3, 6]]},
     material: rock}
  - {name: stones, random: {region: {min: [0, 0, 7], max: [6, 6, 9]}, count: 9,
     size: [0.5, 0.9], seed: 4}, material: rock}
solve: {steps: 1}
"""


@pytest.mark.parametrize("share", [(0, 71), (0, 30), (30, 71), (1, 2), (61, 66), (64, 68),
                                   (5, 5), (70, 71)])
def test_share_builds_only_its_members_bitwise(share):
    """expand_blocks with a build share makes the family members outside it without pieces
    (an array's are never built); the share's store and geometric columns are bitwise the
    whole build's rows (gids, piece numbering, geometry, mass properties)."""
    from pdem.model.blocks import pack
    from pdem.model.build import geometry_columns

    scene = parse_scene(SHARE_SCENE)
    whole = expand_blocks(scene)
    assert len(whole) == 71
    lo, hi = share
    lazy = expand_blocks(scene, share=lambda n: (lo, hi))
    assert [(s.name, s.parent, s.entry) for s in lazy] == \
        [(s.name, s.parent, s.entry) for s in whole]
    built = [g for g, s in enumerate(lazy) if s.pieces is not None]
    singles = {0, 61}  # the entries that are not families are always built
    assert set(built) == set(range(lo, hi)) | singles
    assert all(s.n_pieces == 1 for s in lazy)
    ref, _ = block_store(scene, whole)
    mine, _ = block_store(scene, lazy, lo, hi)
    assert np.array_equal(mine.gid, np.arange(lo, hi))
    a, b = pack(mine, np.arange(hi - lo)), pack(ref, np.arange(lo, hi))
    for k in a:
        assert np.array_equal(_bits(a[k]), _bits(b[k])), k
    cols = geometry_columns(lazy[lo:hi])
    for r, s in enumerate(whole[lo:hi]):
        assert _bits(cols["volume"][r]) == _bits(s.volume)
        assert _bits(cols["surface"][r]) == _bits(float(s.face_areas.sum()))
        assert _bits(cols["max_face"][r]) == _bits(float(s.face_areas.max()))


@pytest.mark.parametrize("share", [(0, 71), (30, 71), (1, 2), (5, 5), (70, 71)])
def test_unbuilt_members_are_runs_and_read_as_specs(share):
    """A share's unbuilt family members are runs (pdem.model.speclist), not an object each:
    the spec table made from them is the whole build's, column by column."""
    from pdem.model.build import SpecTable, geometry_columns
    from pdem.model.speclist import SpecList, UnbuiltRun

    scene = parse_scene(SHARE_SCENE)
    whole = expand_blocks(scene)
    lazy = expand_blocks(scene, share=lambda n: share)
    assert isinstance(lazy, SpecList) and len(lazy) == len(whole)
    runs = [p for _, p in lazy.parts() if isinstance(p, UnbuiltRun)]
    assert sum(r.count for r in runs) == sum(s.pieces is None for s in lazy)
    assert len(runs) <= 4  # at most before and after the share, in each family
    assert [lazy[g].name for g in range(len(lazy))] == [s.name for s in whole]
    assert [s.name for s in lazy[3:40]] == [s.name for s in whole[3:40]]
    columns = geometry_columns(whole)
    a, b = SpecTable(lazy, scene.blocks, columns), SpecTable(whole, scene.blocks, columns)
    assert list(a.names) == list(b.names) and a.parents == b.parents and a.labels == b.labels
    for k in ("parent", "group", "material", "entry", "volume"):
        assert np.array_equal(np.asarray(getattr(a, k)), np.asarray(getattr(b, k))), k
