"""Common plane: Cundall's hill climb (3DEC eqs. (5)-(10)) and the fast common plane (FCP).

Tolerances: "exact" results (snapped normals, gaps from exact normals) are checked to 1e-12
on unit-size blocks; hill-climb-only quantities to the k_min angle (tan 0.01 deg).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pdem.contact.common_plane import (
    CONTACT_TYPE_NAMES,
    EDGE_EDGE,
    FACE_FACE,
    K_MAX_DEFAULT,
    K_MIN_DEFAULT,
    VERTEX_FACE,
    common_plane,
    contact_type,
    type_code,
)
from pdem.contact.fast_common_plane import fast_common_plane

KMAX = K_MAX_DEFAULT
KMIN = K_MIN_DEFAULT
SNAP = 1e-12
Z3 = np.zeros(3)
EXACT = 1e-12


# ---------------------------------------------------------------- shapes, built by hand
def box(lo, hi):
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def rot(axis, ang):
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(ang) * k + (1 - math.cos(ang)) * k @ k


def rand_rot(rng):
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def hull(pts, tol=1e-10):
    """Brute-force hull of a few points in general position: face normals, edges (i, j)."""
    normals, tris = [], []
    for i, j, k in itertools.combinations(range(len(pts)), 3):
        m = np.cross(pts[j] - pts[i], pts[k] - pts[i])
        s = np.linalg.norm(m)
        if s < 1e-12:
            continue
        m /= s
        d = (pts - pts[i]) @ m
        if np.all(d <= tol):
            normals.append(m)
            tris.append((i, j, k))
        elif np.all(d >= -tol):
            normals.append(-m)
            tris.append((i, j, k))
    edges = sorted({(min(a, b), max(a, b)) for t in tris for a, b in itertools.combinations(t, 2)})
    return np.array(normals), np.array(edges)


def reference_gap(va, vb, fa, fb, ea_idx, eb_idx):
    """Exact max over unit n of min_B n.V - max_A n.V, by enumerating every feature pair."""
    ea = va[ea_idx[:, 1]] - va[ea_idx[:, 0]]
    eb = vb[eb_idx[:, 1]] - vb[eb_idx[:, 0]]
    cands = [fa, -fb]
    x = np.cross(ea[:, None, :], eb[None, :, :]).reshape(-1, 3)
    cands += [x, -x, (vb[None, :, :] - va[:, None, :]).reshape(-1, 3)]
    for e, base, other, sgn in ((ea, va[ea_idx[:, 0]], vb, 1), (eb, vb[eb_idx[:, 0]], va, -1)):
        r = other[None, :, :] - base[:, None, :]
        t = np.einsum("eij,ej->ei", r, e) / np.einsum("ej,ej->e", e, e)[:, None]
        cands.append(sgn * (r - t[:, :, None] * e[:, None, :]).reshape(-1, 3))
    c = np.vstack(cands)
    nrm = np.linalg.norm(c, axis=1)
    c = c[nrm > 1e-12] / nrm[nrm > 1e-12, None]
    g = (c @ vb.T).min(1) - (c @ va.T).max(1)
    k = int(np.argmax(g))
    return g[k], c[k]


BOX_N = np.vstack([np.eye(3), -np.eye(3)])


def cundall(va, vb, ctol=1.0, snap=SNAP, warm=False, n_in=Z3, p_in=Z3):
    return common_plane(va, vb, va.mean(0), vb.mean(0), n_in, p_in, warm, ctol, KMAX, KMIN, snap)


def check_plane(res, va, vb):
    """Return conventions: unit n, gap = min_B - max_A, d_a/d_b relative to p."""
    n, p, gap, da, db, _ = res
    assert abs(np.linalg.norm(n) - 1.0) < 1e-14
    assert gap == pytest.approx((vb @ n).min() - (va @ n).max(), abs=1e-14)
    assert da == pytest.approx(((va - p) @ n).max(), abs=1e-13)
    assert db == pytest.approx(((vb - p) @ n).min(), abs=1e-13)
    assert da == pytest.approx(-gap / 2, abs=1e-13)
    assert db == pytest.approx(gap / 2, abs=1e-13)


# ---------------------------------------------------------------- contact geometries
@pytest.mark.parametrize("g", [1e-3, -1e-3])
@pytest.mark.parametrize("seed", [None, 3])
def test_vertex_face(g, seed):
    cube = box([0, 0, 0], [1, 1, 1])
    tip = np.array([0.4, 0.6, 1.0 + g])
    tet = np.array([tip, tip + [-0.3, -0.2, 0.5], tip + [0.35, -0.1, 0.5], tip + [0.0, 0.4, 0.5]])
    nref = np.array([0.0, 0.0, 1.0])
    if seed is not None:
        r = rand_rot(np.random.default_rng(seed))
        cube, tet, nref = cube @ r.T, tet @ r.T, r @ nref
    res = cundall(cube, tet)
    check_plane(res, cube, tet)
    assert np.abs(res[0] - nref).max() < EXACT
    assert res[2] == pytest.approx(g, abs=EXACT)
    ca, cb, ct = contact_type(cube, tet, res[0], res[1], abs(g) / 2 + 1e-9)
    assert (ca, cb, ct) == (4, 1, VERTEX_FACE)


def test_edge_edge():
    # A: cube with a top edge along x; B: cube with a bottom edge along a direction at 60 deg
    a = box([-0.5] * 3, [0.5] * 3) @ rot([1, 0, 0], math.pi / 4).T
    b = box([-0.5] * 3, [0.5] * 3) @ rot([0, 1, 0], math.pi / 4).T @ rot([0, 0, 1], 0.5).T
    h = math.sqrt(0.5)
    g = 2.5e-3
    b = b + [0.05, -0.08, 2 * h + g]
    r = rand_rot(np.random.default_rng(7))
    a, b = a @ r.T, b @ r.T
    # exact: the two edges (top of A, bottom of B) and their segment-segment distance
    ia = np.argsort(a @ (r @ [0, 0, 1]))[-2:]
    ib = np.argsort(b @ (r @ [0, 0, 1]))[:2]
    ea, eb = a[ia[1]] - a[ia[0]], b[ib[1]] - b[ib[0]]
    nx = np.cross(ea, eb)
    nx /= np.linalg.norm(nx)
    nx *= np.sign(nx @ (b.mean(0) - a.mean(0)))
    dist = (b[ib[0]] - a[ia[0]]) @ nx  # the closest points are interior to both edges here
    for res in (cundall(a, b), cundall(a, b, snap=0.0)):
        check_plane(res, a, b)
        ca, cb, ct = contact_type(a, b, res[0], res[1], g / 2 + 1e-9)
        assert (ca, cb, ct) == (2, 2, EDGE_EDGE)
    res = cundall(a, b)
    assert np.abs(res[0] - nx).max() < EXACT
    assert res[2] == pytest.approx(dist, abs=EXACT)
    res = cundall(a, b, snap=0.0)  # hill climb alone: within the k_min angle
    assert math.acos(min(1.0, res[0] @ nx)) < 2 * KMIN
    assert dist - 2 * KMIN < res[2] <= dist + 1e-15


@pytest.mark.parametrize("g", [1e-3, -1e-3])
@pytest.mark.parametrize("seed", [None, 11, 12])
def test_face_face(g, seed):
    a = box([0, 0, 0], [1, 1, 1])
    b = box([0.3, 0.2, 1 + g], [1.1, 0.9, 1.6 + g])
    nref = np.array([0.0, 0.0, 1.0])
    r = np.eye(3) if seed is None else rand_rot(np.random.default_rng(seed))
    a, b, nref = a @ r.T, b @ r.T, r @ nref
    res = cundall(a, b)
    check_plane(res, a, b)
    assert np.abs(res[0] - nref).max() < EXACT
    assert res[2] == pytest.approx(g, abs=EXACT)
    assert contact_type(a, b, res[0], res[1], abs(g) / 2 + 1e-9) == (4, 4, FACE_FACE)
    # FCP agrees exactly (box faces and the three edge directions, rotated)
    fn, ed = BOX_N @ r.T, r.T.copy()
    rf = fast_common_plane(a, b, a.mean(0), b.mean(0), fn, fn, ed, ed, Z3, Z3, False, 1.0)
    check_plane(rf, a, b)
    assert np.abs(rf[0] - nref).max() < EXACT
    assert rf[2] == pytest.approx(g, abs=EXACT)
    # warm restart from the converged plane: one cycle, nothing moves
    rw = cundall(a, b, warm=True, n_in=res[0], p_in=res[1])
    assert rw[5] == 1
    assert np.array_equal(rw[0], res[0])


def test_face_face_without_snap_is_within_kmin():
    a = box([0, 0, 0], [1, 1, 1])
    b = box([0.3, 0.2, 1.001], [1.1, 0.9, 1.6])
    res = cundall(a, b, snap=0.0)
    assert math.acos(min(1.0, res[0][2])) < 2 * KMIN
    assert 1e-3 - 2 * KMIN < res[2] <= 1e-3 + 1e-15


def test_roll_over_edge_warm_start_is_continuous():
    """B (unit cube, overlapping A by delta) rolls about its bottom edge at x=1."""
    delta = 1e-3
    a = box([0, 0, 0], [1, 1, 1])
    b0 = box([0, 0, 1 - delta], [1, 1, 2 - delta])
    pivot = np.array([1.0, 0.0, 1.0 - delta])
    dth = math.radians(0.5)
    n_prev, p_prev = None, None
    for step in range(61):
        th = step * dth
        b = (b0 - pivot) @ rot([0, 1, 0], th).T + pivot
        nref = np.array([math.sin(th), 0.0, math.cos(th)])
        if n_prev is None:
            res = cundall(a, b)
        else:
            res = cundall(a, b, warm=True, n_in=n_prev, p_in=p_prev)
        check_plane(res, a, b)
        assert np.abs(res[0] - nref).max() < 1e-12
        assert res[2] == pytest.approx(-delta * math.cos(th), abs=1e-12)
        if n_prev is not None:
            jump = math.acos(min(1.0, res[0] @ n_prev))
            assert jump <= dth + KMIN
        n_prev, p_prev = res[0], res[1]


def test_deep_overlap():
    a = box([0, 0, 0], [1, 1, 1])
    b = box([0.2, 0.1, 0.7], [1.2, 1.1, 1.7])  # overlap 0.3 along z, 0.8 / 0.9 laterally
    res = cundall(a, b)
    check_plane(res, a, b)
    assert np.abs(res[0] - [0, 0, 1]).max() < EXACT
    assert res[2] == pytest.approx(-0.3, abs=EXACT)
    # rotated deep overlap: the objective is multimodal. FCP finds the global optimum
    # (exact reference by enumeration); Cundall's local search from the centroid direction
    # stops at a local optimum, A's top face (no normal within 0.05 rad does better).
    b = (box([-0.5] * 3, [0.5] * 3) @ rot([1, 2, 0.5], 0.4).T) + [0.6, 0.55, 1.25]
    fb, eb = hull(b)
    fa, ea = hull(a)
    gref, nref = reference_gap(a, b, fa, fb, ea, eb)
    assert gref < -0.4
    res = cundall(a, b)
    check_plane(res, a, b)
    assert np.abs(res[0] - [0, 0, 1]).max() < EXACT
    assert gref - 2e-3 < res[2] < gref
    n = res[0]
    for ang in (1e-3, 1e-2, 5e-2):
        for th in np.linspace(0, 2 * np.pi, 72, endpoint=False):
            m = n + ang * np.array([np.cos(th), np.sin(th), 0.0])
            m /= np.linalg.norm(m)
            assert (b @ m).min() - (a @ m).max() <= res[2] + 1e-15
    rf = fast_common_plane(
        a,
        b,
        a.mean(0),
        b.mean(0),
        fa,
        fb,
        a[ea[:, 1]] - a[ea[:, 0]],
        b[eb[:, 1]] - b[eb[:, 0]],
        Z3,
        Z3,
        False,
        1.0,
    )
    assert rf[2] == pytest.approx(gref, abs=1e-12)


def test_ctol_early_exit():
    a = box([0, 0, 0], [1, 1, 1])
    ctol = 0.01
    # just separated: gap 1.0001 * ctol -> stops early, reports a gap > ctol (<= the true gap)
    g = 1.0001 * ctol
    b = box([0.9, 0.0, 1 + g], [1.9, 1, 2 + g])
    res = cundall(a, b, ctol=ctol)
    assert ctol < res[2] <= g + 1e-15
    check_plane(res, a, b)
    assert np.allclose(res[1], (a[np.argmax(a @ res[0])] + b[np.argmin(b @ res[0])]) / 2)
    # just inside ctol: full search, exact gap
    g = 0.9999 * ctol
    b = box([0.9, 0.0, 1 + g], [1.9, 1, 2 + g])
    res = cundall(a, b, ctol=ctol)
    assert res[2] == pytest.approx(g, abs=EXACT)
    rf = fast_common_plane(
        a, b, a.mean(0), b.mean(0), BOX_N, BOX_N, np.eye(3), np.eye(3), Z3, Z3, False, ctol
    )
    assert rf[2] == pytest.approx(g, abs=EXACT)


def test_cold_start_iterations():
    a = box([0, 0, 0], [1, 1, 1])
    b = box([0.3, 0.2, 1.001], [1.1, 0.9, 1.6]) @ rot([1, 1, 0], 0.05).T
    it = cundall(a, b)[5]
    assert 9 <= it <= 60


def test_type_codes():
    assert type_code(1, 1) != type_code(1, 2)
    assert type_code(1, 5) == type_code(7, 1) == VERTEX_FACE
    assert type_code(2, 2) == EDGE_EDGE
    assert type_code(3, 4) == FACE_FACE
    assert type_code(0, 4) == 0
    assert len(set(CONTACT_TYPE_NAMES)) == 7


# ---------------------------------------------------------------- random polyhedra
def _random_pairs(count, seed=1):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        polys = []
        for _ in range(2):
            p = rng.normal(size=(int(rng.integers(6, 14)), 3))
            p /= np.linalg.norm(p, axis=1)[:, None]
            polys.append(p * rng.uniform(0.5, 1.5, 3))
        pa, pb = polys
        pb = pb @ rand_rot(rng).T
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        pb = pb + ((pa @ u).max() - (pb @ u).min() + rng.uniform(-0.4, 0.3)) * u
        out.append((pa, pb))
    return out


def test_fcp_and_cundall_on_random_polyhedra():
    """FCP is exact on every pair; Cundall (+ pdem ridge steps) on every separated pair.

    Overlapping pairs are multimodal: Cundall's local search may stop at a local optimum
    (never above the exact value); it must agree on most of them.
    """
    n_sep = n_ovl = agree_ovl = 0
    for va, vb in _random_pairs(50):
        fa, eai = hull(va)
        fb, ebi = hull(vb)
        ea = va[eai[:, 1]] - va[eai[:, 0]]
        eb = vb[ebi[:, 1]] - vb[ebi[:, 0]]
        gref, nref = reference_gap(va, vb, fa, fb, eai, ebi)
        ca, cb = va.mean(0), vb.mean(0)
        rf = fast_common_plane(va, vb, ca, cb, fa, fb, ea, eb, Z3, Z3, False, 10.0)
        check_plane(rf, va, vb)
        assert rf[2] == pytest.approx(gref, abs=1e-12)
        rc = common_plane(va, vb, ca, cb, Z3, Z3, False, 10.0, KMAX, KMIN, SNAP)
        check_plane(rc, va, vb)
        assert rc[2] <= gref + 1e-12
        same = abs(rc[2] - gref) < 1e-9 and math.acos(min(1.0, rc[0] @ rf[0])) < KMIN
        if gref > 0:
            n_sep += 1
            assert same
        else:
            n_ovl += 1
            agree_ovl += same
    assert n_sep >= 15 and n_ovl >= 10
    assert agree_ovl >= 0.8 * n_ovl
