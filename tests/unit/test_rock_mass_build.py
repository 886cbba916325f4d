"""Building a rock mass from the scene (pdem.model.rockmass, mesh_blocks): cuts, joins,
excavations, mesh import, names, face tags, and the refusals, each naming the entry and line.

Closed forms: volumes of boxes and of the polygonal cylinder, block counts of orthogonal sets.
"""

from __future__ import annotations

import math

import meshio
import numpy as np
import pytest

from pdem.config import ConfigError, parse_scene
from pdem.geometry.cutting import split_by_plane
from pdem.model.build import block_store, expand_blocks

HEAD = """
materials: {rock: {density: 2500}, soft: {density: 2000}}
joints:
  default: {kn: 1.0e9, ks: 1.0e9, friction: 30}
  J1joint: {kn: 1.0e8, ks: 1.0e8, friction: 20}
solve: {steps: 1}
"""


def build(body: str, source="scene.yaml"):
    scene = parse_scene(HEAD + body, source)
    return scene, expand_blocks(scene)


def _overlap(p, q) -> float:
    """Volume of the intersection of two convex pieces (0 when they only touch)."""
    inner = q
    for n, d in zip(p.normals, p.offsets, strict=True):
        inner, _ = split_by_plane(inner, n, d, 0.0)
        if inner is None:
            return 0.0
    return float(inner.volume)


def test_three_orthogonal_sets_give_the_lattice_and_keep_the_volume():
    scene, specs = build("""
blocks:
  - {name: rock, box: {min: [0, 0, 0], max: [4, 3, 2]}, material: rock}
cuts:
  - {name: EW, dip: 90, dip_direction: 90, origin: [0, 0, 0], spacing: 1.0}
  - {name: NS, dip: 90, dip_direction: 0, origin: [0, 0, 0], spacing: 1.0}
  - {name: bed, dip: 0, dip_direction: 0, origin: [0, 0, 0], spacing: 1.0}
""")
    assert len(specs) == 4 * 3 * 2  # planes x = 1, 2, 3; y = 1, 2; z = 1
    assert math.isclose(sum(s.volume for s in specs), 24.0, rel_tol=1e-13)
    assert [s.name for s in specs[:3]] == ["rock[0]", "rock[1]", "rock[2]"]
    assert {s.parent for s in specs} == {"rock"}
    assert all(math.isclose(s.volume, 1.0, rel_tol=1e-12) for s in specs)
    glob, _ = block_store(scene, specs)
    # each cut plane leaves a face on both sides of every cell it separates
    tags = np.bincount(glob.face_tag[glob.face_tag >= 0], minlength=3)
    assert tags.tolist() == [3 * (3 * 2) * 2, 2 * (4 * 2) * 2, 1 * (4 * 3) * 2]


def test_inclined_sets_tile_the_box():
    _, specs = build("""
blocks:
  - {name: rock, box: {min: [0, 0, 0], max: [3, 2, 2]}, material: rock}
cuts:
  - {name: A, dip: 35, dip_direction: 70, origin: [1, 1, 1], spacing: 0.7}
  - {name: B, dip: 80, dip_direction: 200, origin: [1, 1, 1], spacing: 0.9}
""")
    assert len(specs) > 10
    assert math.isclose(sum(s.volume for s in specs), 12.0, rel_tol=1e-12)
    polys = [s.pieces[0] for s in specs]
    worst = max(_overlap(polys[i], polys[j]) for i in range(len(polys))
                for j in range(i + 1, len(polys)))
    assert worst < 1e-12


def test_range_groups_and_the_set_joint_reach_the_contacts():
    scene, specs = build("""
blocks:
  - {name: base, box: {min: [-1, -1, -1], max: [3, 3, 0]}, material: rock, fixed: true,
     group: floor}
  - {name: rock, box: {min: [0, 0, 0], max: [2, 2, 2]}, material: rock}
cuts:
  - {name: J1, dip: 90, dip_direction: 90, origin: [1, 0, 0], joint: J1joint,
     groups: [default]}
  - {name: J2, dip: 0, dip_direction: 0, origin: [0, 0, 1],
     range: {box: {min: [0, 0, 1], max: [2, 2, 2]}}}
""")
    # J1 (one plane) cuts the rock only (group), J2 only the upper piece... whose centroid is
    # at z = 1: both halves have it, so both are cut
    assert [s.name for s in specs] == ["base", "rock[0]", "rock[1]", "rock[2]", "rock[3]"]
    assert specs[0].pieces[0].face_tag is None or (specs[0].pieces[0].face_tag < 0).all()
    glob, groups = block_store(scene, specs)
    assert groups == ["default", "floor"]
    from pdem.contact.laws import joint_table

    table = joint_table(scene, groups)
    assert table.cut_joint.tolist() == [1, -1] and table.by_set


def test_join_makes_one_body_with_the_combined_inertia():
    scene, specs = build("""
blocks:
  - {name: a, box: {min: [0, 0, 0], max: [3, 1, 1]}, material: rock}
  - {name: b, box: {min: [0, 0, 1], max: [1, 1, 3]}, material: rock}
  - {name: c, box: {min: [5, 0, 0], max: [6, 1, 1]}, material: rock}
join: [[a, b]]
""")
    assert [s.name for s in specs] == ["a", "c"]
    L = specs[0]
    assert len(L.pieces) == 2 and math.isclose(L.volume, 5.0, rel_tol=1e-14)
    glob, _ = block_store(scene, specs)
    # closed form: two boxes, parallel-axis theorem about the common centroid
    boxes = [((0, 0, 0), (3, 1, 1)), ((0, 0, 1), (1, 1, 3))]
    rho = 2500.0
    m = [rho * np.prod(np.subtract(hi, lo)) for lo, hi in boxes]
    c = [0.5 * np.add(lo, hi) for lo, hi in boxes]
    C = sum(mi * ci for mi, ci in zip(m, c, strict=True)) / sum(m)
    inertia = np.zeros((3, 3))
    for (lo, hi), mi, ci in zip(boxes, m, c, strict=True):
        a2 = np.subtract(hi, lo) ** 2
        inertia += mi / 12.0 * np.diag([a2[1] + a2[2], a2[0] + a2[2], a2[0] + a2[1]])
        d = ci - C
        inertia += mi * (d @ d * np.eye(3) - np.outer(d, d))
    assert np.allclose(glob.x[0], C, atol=1e-14)
    assert math.isclose(glob.mass[0], sum(m), rel_tol=1e-14)
    assert np.allclose(np.sort(glob.inertia[0]), np.linalg.eigvalsh(inertia), rtol=1e-12)
    assert glob.piece_start.tolist() == [0, 2, 3]
    # body frame: piece centres are the boxes' centroids relative to C, rotated
    from pdem.dynamics.rotation import quat_to_matrix

    R = quat_to_matrix(glob.q[0])
    world = glob.x[0] + glob.piece_center[:2] @ R.T
    assert np.allclose(world, c, atol=1e-12)


def test_excavating_a_cylinder_removes_its_volume_and_joins_what_is_left():
    r, sides, length = 1.5, 12, 4.0
    _, specs = build(f"""
blocks:
  - {{name: rock, box: {{min: [0, 0, 0], max: [6, 4, 6]}}, material: rock}}
cuts:
  - {{name: V, dip: 90, dip_direction: 90, origin: [0, 0, 0], spacing: 2.0}}
excavate:
  - {{cylinder: {{start: [3, 0, 3], end: [3, 4, 3], radius: {r}, sides: {sides}}}}}
""")
    prism = r * r * sides * math.sin(2 * math.pi / sides) / 2 * length
    assert math.isclose(sum(s.volume for s in specs), 144.0 - prism, rel_tol=1e-12)
    # the middle slab (x in [2, 4]) is split into the part above and the part below the
    # opening: two blocks, each joined from the pieces around the polygon
    middle = [s for s in specs if s.name.startswith("rock[1]")]
    assert len(middle) == 2 and all(len(s.pieces) > 1 for s in middle)
    deferred = build(f"""
blocks:
  - {{name: rock, box: {{min: [0, 0, 0], max: [6, 4, 6]}}, material: rock}}
excavate:
  - {{cylinder: {{start: [3, 0, 3], end: [3, 4, 3], radius: {r}, sides: {sides}}}, time: 0.5}}
""")[1]
    inside = [s for s in deferred if s.excavate_at == 0.5]
    assert len(inside) == 1 and math.isclose(inside[0].volume, prism, rel_tol=1e-12)
    assert math.isclose(sum(s.volume for s in deferred), 144.0, rel_tol=1e-12)


def test_mesh_cells_become_blocks_joined_by_cell_data(tmp_path):
    xs = np.array([0.0, 1.0, 2.5])
    pts = np.array([[x, y, z] for z in (0.0, 1.0) for y in (0.0, 1.0) for x in xs])

    def pid(i, j, k):
        return k * 6 + j * 3 + i

    cells = [[pid(i, 0, 0), pid(i + 1, 0, 0), pid(i + 1, 1, 0), pid(i, 1, 0),
              pid(i, 0, 1), pid(i + 1, 0, 1), pid(i + 1, 1, 1), pid(i, 1, 1)] for i in range(2)]
    mesh = tmp_path / "two.vtu"
    meshio.write(mesh, meshio.Mesh(pts, [("hexahedron", np.array(cells))],
                                   cell_data={"block_id": [np.array([7, 7])],
                                              "mat": [np.array([1, 1])]}))
    scene = parse_scene(HEAD.replace("soft:", '"1":') + """
blocks:
  - {name: m, mesh: {file: two.vtu, cell_data_group: block_id, material_data: mat},
     material: rock}
""", "scene.yaml", tmp_path)
    specs = expand_blocks(scene)
    assert [s.name for s in specs] == ["m[7]"] and len(specs[0].pieces) == 2
    assert specs[0].material == "1" and math.isclose(specs[0].volume, 2.5, rel_tol=1e-13)


@pytest.mark.parametrize("body, words", [
    ("""
blocks: [{name: rock, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}]
cuts: [{name: far, dip: 0, dip_direction: 0, origin: [0, 0, 5]}]
""", ["cuts[0] (line 9) ('far')", "misses every block"]),
    ("""
blocks: [{name: rock, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}]
cuts: [{name: none, dip: 0, dip_direction: 0, origin: [0, 0, 0.5], groups: [default],
        range: {box: {min: [5, 5, 5], max: [6, 6, 6]}}}]
""", ["cuts[0]", "selects no block"]),
    ("""
blocks: [{name: rock, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}]
cuts: [{name: J, dip: 0, dip_direction: 0, origin: [0, 0, 0.5], spacing: 0.0}]
""", ["cuts[0].spacing", "greater than 0"]),
    ("""
blocks: [{name: rock, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}]
cuts: [{name: J, dip: 0, dip_direction: 0, origin: [0, 0, 0.5], joint: nosuch}]
""", ["cuts[0].joint", "unknown joint 'nosuch'"]),
    ("""
blocks:
  - {name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}
  - {name: b, box: {min: [2, 0, 0], max: [3, 1, 1]}, material: rock}
join: [[a, b]]
""", ["join[0] (line 11)", "do not touch"]),
    ("""
blocks:
  - {name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}
join: [[a, zz]]
""", ["join[0]", "unknown block 'zz'"]),
    ("""
blocks: [{name: rock, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}]
excavate: [{box: {min: [5, 5, 5], max: [6, 6, 6]}}]
""", ["excavate[0]", "meets no block"]),
])
def test_bad_rock_mass_input_is_refused_naming_the_entry(body, words):
    with pytest.raises(ConfigError) as err:
        build(body)
    text = str(err.value)
    for w in words:
        assert w in text, text
    assert "Traceback" not in text


def test_a_set_making_too_many_blocks_is_refused_before_it_finishes():
    scene = parse_scene(HEAD + """
blocks: [{name: rock, box: {min: [0, 0, 0], max: [10, 10, 10]}, material: rock}]
cuts:
  - {name: fine, dip: 0, dip_direction: 0, origin: [0, 0, 0], spacing: 0.01}
""")
    with pytest.raises(ConfigError, match=r"cuts\[0\] .*would make up to 1000 blocks, more "
                       r"than 100"):
        expand_blocks(scene, max_blocks=100)


def test_a_non_convex_mesh_cell_is_refused_naming_the_cell(tmp_path):
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                    [0, 0, 1], [1, 0, 1], [0.3, 0.3, 0.2], [0, 1, 1]], float)
    meshio.write(tmp_path / "bad.vtu", meshio.Mesh(pts, [("hexahedron", np.array([range(8)]))]))
    scene = parse_scene(HEAD + """
blocks: [{name: m, mesh: {file: bad.vtu}, material: rock}]
""", "scene.yaml", tmp_path)
    with pytest.raises(ConfigError, match=r"blocks\[0\].mesh.*cell 0 \(hexahedron\)"):
        expand_blocks(scene)


def test_a_join_with_a_fixed_member_is_fixed_and_moving_members_must_agree():
    scene, specs = build("""
blocks:
  - {name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}
  - {name: wall, box: {min: [1, 0, 0], max: [2, 1, 1]}, material: rock, fixed: true}
join: [[a, wall]]
""")
    assert len(specs) == 1 and specs[0].spec.fixed
    glob, _ = block_store(scene, specs)
    assert glob.fixed.tolist() == [1]
    with pytest.raises(ConfigError, match=r"join\[0\].*differ in velocity"):
        build("""
blocks:
  - {name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock, velocity: [0, 1, 0]}
  - {name: b, box: {min: [1, 0, 0], max: [2, 1, 1]}, material: rock, velocity: [1, 0, 0]}
join: [[a, b]]
""")
    # the first member's motion is the joined block's; the others may leave theirs unset
    _, (ab,) = build("""
blocks:
  - {name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock, velocity: [0, 1, 0]}
  - {name: b, box: {min: [1, 0, 0], max: [2, 1, 1]}, material: rock}
join: [[a, b]]
""")
    assert ab.spec.velocity == (0.0, 1.0, 0.0)


def _extruded(profile, depth):
    """Vertices and outward faces of a planar xz polygon (counter-clockwise seen from -y)
    extruded along +y by ``depth``."""
    n = len(profile)
    v = [(x, 0.0, z) for x, z in profile] + [(x, depth, z) for x, z in profile]
    faces = [list(range(n)), [n + i for i in range(n)][::-1]]
    faces += [[(i + 1) % n, i, n + i, n + (i + 1) % n] for i in range(n)]
    return v, faces


@pytest.mark.parametrize("flip", [False, True])
def test_a_concave_polyhedron_given_by_faces_becomes_one_joined_block(flip):
    # a U: 5 x 1 base with two 1 x 2 posts, 0.5 deep; volume (5 + 2 + 2) * 0.5
    v, faces = _extruded([(0, 0), (5, 0), (5, 3), (4, 3), (4, 1), (1, 1), (1, 3), (0, 3)], 0.5)
    if flip:
        faces = [f[::-1] for f in faces]
    scene, specs = build(f"""
blocks:
  - {{name: u, polyhedron: {{vertices: {v}, faces: {faces}}}, material: rock}}
""".replace("(", "[").replace(")", "]"))
    (u,) = specs
    assert len(u.pieces) >= 3 and math.isclose(u.volume, 4.5, rel_tol=1e-12)
    assert np.allclose(u.centroid, [2.5, 0.25, (5 * 0.5 + 2 * 2 * 2) / 9], atol=1e-12)
    polys = u.pieces
    assert max(_overlap(polys[i], polys[j]) for i in range(len(polys))
               for j in range(i + 1, len(polys))) < 1e-12


def test_a_polyhedron_surface_with_a_hole_or_a_wrong_face_is_refused():
    v, faces = _extruded([(0, 0), (2, 0), (2, 2), (0, 2)], 1.0)
    with pytest.raises(ConfigError, match=r"blocks\[0\].*surface is not closed"):
        build(f"""
blocks: [{{name: b, polyhedron: {{vertices: {v}, faces: {faces[:-1]}}}, material: rock}}]
""".replace("(", "[").replace(")", "]"))
    faces[2] = faces[2][::-1]
    with pytest.raises(ConfigError, match=r"blocks\[0\].*counter-clockwise"):
        build(f"""
blocks: [{{name: b, polyhedron: {{vertices: {v}, faces: {faces}}}, material: rock}}]
""".replace("(", "[").replace(")", "]"))


def test_pdem_check_reports_what_the_cuts_made(tmp_path, capfd):
    from pdem import cli

    scene = tmp_path / "cut.yaml"
    scene.write_text(HEAD + """
blocks:
  - {name: floor, box: {min: [-1, -1, -1], max: [3, 3, 0]}, material: rock, fixed: true}
  - {name: rock, box: {min: [0, 0, 0], max: [2, 2, 2]}, material: rock}
cuts:
  - {name: J1, dip: 90, dip_direction: 90, origin: [1, 0, 0], joint: J1joint,
     groups: [default], range: {box: {min: [0, 0, 0], max: [2, 2, 2]}}}
excavate:
  - {box: {min: [1.5, 1.5, 1.5], max: [3, 3, 3]}, time: 0.5}
""")
    assert cli.main(["check", str(scene)]) == 0
    err = capfd.readouterr().out  # rank 0 logs to stdout
    assert "blocks: 4 from 2 scene entries" in err  # floor, two halves, the corner to dig
    assert "cut 'J1': 1 joint faces" in err and "joint J1joint" in err
    assert "excavation at t = 0.5 s: 1 blocks, 0.125 m3" in err
    assert "smallest / median" in err


def _row_of_hexes(tmp_path, n: int, gap_after: int | None = None, **cell_data):
    """n unit hexahedra in a row along x (a gap of 1 m after cell ``gap_after``), as
    ``row.vtu`` with the given cell data (one array per name, one value a cell)."""
    xs = [float(i + (1 if gap_after is not None and i > gap_after else 0)) for i in range(n)]
    pts, cells = [], []
    for x in xs:
        base = len(pts)
        pts += [[x + a, b, c] for c in (0.0, 1.0) for b, a in ((0, 0), (0, 1), (1, 1), (1, 0))]
        cells.append([base + k for k in range(8)])
    meshio.write(tmp_path / "row.vtu", meshio.Mesh(
        np.array(pts), [("hexahedron", np.array(cells))],
        cell_data={k: [np.asarray(v)] for k, v in cell_data.items()}))


def _mesh_scene(tmp_path, options: str):
    return parse_scene(HEAD + f"""
blocks: [{{name: m, mesh: {{file: row.vtu, {options}}}, material: rock}}]
""", "scene.yaml", tmp_path)


def test_mesh_cells_join_by_label_in_order_of_their_first_cell(tmp_path):
    # labels 5, 5, 3, 3, 9: the blocks come in the order of their first cell (5 before 3),
    # each one's cells in mesh order; select drops the cell labelled 9
    _row_of_hexes(tmp_path, 5, pair=[5, 5, 3, 3, 9], zone=[1, 1, 1, 1, 2],
                  kind=[2.0, 2.0, 1.0, 1.0, 1.0])
    specs = expand_blocks(_mesh_scene(tmp_path, "cell_data_group: pair, group_data: kind, "
                                                "select: {zone: 1}"))
    assert [s.name for s in specs] == ["m[5]", "m[3]"]
    assert [s.group for s in specs] == ["2", "1"]  # integral floats without the .0
    assert [[round(float(p.centroid[0]), 6) for p in s.pieces] for s in specs] == \
        [[0.5, 1.5], [2.5, 3.5]]


@pytest.mark.parametrize("options, data, words", [
    ("cell_data_group: nosuch", {"pair": [1, 1]},
     ["blocks[0].mesh", "no scalar cell data 'nosuch' (it has: pair)"]),
    ("material_data: mat", {"mat": [7, 7]}, ["cell 0 has mat = '7', not a material"]),
    ("cell_data_group: pair, group_data: g", {"pair": [1, 1], "g": [1, 2]},
     ["cells 0 and 1 join into block m[1] but differ in 'g'"]),
    ("select: {zone: 3}", {"zone": [1, 2]}, ["no cell of", "is selected"]),
])
def test_bad_mesh_data_is_refused_naming_the_cells(tmp_path, options, data, words):
    _row_of_hexes(tmp_path, 2, **data)
    with pytest.raises(ConfigError) as err:
        expand_blocks(_mesh_scene(tmp_path, options))
    for w in words:
        assert w in str(err.value), str(err.value)


def test_mesh_cells_joined_but_apart_are_refused(tmp_path):
    _row_of_hexes(tmp_path, 3, gap_after=0, pair=[1, 1, 2])
    with pytest.raises(ConfigError, match=r"cells with pair = 1 do not all touch face to face"):
        expand_blocks(_mesh_scene(tmp_path, "cell_data_group: pair"))
