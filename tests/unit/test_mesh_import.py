"""Volume meshes read into convex blocks (pdem.geometry.mesh_import).

Every expected volume and centroid is a closed form computed here from the coordinates the
test writes; the files go through meshio's own writers, so the node orderings checked are
the ones meshio produces and reads.
"""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

meshio = pytest.importorskip("meshio")

from pdem.geometry import GeometryError  # noqa: E402
from pdem.geometry.mesh_import import (  # noqa: E402
    CELL_FACES,
    MeshCell,
    cell_polyhedron,
    read_mesh_cells,
)
from pdem.geometry.polyhedron import ConvexPolyhedron  # noqa: E402

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


def _write(path, points, cells, cell_data=None, **kw):
    mesh = meshio.Mesh(np.asarray(points), cells, cell_data=cell_data or {})
    with warnings.catch_warnings():
        # gmsh22 warns when it fills in missing tags; not what these tests are about
        warnings.simplefilter("ignore")
        mesh.write(path, **kw)
    return path


# ---------------------------------------------------------------------------- fixtures
# Coordinates along each axis: non-uniform spacing, offset from the origin.
XS = np.array([1.0, 1.5, 2.75, 3.0])
YS = np.array([-2.0, -1.2, 0.3])
ZS = np.array([10.0, 10.25, 11.0])


def _grid():
    """3x2x2 hexahedra over XS x YS x ZS, VTK order, plus the boundary quads of z = ZS[0]."""
    pid = {}
    pts = []
    for k, j, i in itertools.product(range(len(ZS)), range(len(YS)), range(len(XS))):
        pid[i, j, k] = len(pts)
        pts.append((XS[i], YS[j], ZS[k]))
    hexes, boxes = [], []
    for k, j, i in itertools.product(range(len(ZS) - 1), range(len(YS) - 1), range(len(XS) - 1)):
        c = [(i, j, k), (i + 1, j, k), (i + 1, j + 1, k), (i, j + 1, k)]
        hexes.append([pid[q] for q in c] + [pid[a, b, k + 1] for a, b, _ in c])
        boxes.append(((XS[i], YS[j], ZS[k]), (XS[i + 1], YS[j + 1], ZS[k + 1])))
    quads = [
        [pid[i, j, 0], pid[i, j + 1, 0], pid[i + 1, j + 1, 0], pid[i + 1, j, 0]]
        for j, i in itertools.product(range(len(YS) - 1), range(len(XS) - 1))
    ]
    return np.array(pts), np.array(hexes), np.array(quads), np.array(boxes)


def _box_volume_centroid(lo, hi):
    lo, hi = np.asarray(lo), np.asarray(hi)
    return float(np.prod(hi - lo)), 0.5 * (lo + hi)


# Positive (VTK/meshio-oriented) unit cells of each linear type.
UNIT_CELLS = {
    "tetra": np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float),
    "hexahedron": np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
        float,
    ),
    # meshio's wedge (gmsh prism order): triangle 0-1-2 counter-clockwise seen from 3-4-5
    "wedge": np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], float),
    "pyramid": np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float),
}
UNIT_VOLUMES = {"tetra": 1 / 6, "hexahedron": 1.0, "wedge": 0.5, "pyramid": 1 / 3}


# ---------------------------------------------------------------------------- face lists
@pytest.mark.parametrize("kind", sorted(CELL_FACES))
def test_face_lists_are_outward_for_meshio_written_cells(tmp_path, kind):
    # Round-trip through a VTU file (meshio reorders the wedge on the way), then the module's
    # face list, used as is, must already be outward: no orientation fix-up needed.
    pts = UNIT_CELLS[kind]
    path = _write(tmp_path / "c.vtu", pts, [(kind, [list(range(len(pts)))])])
    m = meshio.read(path)
    conn = m.cells[0].data[0]
    np.testing.assert_array_equal(conn, np.arange(len(pts)))
    poly = ConvexPolyhedron.from_faces(m.points[conn], [list(f) for f in CELL_FACES[kind]])
    assert poly.volume == pytest.approx(UNIT_VOLUMES[kind], rel=1e-14)
    for f in range(poly.n_faces):
        assert poly.normals[f] @ (poly.face_polygon(f).mean(axis=0) - poly.centroid) > 0.0
    (cell,) = read_mesh_cells(path)
    assert cell.kind == kind and cell.poly.volume == pytest.approx(UNIT_VOLUMES[kind], rel=1e-14)


def test_wedge_in_vtu_file_uses_vtk_order(tmp_path):
    # The file itself carries VTK's wedge order (0-1-2 normal pointing away from 3-4-5);
    # meshio permutes it to its own on reading. Check the block is the same either way.
    pts = UNIT_CELLS["wedge"]
    path = _write(tmp_path / "w.vtu", pts, [("wedge", [[0, 1, 2, 3, 4, 5]])], binary=False)
    text = path.read_text()
    assert "0 2 1 3 5 4" in " ".join(text.split())
    (cell,) = read_mesh_cells(path)
    assert cell.poly.volume == pytest.approx(0.5, rel=1e-14)


# ---------------------------------------------------------------------------- grids
@pytest.mark.parametrize(
    "name, kw",
    [
        ("grid.vtu", {}),
        ("grid.vtk", {}),
        ("grid.xdmf", {}),
        ("grid.msh", {"file_format": "gmsh22", "binary": False}),
    ],
)
def test_structured_hex_grid_round_trips(tmp_path, name, kw):
    pts, hexes, quads, boxes = _grid()
    n = len(hexes)
    block_id = np.arange(n, dtype=np.int64) % 4 + 1
    zone = 0.5 * np.arange(n, dtype=np.float64)
    if name.endswith(".msh"):
        # meshio's gmsh writer/reader keeps only its own tag arrays: use physical groups
        data = {
            "gmsh:physical": [np.zeros(len(quads), int), block_id],
            "gmsh:geometrical": [np.ones(len(quads), int), np.full(n, 2)],
        }
    else:
        data = {"block_id": [np.zeros(len(quads), int), block_id],
                "zone": [np.zeros(len(quads)), zone]}
    path = _write(tmp_path / name, pts, [("quad", quads), ("hexahedron", hexes)], data, **kw)
    cells = read_mesh_cells(path)
    assert len(cells) == n
    total = 0.0
    for c, (lo, hi) in zip(cells, boxes, strict=True):
        assert isinstance(c, MeshCell) and c.kind == "hexahedron"
        vol, cen = _box_volume_centroid(lo, hi)
        assert abs(c.poly.volume - vol) <= 1e-12
        np.testing.assert_allclose(c.poly.centroid, cen, rtol=0, atol=1e-12)
        total += c.poly.volume
    grid_volume = np.ptp(XS) * np.ptp(YS) * np.ptp(ZS)
    assert total == pytest.approx(grid_volume, rel=1e-13)
    # the boundary quads come first in the file: they are skipped but counted in the index
    assert [c.index for c in cells] == list(range(len(quads), len(quads) + n))
    key = "gmsh:physical" if name.endswith(".msh") else "block_id"
    assert [c.data[key] for c in cells] == block_id.tolist()
    assert all(type(c.data[key]) is int for c in cells)
    if not name.endswith(".msh"):
        assert [c.data["zone"] for c in cells] == zone.tolist()
        assert all(type(c.data["zone"]) is float for c in cells)  # 1.0 stays float


def test_float32_points_far_from_origin_pass(tmp_path):
    # A rotated grid in map coordinates stored as float32: every face is warped by round-off
    # of ~ulp(3e5) = 0.03 m. That is coordinate precision, not geometry, and must pass.
    pts, hexes, _, boxes = _grid()
    a = 0.3
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    big = (pts * 40.0) @ R.T + np.array([3.0e5, 6.0e5, 100.0])
    path = _write(tmp_path / "f32.vtu", big.astype(np.float32), [("hexahedron", hexes)])
    cells = read_mesh_cells(path)
    vols = np.array([np.prod(hi - lo) for lo, hi in boxes]) * 40.0**3
    # float32 corners at 6e5 m are 0.06 m apart: the volumes carry that error (~5e-4)
    np.testing.assert_allclose([c.poly.volume for c in cells], vols, rtol=2e-3)


# ---------------------------------------------------------------------------- tetrahedra
def _cube_tets(flip: bool):
    """A 2 x 3 x 4 box split into 6 tetrahedra along its main diagonal (Kuhn split)."""
    size = np.array([2.0, 3.0, 4.0])
    corners = np.array(list(itertools.product([0, 1], repeat=3)))[:, ::-1] * size  # bit0 = x
    cid = {tuple(c): i for i, c in enumerate((corners / size).astype(int).tolist())}
    tets = []
    for perm in itertools.permutations(range(3)):
        path = [np.zeros(3, int)]
        for ax in perm:
            nxt = path[-1].copy()
            nxt[ax] = 1
            path.append(nxt)
        t = [cid[tuple(p.tolist())] for p in path]
        if flip:
            t[0], t[1] = t[1], t[0]
        tets.append(t)
    return corners, np.array(tets), size


@pytest.mark.parametrize("flip", [False, True])
def test_cube_split_into_tetrahedra(tmp_path, flip):
    pts, tets, size = _cube_tets(flip)
    # the Kuhn split has both handednesses; `flip` swaps them all
    signs = [np.linalg.det(pts[t[1:]] - pts[t[0]]) > 0 for t in tets]
    assert any(signs) and not all(signs)
    path = _write(tmp_path / "tets.vtu", pts, [("tetra", tets)])
    cells = read_mesh_cells(path)
    assert len(cells) == 6
    for c, t in zip(cells, tets, strict=True):
        assert c.poly.volume == pytest.approx(np.prod(size) / 6, rel=1e-13)
        np.testing.assert_allclose(c.poly.centroid, pts[t].mean(axis=0), atol=1e-13)
    assert sum(c.poly.volume for c in cells) == pytest.approx(np.prod(size), rel=1e-13)


def test_mixed_mesh_ignores_triangles_and_lines(tmp_path):
    pts, tets, size = _cube_tets(False)
    tris = [[0, 1, 2], [0, 2, 4]]
    path = _write(
        tmp_path / "mixed.vtu",
        pts,
        [("line", [[0, 7]]), ("triangle", tris), ("tetra", tets)],
        {"block_id": [np.array([-1]), np.array([-2, -2]), np.arange(6) + 10]},
    )
    cells = read_mesh_cells(path)
    assert [c.kind for c in cells] == ["tetra"] * 6
    assert [c.index for c in cells] == list(range(3, 9))
    assert [c.data["block_id"] for c in cells] == list(range(10, 16))


# ---------------------------------------------------------------------------- wedge, pyramid
def test_wedge_and_pyramid_closed_forms(tmp_path):
    # Wedge: triangle base (a general one) extruded straight up by h.
    tri = np.array([[0.2, 0.1, 0.0], [2.2, 0.4, 0.0], [0.9, 1.7, 0.0]])
    h = 1.3
    wedge = np.vstack([tri, tri + [0, 0, h]])
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    area = 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0])
    # Pyramid: a x b rectangle at z = 5 with an off-centre apex.
    a, b, hp = 2.0, 1.5, 3.0
    apex = np.array([3.4, 0.9, 5.0 + hp])
    base = np.array([[3.0, 0.0, 5.0], [3.0 + a, 0.0, 5.0], [3.0 + a, b, 5.0], [3.0, b, 5.0]])
    pts = np.vstack([wedge, base, apex])
    path = _write(tmp_path / "wp.vtu", pts, [("wedge", [list(range(6))]),
                                              ("pyramid", [list(range(6, 11))])])
    w, p = read_mesh_cells(path)
    assert (w.kind, p.kind) == ("wedge", "pyramid")
    assert w.poly.volume == pytest.approx(area * h, rel=1e-13)
    np.testing.assert_allclose(w.poly.centroid, [*tri.mean(axis=0)[:2], h / 2], atol=1e-13)
    assert p.poly.volume == pytest.approx(a * b * hp / 3, rel=1e-13)
    np.testing.assert_allclose(p.poly.centroid, 0.75 * base.mean(axis=0) + 0.25 * apex, atol=1e-13)


def test_inverted_wedge_and_pyramid_read_the_same(tmp_path):
    # Clockwise numbering (the mirror image's ordering) gives the same blocks.
    w = UNIT_CELLS["wedge"]
    p = UNIT_CELLS["pyramid"] + [2, 0, 0]
    pts = np.vstack([w, p])
    path = _write(tmp_path / "inv.vtu", pts, [("wedge", [[0, 2, 1, 3, 5, 4]]),
                                              ("pyramid", [[6, 9, 8, 7, 10]])])
    cw, cp = read_mesh_cells(path)
    assert cw.poly.volume == pytest.approx(0.5, rel=1e-14)
    assert cp.poly.volume == pytest.approx(1 / 3, rel=1e-14)


def test_collapsed_hexahedron_is_a_wedge(tmp_path):
    # A hexahedron with nodes 2 = 3 and 6 = 7 repeated (how some meshers write a wedge).
    pts = UNIT_CELLS["hexahedron"]
    path = _write(tmp_path / "col.vtu", pts, [("hexahedron", [[0, 1, 2, 2, 4, 5, 6, 6]])])
    (c,) = read_mesh_cells(path)
    assert c.poly.n_vertices == 6 and c.poly.n_faces == 5
    assert c.poly.volume == pytest.approx(0.5, rel=1e-14)


# ---------------------------------------------------------------------------- polyhedra
def test_polyhedron_cells_from_vtu(tmp_path):
    # A hexagonal prism (12 nodes) and an octahedron (6 nodes), some faces numbered
    # clockwise. The 12-node cell comes first: meshio 5.3.5 hands back its cell data in
    # ascending node count, which the reader must undo.
    r, h = 1.0, 2.0
    ang = np.arange(6) * np.pi / 3
    ring = np.stack([r * np.cos(ang), r * np.sin(ang), np.zeros(6)], axis=1)
    prism = np.vstack([ring, ring + [0, 0, h]])
    prism_faces = [np.arange(6)[::-1], np.arange(6, 12)]  # bottom outward, top outward
    prism_faces += [np.array([k, (k + 1) % 6, (k + 1) % 6 + 6, k + 6]) for k in range(6)]
    prism_faces[3] = prism_faces[3][::-1]  # one side face inward: orientation is redone
    octa = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    octa = octa * 0.5 + [5.0, 0.0, 0.0]
    octa_faces = [np.array(f) + 12 for f in (
        (0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5))]
    pts = np.vstack([prism, octa])
    try:
        path = _write(tmp_path / "poly.vtu", pts, [("polyhedron12", [prism_faces]),
                                                   ("polyhedron6", [octa_faces])],
                      {"block_id": [np.array([12]), np.array([6])]})
        meshio.read(path)
    except Exception as exc:  # pragma: no cover - depends on the meshio version
        pytest.skip(f"meshio cannot round-trip VTU polyhedra here: {exc}")
    cells = read_mesh_cells(path)
    by_kind = {c.kind: c for c in cells}
    assert set(by_kind) == {"polyhedron12", "polyhedron6"}
    hexagon_area = 1.5 * np.sqrt(3.0) * r**2
    pc, oc = by_kind["polyhedron12"], by_kind["polyhedron6"]
    assert pc.poly.volume == pytest.approx(hexagon_area * h, rel=1e-13)
    np.testing.assert_allclose(pc.poly.centroid, [0, 0, h / 2], atol=1e-13)
    assert oc.poly.volume == pytest.approx(4 / 3 * 0.5**3, rel=1e-13)
    np.testing.assert_allclose(oc.poly.centroid, [5, 0, 0], atol=1e-13)
    assert pc.data["block_id"] == 12 and oc.data["block_id"] == 6


# ---------------------------------------------------------------------------- refusals
def _hex_file(tmp_path, hex_pts, n_good=2):
    """``n_good`` unit cubes side by side, then the given hexahedron (cell index n_good)."""
    pts = []
    for k in range(n_good):
        pts.extend(UNIT_CELLS["hexahedron"] + [2.0 * k, 0, 0])
    pts.extend(hex_pts)
    conn = np.arange(8 * (n_good + 1)).reshape(-1, 8)
    return _write(tmp_path / "h.vtu", np.array(pts), [("hexahedron", conn)])


def test_reentrant_hexahedron_is_refused(tmp_path):
    # Planar faces, but the bottom (and top) quad is an arrowhead: node 3 is re-entrant.
    base = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [1.4, 0.6, 0]], float) + [10, 0, 0]
    path = _hex_file(tmp_path, np.vstack([base, base + [0, 0, 1]]))
    with pytest.raises(GeometryError, match=r"cell 2 \(hexahedron\): node \d .* outside the plane "
                                            r"of face \d: not convex") as info:
        read_mesh_cells(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_warped_face_is_refused_but_round_off_passes(tmp_path):
    cube = UNIT_CELLS["hexahedron"] + [10, 0, 0]
    warped = cube.copy()
    warped[6, 2] += 0.12  # lift one top corner: the top face is no longer planar
    with pytest.raises(GeometryError, match=r"cell 2 \(hexahedron\): face 1 is warped: node \d "
                                            r"\(point \d+\) lies 0.0\d+ m off"):
        read_mesh_cells(_hex_file(tmp_path, warped))
    rng = np.random.default_rng(3)
    noisy = cube + rng.uniform(-1e-12, 1e-12, cube.shape)
    cells = read_mesh_cells(_hex_file(tmp_path, noisy))
    assert cells[2].poly.volume == pytest.approx(1.0, rel=1e-10)


def test_degenerate_cells_are_refused(tmp_path):
    flat = UNIT_CELLS["hexahedron"].copy()
    flat[4:, 2] = 0.0  # top face pressed onto the bottom
    with pytest.raises(GeometryError, match=r"cell 2 \(hexahedron\): degenerate"):
        read_mesh_cells(_hex_file(tmp_path, flat + [10, 0, 0]))
    pts = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float)  # coplanar tet
    path = _write(tmp_path / "t.vtu", pts, [("tetra", [[0, 1, 2, 3]])])
    with pytest.raises(GeometryError, match=r"cell 0 \(tetra\): degenerate"):
        read_mesh_cells(path)


def test_higher_order_cells_are_refused(tmp_path):
    corners = UNIT_CELLS["tetra"]
    mids = 0.5 * (corners[[0, 1, 2, 0, 0, 1]] + corners[[1, 2, 0, 3, 3, 3]])
    pts = np.vstack([corners, mids])
    path = _write(tmp_path / "t10.vtu", pts, [("tetra10", [list(range(10))])])
    with pytest.raises(GeometryError, match=r"cell 0 \(tetra10\): higher-order .* linear mesh"):
        read_mesh_cells(path)


def test_file_without_volume_cells_is_refused(tmp_path):
    pts = UNIT_CELLS["tetra"]
    path = _write(tmp_path / "s.vtu", pts, [("triangle", [[0, 1, 2], [0, 1, 3]])])
    with pytest.raises(GeometryError, match=r"no 3D cells \(found: triangle\)"):
        read_mesh_cells(path)


def test_missing_and_unreadable_files(tmp_path):
    missing = tmp_path / "nope.vtu"
    with pytest.raises(GeometryError, match="cannot read mesh .*nope.vtu: .*not found"):
        read_mesh_cells(missing)
    bad = tmp_path / "bad.vtu"
    bad.write_text("this is not\nXML at all\n")
    with pytest.raises(GeometryError, match="cannot read mesh .*bad.vtu: ") as info:
        read_mesh_cells(bad)
    assert "\n" not in str(info.value)
    odd = tmp_path / "rock.xyz123"
    odd.write_text("1 2 3\n")
    with pytest.raises(GeometryError, match="cannot read mesh .*rock.xyz123: .*format"):
        read_mesh_cells(odd)


# ---------------------------------------------------------------------------- cell data, select
def test_cell_data_scalars_and_select(tmp_path):
    pts, hexes, quads, _ = _grid()
    n = len(hexes)
    data = {
        "block_id": [np.zeros(len(quads), np.int32), np.arange(n, dtype=np.int32)],
        "zone": [np.zeros(len(quads)), np.where(np.arange(n) < 6, 1.0, 2.0)],
        "column": [np.zeros((len(quads), 1)), np.arange(n, dtype=float)[:, None] * 0.25],
        "velocity": [np.zeros((len(quads), 3)), np.ones((n, 3))],  # vector: skipped
    }
    path = _write(tmp_path / "d.vtu", pts, [("quad", quads), ("hexahedron", hexes)], data)
    cells = read_mesh_cells(path)
    assert set(cells[0].data) == {"block_id", "zone", "column"}
    assert [c.data["block_id"] for c in cells] == list(range(n))
    assert type(cells[0].data["block_id"]) is int and type(cells[0].data["zone"]) is float
    assert cells[5].data["column"] == 1.25
    zone2 = read_mesh_cells(path, select={"zone": 2})
    assert [c.data["block_id"] for c in zone2] == list(range(6, n))
    some = read_mesh_cells(path, select={"block_id": [1, 3], "zone": (1.0, 2.0)})
    assert [c.index for c in some] == [len(quads) + 1, len(quads) + 3]
    odd = read_mesh_cells(path, select=lambda index, kind, d: d["block_id"] % 2 == 1)
    assert len(odd) == n // 2
    assert read_mesh_cells(path, select={"zone": 7}) == []
    with pytest.raises(GeometryError, match=r"select names cell data \['mat'\]"):
        read_mesh_cells(path, select={"mat": 1})


def test_select_skips_bad_cells_before_checking_them(tmp_path):
    warped = UNIT_CELLS["hexahedron"] + [10, 0, 0]
    warped[6, 2] += 0.3
    path = _hex_file(tmp_path, warped)
    good = read_mesh_cells(path, select=lambda index, kind, d: index != 2)
    assert len(good) == 2


# ---------------------------------------------------------------------------- property
# A general (non-box) convex hexahedron: a frustum-like cell with planar faces.
_HEX0 = np.array(
    [[0, 0, 0], [2, 0, 0], [2, 1.5, 0], [0, 1.5, 0],
     [0.2, 0.1, 1], [1.6, 0.1, 1], [1.6, 1.2, 1], [0.2, 1.2, 1]], float,
)
_POLY0 = ConvexPolyhedron.from_faces(_HEX0, [list(f) for f in CELL_FACES["hexahedron"]])

_coef = st.floats(-2.0, 2.0, allow_nan=False)


@settings(derandomize=True, deadline=None, max_examples=60,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_coef, min_size=9, max_size=9), st.lists(_coef, min_size=3, max_size=3))
def test_affine_map_scales_volume_by_det(a, t):
    A = np.array(a).reshape(3, 3)
    det = np.linalg.det(A)
    # keep to well-conditioned maps: a near-singular one makes a near-flat cell, refused
    hypothesis.assume(abs(det) > 0.05 and np.linalg.cond(A) < 50.0)
    pts = _HEX0 @ A.T + 1000.0 * np.array(t)
    poly = cell_polyhedron(pts, np.arange(8), CELL_FACES["hexahedron"])
    assert poly.volume == pytest.approx(abs(det) * _POLY0.volume, rel=1e-9)
    np.testing.assert_allclose(poly.centroid, A @ _POLY0.centroid + 1000.0 * np.array(t),
                               rtol=0, atol=1e-9 * (1.0 + 1000.0 * np.abs(t).max()))
