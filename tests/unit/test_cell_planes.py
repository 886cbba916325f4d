"""The compiled check of a fixed-type mesh cell (pdem.geometry.cell_planes) against the numpy
one (pdem.geometry.mesh_import.cell_polyhedron): the same polyhedron, bit for bit, for every
cell the numpy one accepts; every cell it refuses handed back to it (so its message)."""

import meshio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdem.geometry import mesh_import
from pdem.geometry.errors import GeometryError
from pdem.geometry.mesh_import import CELL_FACES, cell_polyhedron, fixed_cell_polyhedron

# reference cells in meshio's node order, positively oriented
UNIT = {
    "tetra": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
    "hexahedron": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                   [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
    "wedge": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]],
    "pyramid": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]],
}
FIELDS = ("vertices", "face_start", "face_verts", "normals", "offsets", "edges", "centroid",
          "inertia")


def random_cell(kind: str, rng: np.random.Generator) -> np.ndarray:
    """A random affine image of the unit cell (either handedness), far from the origin or
    not; a hexahedron, wedge or pyramid stays planar-faced under an affine map."""
    a = np.eye(3) + 0.4 * rng.standard_normal((3, 3))
    while abs(np.linalg.det(a)) < 0.2:
        a = np.eye(3) + 0.4 * rng.standard_normal((3, 3))
    shift = rng.uniform(-1, 1, 3) * 10.0 ** rng.integers(0, 6)
    return np.asarray(UNIT[kind], float) @ a.T * 10.0 ** rng.uniform(-2, 2) + shift


def same(a, b) -> None:
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert x.tobytes() == y.tobytes(), f
    assert a.volume == b.volume


@settings(max_examples=60, deadline=None)
@given(kind=st.sampled_from(sorted(CELL_FACES)), seed=st.integers(0, 2**32 - 1))
def test_an_accepted_cell_is_the_numpy_checks_polyhedron_bit_for_bit(kind, seed):
    rng = np.random.default_rng(seed)
    pts = random_cell(kind, rng)
    ids = rng.permutation(len(pts) + 3)[:len(pts)].astype(np.int64)  # ids into a larger array
    points = rng.standard_normal((len(pts) + 3, 3))
    points[ids] = pts
    fast = fixed_cell_polyhedron(points, ids, kind)
    slow = cell_polyhedron(points, ids, CELL_FACES[kind])
    assert fast is not None
    same(fast, slow)


def bad_cells():
    hexa = np.array(UNIT["hexahedron"], float)
    warped = hexa.copy()
    warped[6, 2] += 0.2  # a top corner lifted: the top face is warped
    reentrant = hexa.copy()
    reentrant[6, :2] = [0.3, 0.3]  # a top corner pushed inside: not convex
    flat = hexa.copy()
    flat[4:, 2] = 0.0  # zero height
    nan = hexa.copy()
    nan[3, 1] = np.nan
    tet_flat = np.array(UNIT["tetra"], float)
    tet_flat[3] = [0.3, 0.3, 0.0]
    return [("hexahedron", warped, None), ("hexahedron", reentrant, None),
            ("hexahedron", flat, None), ("hexahedron", nan, None),
            ("tetra", tet_flat, None),
            # a collapsed hexahedron (a wedge: ids repeated) is accepted, the numpy way
            ("hexahedron", hexa, np.array([0, 1, 2, 2, 4, 5, 6, 6], np.int64))]


@pytest.mark.parametrize("k", range(len(bad_cells())))
def test_a_cell_the_compiled_check_refuses_goes_to_the_numpy_one(k):
    kind, pts, ids = bad_cells()[k]
    ids = np.arange(len(pts), dtype=np.int64) if ids is None else ids
    assert fixed_cell_polyhedron(pts, ids, kind) is None
    if len(set(ids.tolist())) == len(ids):
        with pytest.raises(GeometryError):
            cell_polyhedron(pts, ids, CELL_FACES[kind])


def test_a_polyhedron_cell_or_a_wrong_node_count_is_not_for_the_compiled_check():
    pts = np.array(UNIT["hexahedron"], float)
    assert fixed_cell_polyhedron(pts, np.arange(8, dtype=np.int64), "polyhedron8") is None
    assert fixed_cell_polyhedron(pts, np.arange(6, dtype=np.int64), "hexahedron") is None


def test_a_mesh_reads_to_the_same_blocks_either_way(tmp_path, monkeypatch):
    """A mixed mesh (hexahedra, tetrahedra, a collapsed hexahedron, a wedge, a pyramid) read
    with the compiled check and without it."""
    rng = np.random.default_rng(7)
    x = np.linspace(0.0, 3.0, 4) + 1e5  # far from the origin
    grid = np.stack(np.meshgrid(x, x, x, indexing="ij"), -1).reshape(-1, 3)
    grid = grid + 1e-7 * rng.standard_normal(grid.shape)  # not a lattice; within tolerance
    hexes = []
    for i in range(3):
        for j in range(3):
            for k in range(3):
                c = [(i, j, k), (i + 1, j, k), (i + 1, j + 1, k), (i, j + 1, k)]
                c = c + [(a, b, k + 1) for a, b, _ in c]
                hexes.append([np.ravel_multi_index(p, (4, 4, 4)) for p in c])
    hexes = np.array(hexes)
    collapsed = hexes[0][[0, 1, 2, 2, 4, 5, 6, 6]]
    cells = [("hexahedron", np.vstack([hexes[:20], collapsed])),
             ("tetra", hexes[20:][:, [0, 1, 3, 4]]),
             ("wedge", hexes[:1][:, [0, 1, 3, 4, 5, 7]]),
             ("pyramid", hexes[:1][:, [0, 1, 2, 3, 4]])]
    path = tmp_path / "mixed.vtu"
    meshio.write(path, meshio.Mesh(grid, cells))
    fast = mesh_import.read_mesh_cells(path)
    monkeypatch.setattr(mesh_import, "fixed_cell_polyhedron", lambda *a, **k: None)
    slow = mesh_import.read_mesh_cells(path)
    assert [c.index for c in fast] == [c.index for c in slow]
    assert len(fast) == sum(len(c[1]) for c in cells)
    for a, b in zip(fast, slow, strict=True):
        same(a.poly, b.poly)
