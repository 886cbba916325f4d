"""Zoning of convex blocks (pdem.deformable.mesh): exact partition, orientation, conformity,
determinism, the size bound and a shape-quality floor, on a box, a prism and a hull."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.deformable.mesh import min_dihedral_angles, signed_volumes, tetrahedralise
from pdem.geometry import box, from_vertices, prism


def _hull():
    # 24 points on an ellipsoid: an irregular convex block with faces of mixed sizes
    d = np.random.default_rng(7).normal(size=(24, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return from_vertices(d * [1.0, 0.7, 0.5])


_HEX = [[np.cos(a), np.sin(a), 0.0] for a in np.linspace(0.0, 2 * np.pi, 7)[:-1]]

# (block, zone size, measured minimum dihedral angle floor in degrees)
CASES = {
    "box": (lambda: box([0, 0, 0], [1, 1, 1]), 0.25, 40.0),       # measured 45.0
    "column": (lambda: box([0, 0, 0], [0.5, 0.5, 1.5]), 0.25, 12.0),  # measured 14.8
    "prism": (lambda: prism(_HEX, [0.2, 0.1, 1.0]), 0.3, 15.0),  # measured 20.2
    "hull": (_hull, 0.3, 1.5),  # measured 2.0 (thin cones under small hull faces)
}


@pytest.fixture(scope="module", params=list(CASES))
def case(request):
    make, size, floor = CASES[request.param]
    poly = make()
    return request.param, poly, size, floor, tetrahedralise(poly, size)


def test_volumes_partition_the_block(case):
    _, poly, _, _, m = case
    v = signed_volumes(m.nodes, m.tets)
    assert v.min() > 0.0  # positively oriented, none degenerate
    assert abs(v.sum() - poly.volume) <= 1e-12 * poly.volume


def test_edges_respect_size(case):
    _, _, size, _, m = case
    x = m.nodes[m.tets]
    for a in range(4):
        for b in range(a + 1, 4):
            assert np.linalg.norm(x[:, a] - x[:, b], axis=1).max() <= size * (1 + 1e-12)


def test_nodes_are_unique_and_all_used(case):
    _, _, _, _, m = case
    assert len(np.unique(m.nodes, axis=0)) == len(m.nodes)
    assert np.array_equal(np.unique(m.tets), np.arange(len(m.nodes)))


def test_conforming_closed_surface(case):
    """Every interior tet face is shared by exactly two tets with opposite orientation, the
    boundary triangles' area vectors sum to zero and each lies on the face it is tagged with."""
    _, poly, _, _, m = case
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    tri = m.tets[:, local].reshape(-1, 3)
    _, count = np.unique(np.sort(tri, axis=1), axis=0, return_counts=True)
    assert count.max() == 2
    assert (count == 1).sum() == len(m.surface)
    x = m.nodes[m.surface]
    area_vec = 0.5 * np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    assert np.abs(area_vec.sum(axis=0)).max() < 1e-12 * np.abs(area_vec).sum()
    # tagged face: outward normal matches and the triangle lies in its plane
    n = np.asarray(poly.normals)[m.surface_face]
    unit = area_vec / np.linalg.norm(area_vec, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", unit, n).min() > 1 - 1e-9
    off = np.asarray(poly.offsets)[m.surface_face]
    assert np.abs(np.einsum("kij,kj->ki", x, n) - off[:, None]).max() < 1e-12 * poly.radius()
    # face areas per block face equal the face's area
    per_face = np.bincount(m.surface_face, np.linalg.norm(area_vec, axis=1), poly.n_faces)
    assert np.allclose(per_face, poly.face_areas(), rtol=1e-12)
    # surface flag: exactly the nodes of surface triangles, and those lie on the boundary
    dist = np.max(m.nodes @ np.asarray(poly.normals).T - np.asarray(poly.offsets), axis=1)
    assert np.all(np.abs(dist[m.on_surface]) < 1e-12 * poly.radius())
    assert np.all(dist[~m.on_surface] < -1e-9 * poly.radius())


def test_deterministic(case):
    name, _, size, _, m = case
    again = tetrahedralise(CASES[name][0](), size)
    for a, b in ((m.nodes, again.nodes), (m.tets, again.tets), (m.surface, again.surface)):
        assert a.tobytes() == b.tobytes()


def test_quality_floor(case):
    _, _, _, floor, m = case
    angles = min_dihedral_angles(m.nodes, m.tets)
    print(f"min dihedral {angles.min():.2f} deg, 5th percentile {np.percentile(angles, 5):.2f}")
    assert angles.min() >= floor


def test_dihedral_of_regular_tet():
    """The quality measure itself: a regular tet's dihedral angle is arccos(1/3)."""
    x = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    t = np.array([[0, 1, 2, 3]])
    if signed_volumes(x, t)[0] < 0:
        t = t[:, [0, 2, 1, 3]]
    assert min_dihedral_angles(x, t)[0] == pytest.approx(np.degrees(np.arccos(1 / 3)), abs=1e-10)
