"""Unit tests for pdem.geometry against closed forms and independent computations."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.geometry import (
    ConvexPolyhedron,
    GeometryError,
    box,
    check_convex,
    convex_hull,
    from_planes,
    from_vertices,
    hull_vertex_indices,
    mass_properties,
    prism,
    tetrahedron,
)

RTOL = 1e-12


def rotation(seed: int) -> np.ndarray:
    """Random proper rotation from a QR decomposition (independent of pdem code)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def close(a, b, scale=1.0, rtol=RTOL):
    """Relative comparison, with zero entries compared against ``rtol * scale``."""
    np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * scale)


# ---------------------------------------------------------------- independent integration
def _tet_moments_quadrature(v: np.ndarray):
    """Volume, first and second moments of a tetrahedron by Gauss-Legendre on a Duffy map.

    Collapsed coordinates x = u, y = (1-u) s, z = (1-u)(1-s) w map the unit cube onto the
    unit simplex with Jacobian (1-u)^2 (1-s); the integrands are then polynomials of degree
    <= 4 per variable, which 4-point Gauss-Legendre integrates exactly.
    """
    g, w = np.polynomial.legendre.leggauss(4)
    g, w = 0.5 * (g + 1), 0.5 * w
    U, S, W = np.meshgrid(g, g, g, indexing="ij")
    wt = (w[:, None, None] * w[None, :, None] * w[None, None, :]) * (1 - U) ** 2 * (1 - S)
    bary = np.stack([U, (1 - U) * S, (1 - U) * (1 - S) * W], axis=-1).reshape(-1, 3)
    wt = wt.reshape(-1)
    J = np.stack([v[1] - v[0], v[2] - v[0], v[3] - v[0]], axis=1)
    x = v[0] + bary @ J.T
    wt = wt * abs(np.linalg.det(J))
    return wt.sum(), wt @ x, np.einsum("q,qi,qj->ij", wt, x, x)


def _inertia_from_moments(vol, first, second):
    c = first / vol
    cov = second - vol * np.outer(c, c)
    return c, np.trace(cov) * np.eye(3) - cov


def _tonon_tetrahedron(v: np.ndarray):
    """Tonon (2004) closed-form inertia of a tetrahedron about its centroid, unit density."""
    vol = abs(np.linalg.det(np.stack([v[1] - v[0], v[2] - v[0], v[3] - v[0]]))) / 6
    c = v.mean(axis=0)
    x, y, z = (v - c).T
    detj = 6 * vol

    def sq(t):  # sum_{i <= j} t_i t_j, Tonon's symmetric quadratic form
        return (t.sum() ** 2 + (t**2).sum()) / 2

    def pr(s, t):  # sum_{i, j} s_i t_j + sum_i s_i t_i (diagonal terms doubled)
        return s.sum() * t.sum() + (s * t).sum()

    a = detj * (sq(y) + sq(z)) / 60
    b = detj * (sq(x) + sq(z)) / 60
    cc = detj * (sq(x) + sq(y)) / 60
    ap = detj * pr(y, z) / 120  # a' = -I_yz
    bp = detj * pr(x, z) / 120  # b' = -I_xz
    cp = detj * pr(x, y) / 120  # c' = -I_xy
    return vol, c, np.array([[a, -cp, -bp], [-cp, b, -ap], [-bp, -ap, cc]])


# ---------------------------------------------------------------- structure checks
def check_structure(poly: ConvexPolyhedron, tol: float = 1e-10):
    """Invariants every polyhedron must satisfy (planarity, orientation, half-edges, Euler)."""
    nv, nf, ne = poly.n_vertices, poly.n_faces, poly.n_edges
    assert nv - ne + nf == 2
    scale = np.abs(poly.vertices).max() + np.ptp(poly.vertices)
    np.testing.assert_allclose(np.linalg.norm(poly.normals, axis=1), 1.0, rtol=1e-14)
    for f in range(nf):
        pts = poly.face_polygon(f)
        assert len(pts) >= 3
        # planar, on its plane
        assert np.max(np.abs(pts @ poly.normals[f] - poly.offsets[f])) <= tol * scale
        # CCW from outside: the right-hand rule (Newell sum) points along the outward normal
        area_vec = 0.5 * sum(np.cross(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts)))
        np.testing.assert_allclose(
            area_vec, poly.face_area(f) * poly.normals[f], atol=tol * scale**2
        )
        # convex polygon: every corner turns left about the normal
        e = np.roll(pts, -1, axis=0) - pts
        turn = np.cross(np.roll(e, 1, axis=0), e) @ poly.normals[f]
        assert np.all(turn > 0)
    # convex: every vertex on or below every face plane
    d = poly.vertices @ poly.normals.T - poly.offsets
    assert d.max() <= tol * scale
    # edges unique, i < j, and equal to the set of face sides
    assert np.all(poly.edges[:, 0] < poly.edges[:, 1])
    sides = set()
    for f in range(nf):
        ids = poly.face_vertex_ids(f).tolist()
        for i, j in zip(ids, ids[1:] + ids[:1], strict=True):
            sides.add((min(i, j), max(i, j)))
    assert sides == {tuple(e) for e in poly.edges.tolist()}
    assert len(sides) == ne
    # half-edges
    nh = len(poly.face_verts)
    h = np.arange(nh)
    assert np.array_equal(poly.he_twin[poly.he_twin], h)
    assert np.all(poly.he_twin != h)
    assert np.array_equal(poly.he_origin, poly.face_verts)
    dest = poly.he_origin[poly.he_next]
    assert np.array_equal(poly.he_origin[poly.he_twin], dest)
    assert np.array_equal(dest[poly.he_twin], poly.he_origin)
    assert np.array_equal(poly.he_face[poly.he_next], poly.he_face)
    for f in range(nf):
        start = poly.face_start[f]
        k = poly.face_start[f + 1] - start
        seq = [start]
        for _ in range(k - 1):
            seq.append(poly.he_next[seq[-1]])
        assert sorted(seq) == list(range(start, start + k))
        assert poly.he_next[seq[-1]] == start
    assert np.array_equal(poly.he_origin[poly.vert_he], np.arange(nv))
    for v in range(nv):
        brute = {f for f in range(nf) if v in poly.face_vertex_ids(f)}
        walked = poly.vertex_faces(v).tolist()
        assert len(walked) == len(brute) and set(walked) == brute
        nb = {j for e in poly.edges.tolist() if v in e for j in e if j != v}
        assert set(poly.vertex_neighbors(v).tolist()) == nb


# ---------------------------------------------------------------- mass properties
def test_box_closed_form():
    lo, hi = np.array([-1.0, 2.0, 0.5]), np.array([2.0, 2.5, 4.5])
    a, b, c = hi - lo
    p = box(lo, hi)
    check_structure(p)
    assert p.n_vertices == 8 and p.n_faces == 6 and p.n_edges == 12
    m = a * b * c
    close(p.volume, m)
    close(p.centroid, (lo + hi) / 2)
    close(
        p.inertia,
        np.diag([m * (b**2 + c**2), m * (a**2 + c**2), m * (a**2 + b**2)]) / 12,
        scale=m * a * a,
    )


def test_box_from_corners_matches_box():
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([1.0, 2.0, 3.0])
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 2) for z in (0, 3)], float)
    p = from_vertices(corners[::-1])
    check_structure(p)
    q = box(lo, hi)
    assert p.n_faces == 6 and all(np.diff(p.face_start) == 4)
    close(p.volume, q.volume)
    close(p.centroid, q.centroid)
    close(p.inertia, q.inertia, scale=10.0)


@pytest.mark.parametrize(
    "v",
    [
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
        [
            [8.33220, -11.86875, 0.93355],
            [0.75523, 5.00000, 16.37072],
            [52.61236, 5.00000, -5.38580],
            [2.00000, 5.00000, 3.00000],
        ],  # Tonon's example
        [[0.3, -1.2, 2.0], [2.1, 0.4, -0.7], [-1.5, 1.9, 0.2], [0.9, 2.2, 3.1]],
    ],
)
def test_tetrahedron_closed_form(v):
    v = np.array(v, dtype=float)
    p = tetrahedron(*v)
    check_structure(p)
    assert p.n_faces == 4 and p.n_vertices == 4
    vol = abs(np.linalg.det(v[1:] - v[0])) / 6
    close(p.volume, vol)
    close(p.centroid, v.mean(axis=0), scale=np.abs(v).max())
    tvol, tc, tI = _tonon_tetrahedron(v)
    qvol, qfirst, qsecond = _tet_moments_quadrature(v)
    qc, qI = _inertia_from_moments(qvol, qfirst, qsecond)
    scale = np.abs(tI).max()
    close(tvol, vol)
    close(qvol, vol)
    close(tI, qI, scale=scale, rtol=1e-10)  # the two references agree with each other
    close(p.inertia, tI, scale=scale)
    close(p.inertia, qI, scale=scale, rtol=1e-10)


def test_tonon_published_example():
    # Tonon (2004), J. Math. Stat. 1(1): a = 43520.33257, b = 194711.28938, c = 191168.76173,
    # a' = 4417.66150, b' = -46343.16662, c' = 11996.20119 (density 1).
    v = np.array(
        [
            [8.33220, -11.86875, 0.93355],
            [0.75523, 5.00000, 16.37072],
            [52.61236, 5.00000, -5.38580],
            [2.00000, 5.00000, 3.00000],
        ]
    )
    I = tetrahedron(*v).inertia
    ref = np.array(
        [
            [43520.33257, -11996.20119, 46343.16662],
            [-11996.20119, 194711.28938, -4417.66150],
            [46343.16662, -4417.66150, 191168.76173],
        ]
    )
    # The paper prints vertices rounded to 5 decimals, so agreement is ~1e-8, not round-off.
    np.testing.assert_allclose(I, ref, rtol=5e-8)


def test_rotated_translated_box():
    R, t = rotation(3), np.array([10.0, -4.0, 7.5])
    b = box([0, 0, 0], [1.0, 2.0, 0.5])
    corners = b.vertices @ R.T + t
    moved_hull = convex_hull(corners)  # recomputed from scratch
    moved_tf = b.transformed(R, t)  # transformed tensors
    for p in (moved_hull, moved_tf):
        check_structure(p)
        close(p.volume, b.volume)
        close(p.centroid, R @ b.centroid + t, scale=10.0)
        close(p.inertia, R @ b.inertia @ R.T, scale=1.0)
    close(moved_tf.vertices, corners, scale=10.0)
    with pytest.raises(GeometryError):
        b.transformed(np.diag([1.0, 1.0, -1.0]), t)


def test_principal_frame_round_trip():
    rng = np.random.default_rng(7)
    p = convex_hull(rng.normal(size=(40, 3)) * [1.0, 2.0, 0.5] + [3.0, -1.0, 2.0])
    body, c, R, moments = p.principal_frame()
    close(np.linalg.det(R), 1.0)
    close(R.T @ R, np.eye(3), scale=1.0)
    assert np.all(np.diff(moments) >= 0)
    close(R @ body.vertices.T + c[:, None], p.vertices.T, scale=10.0)
    close(c, p.centroid)
    check_structure(body)
    # recompute mass properties of the body-frame vertices: centroid 0, inertia diagonal
    vol, cb, Ib = mass_properties(body.vertices, body.face_start, body.face_verts)
    close(vol, p.volume)
    close(cb, np.zeros(3), scale=10.0, rtol=1e-11)
    close(Ib, np.diag(moments), scale=moments.max(), rtol=1e-11)
    close(R @ np.diag(moments) @ R.T, p.inertia, scale=moments.max())


def test_far_from_origin_box():
    off = np.array([5.0e6, -3.0e6, 1.2e3])  # map coordinates
    corners = np.array([[x, y, z] for x in (0, 2) for y in (0, 1) for z in (0, 3)], float) + off
    p = convex_hull(corners)
    assert p.n_faces == 6
    np.testing.assert_allclose(p.volume, 6.0, rtol=1e-9)
    np.testing.assert_allclose(p.inertia, box([0, 0, 0], [2, 1, 3]).inertia, atol=1e-7)


# ---------------------------------------------------------------- hull
@pytest.mark.parametrize("mode", ["surface", "ball"])
def test_hull_random_cloud(mode):
    rng = np.random.default_rng(11)
    pts = rng.normal(size=(250, 3))
    pts /= np.linalg.norm(pts, axis=1)[:, None]
    if mode == "ball":
        pts *= rng.uniform(0, 1, size=(250, 1)) ** (1 / 3)
    pts = pts * 2.0 + [1.0, -2.0, 0.5]
    p = convex_hull(pts)
    check_structure(p)
    tol = 1e-9 * 4
    assert np.max(pts @ p.normals.T - p.offsets) <= tol
    idx = hull_vertex_indices(pts)
    assert np.array_equal(p.vertices, pts[idx])
    if mode == "surface":
        assert p.n_vertices == 250  # in general position, every sphere point is extreme
    # support function: the hull reaches as far as the cloud in every direction
    dirs = rng.normal(size=(500, 3))
    np.testing.assert_allclose((p.vertices @ dirs.T).max(0), (pts @ dirs.T).max(0), rtol=1e-14)
    # independent volume: divergence theorem over faces, V = sum(A_f d_f)/3 with d_f about
    # an interior point
    x0 = pts.mean(axis=0)
    vol = sum(p.face_area(f) * (p.offsets[f] - p.normals[f] @ x0) for f in range(p.n_faces)) / 3
    close(p.volume, vol, rtol=1e-12)
    # and by quadrature over tetrahedra from vertex 0
    qvol = qfirst = 0.0
    for f in range(p.n_faces):
        ids = p.face_vertex_ids(f)
        for i in range(1, len(ids) - 1):
            tet = p.vertices[[0, ids[0], ids[i], ids[i + 1]]]
            if abs(np.linalg.det(tet[1:] - tet[0])) < 1e-14:
                continue
            s = np.sign(np.linalg.det(tet[1:] - tet[0]))
            v, fm, _ = _tet_moments_quadrature(tet)
            qvol, qfirst = qvol + s * v, qfirst + s * fm
    close(p.volume, qvol, rtol=1e-11)
    close(p.centroid, qfirst / qvol, scale=2.0, rtol=1e-11)
    assert p.volume < 4 / 3 * np.pi * 8


def test_hull_converges_to_sphere():
    n = 600  # Fibonacci sphere: near-uniform, volume deficit ~ O(1/n)
    k = np.arange(n) + 0.5
    phi, theta = np.arccos(1 - 2 * k / n), np.pi * (1 + 5**0.5) * k
    pts = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)
    p = convex_hull(pts)
    assert p.n_vertices == n
    exact = 4 / 3 * np.pi
    assert 0.99 * exact < p.volume < exact
    close(p.inertia, np.eye(3) * 0.4 * p.volume, scale=1.0, rtol=2e-2)


def test_coplanar_merge_cube_with_face_and_edge_points():
    c = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    mids = (c[:, None] + c[None, :]).reshape(-1, 3) / 2  # edge mids, face centres, centre
    rng = np.random.default_rng(5)
    on_faces = rng.uniform(0, 1, size=(60, 3))
    on_faces[np.arange(60), rng.integers(0, 3, 60)] = rng.integers(0, 2, 60)
    inside = rng.uniform(0.1, 0.9, size=(20, 3))
    pts = np.concatenate([mids, on_faces, c[::-1], inside, c])  # also duplicates
    rng.shuffle(pts)
    p = convex_hull(pts)
    check_structure(p)
    assert p.n_vertices == 8 and p.n_faces == 6 and p.n_edges == 12
    assert np.all(np.diff(p.face_start) == 4)
    close(p.volume, 1.0)
    close(p.inertia, np.eye(3) / 6, scale=1.0)


def test_coplanar_merge_octagonal_prism():
    ang = np.arange(8) * np.pi / 4
    base = np.stack([np.cos(ang), np.sin(ang), np.zeros(8)], 1)
    p = prism(base, [0.2, 0.1, 2.0])
    check_structure(p)
    assert p.n_faces == 10 and p.n_vertices == 16
    assert sorted(np.diff(p.face_start).tolist()) == [4] * 8 + [8] * 2
    close(p.volume, 2 * np.sqrt(2) * 2.0)


def test_check_convex_reports_interior_points():
    c = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    pts = np.concatenate([c[:5], [[0.5, 0.5, 0.5]], c[5:], [[0.5, 0.5, 1.0]]])
    assert check_convex(pts).tolist() == [5]  # the face point is on the hull, not inside
    assert check_convex(c).tolist() == []
    assert check_convex(pts, boundary=True).tolist() == [5, 9]


def test_check_convex_l_shaped_prism():
    # Re-entrant corners of an L-shaped prism lie on hull faces, not strictly inside.
    ell = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
    pts = np.concatenate([np.c_[ell, np.zeros(6)], np.c_[ell, np.ones(6)]])
    assert check_convex(pts).tolist() == []
    assert check_convex(pts, boundary=True).tolist() == [3, 9]


@pytest.mark.parametrize(
    ("pts", "msg"),
    [
        (np.zeros((3, 3)), "at least 4"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.2, 0]], "coplanar"),
        ([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], "collinear"),
        ([[1, 1, 1]] * 5, "coincide"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]], "NaN"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.inf]], "NaN or inf"),
        (np.zeros((4, 2)), "shape"),
    ],
)
def test_hull_errors(pts, msg):
    with pytest.raises(GeometryError, match=msg):
        convex_hull(pts)
    assert issubclass(GeometryError, ValueError)


def test_polyhedron_is_immutable():
    p = box([0, 0, 0], [1, 1, 1])
    with pytest.raises(ValueError):
        p.vertices[0, 0] = 5.0
    with pytest.raises(AttributeError):
        p.volume = 2.0


# ---------------------------------------------------------------- builders
def test_from_planes_box():
    n = np.array([[1, 0, 0], [-1, 0, 0], [0, 2, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    d = np.array([2.0, 1.0, 4.0, 0.0, 3.0, -0.5])  # x in [-1,2], y in [0,2], z in [0.5,3]
    p = from_planes(n, d)
    check_structure(p)
    q = box([-1, 0, 0.5], [2, 2, 3])
    assert p.n_faces == 6 and p.n_vertices == 8
    close(p.volume, q.volume)
    close(p.centroid, q.centroid)
    close(p.inertia, q.inertia, scale=10.0)
    # faces carry the exact input planes
    for f in range(6):
        k = np.argmax(n @ p.normals[f] / np.linalg.norm(n, axis=1))
        close(p.normals[f], n[k] / np.linalg.norm(n[k]), scale=1.0)
        close(p.offsets[f], d[k] / np.linalg.norm(n[k]), scale=1.0)


def test_from_planes_wedge():
    # box [-1,1]x[0,1]x[0,2] cut by the roof planes z + x <= 1.5 and z - x <= 1.5
    # (z <= 2 becomes redundant): pentagonal cross-section of area 2.
    s = 1 / np.sqrt(2)
    n = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [s, 0, s], [-s, 0, s]]
    d = [1, 1, 1, 0, 2, 0, 1.5 * s, 1.5 * s]
    p = from_planes(n, d)
    check_structure(p)
    assert p.n_faces == 7 and p.n_vertices == 10
    close(p.volume, 2.0)
    close(p.centroid, [0.0, 0.5, 13 / 24])
    # same solid from a prism of the pentagon, checked by quadrature-independent hull
    pent = np.array([[-1, 0, 0], [1, 0, 0], [1, 0, 0.5], [0, 0, 1.5], [-1, 0, 0.5]], float)
    q = prism(pent, [0, 1, 0])
    close(p.inertia, q.inertia, scale=1.0)


def test_from_planes_bounds_and_errors():
    p = from_planes([[1, 1, 1]], [0.0], bounds=([-1, -1, -1], [1, 1, 1]))
    check_structure(p)
    close(p.volume, 4.0)  # the plane through the centre halves the cube
    with pytest.raises(GeometryError, match="unbounded"):  # open top
        from_planes([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, -1]], [1] * 5)
    with pytest.raises(GeometryError, match="unbounded|empty"):  # cone, one vertex
        from_planes([[-1, 0, 0], [0, -1, 0], [0, 0, -1]], [0, 0, 0])
    with pytest.raises(GeometryError, match="empty"):
        from_planes(
            [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
            [0, -1, 1, 1, 1, 1],
        )
    with pytest.raises(GeometryError):
        from_planes([[0, 0, 0]], [1.0])


def test_prism_errors():
    with pytest.raises(GeometryError, match="in the base plane"):
        prism([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [1, 1, 0])
    with pytest.raises(GeometryError, match="not convex"):
        prism([[0, 0, 0], [2, 0, 0], [0.5, 0.5, 0], [0, 2, 0]], [0, 0, 1])
    with pytest.raises(GeometryError, match="not planar"):
        prism([[0, 0, 0], [1, 0, 0], [1, 1, 0.5], [0, 1, 0]], [0, 0, 1])
    with pytest.raises(GeometryError):
        tetrahedron([0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0])


def test_cross_is_numpys_bit_for_bit():
    """pdem.geometry.vector.cross against np.cross on broadcast shapes and awkward values
    (huge, tiny, mixed signs, integers): the same bits."""
    from pdem.geometry.vector import cross

    rng = np.random.default_rng(5)
    a = rng.normal(size=(50, 3)) * 10.0 ** rng.integers(-12, 12, size=(50, 1))
    b = rng.normal(size=(50, 3)) * 10.0 ** rng.integers(-12, 12, size=(50, 1))
    for x, y in ((a, b), (a[0], b), (a, b[3]), (a[0], b[1]), (a.reshape(5, 10, 3), b[:10]),
                 (np.eye(3)[1], a), (np.array([1, 2, 3]), np.array([4, -5, 6]))):
        assert np.array_equal(cross(x, y), np.cross(x, y))
        assert cross(x, y).shape == np.cross(x, y).shape


def test_rotation_check_is_allclose_and_a_positive_determinant():
    """pdem.geometry.polyhedron._is_rotation by hand gives np.allclose's and det's answer:
    rotations, reflections, near-rotations either side of the tolerance, any matrix, NaN."""
    from pdem.geometry.polyhedron import _is_rotation

    def reference(R, tol=1e-9):
        return bool(np.allclose(R @ R.T, np.eye(3), atol=tol) and np.linalg.det(R) > 0.0)

    rng = np.random.default_rng(3)
    kinds = [lambda Q: Q, lambda Q: -Q, lambda Q: rng.standard_normal((3, 3)),
             lambda Q: Q + rng.standard_normal((3, 3)) * 10.0 ** rng.uniform(-12, -3),
             lambda Q: np.diag([1.0 + rng.uniform(-2e-5, 2e-5), 1.0, 1.0])]
    seen = set()
    for i in range(2000):
        Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        R = kinds[i % len(kinds)](Q)
        if i == 7:
            R[0, 0] = np.nan
        assert _is_rotation(R) == reference(R), R
        seen.add(reference(R))
    assert seen == {True, False}
