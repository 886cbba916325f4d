"""The fast common plane gives the same bits as the plain algorithm it was optimised from.

:func:`pdem.contact.fast_common_plane.fast_common_plane` rejects candidates with extra hint
pairs (the last rejection's witness), without early exits inside the support scans, and with a
pre-test on the unnormalised candidate against a rounding margin (``_consider``). None of these
may change a result bit: the plane normal, point, gap, d_a, d_b and the candidate count must
equal those of the plain algorithm (a verbatim copy of the kernel before the optimisation,
below), on random convex polyhedra and on the cube-stack regime (nearly aligned cubes at a tiny
gap or overlap across a face, an edge or a corner), translated far from the origin and scaled,
cold and warm started.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from test_common_plane import box, hull, rand_rot, rot

from pdem.contact.common_plane import finish_plane, initial_plane, support_gap
from pdem.contact.fast_common_plane import fast_common_plane

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_INF = np.inf
_MAX_TIES = 4
_MAX_ROUNDS = 32


@numba.njit(cache=False)
def _ref_consider(va, vb, m0, m1, m2, state):
    s = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    if not (s > 0.0):
        return False
    m0 /= s
    m1 /= s
    m2 /= s
    ia = int(state[6])
    ib = int(state[7])
    ok, mxa, mnb, ka, kb = support_gap(va, vb, m0, m1, m2, ia, ib, state[3])
    if ok:
        state[0] = m0
        state[1] = m1
        state[2] = m2
        state[3] = mnb - mxa
        state[4] = mxa
        state[5] = mnb
        state[6] = ka
        state[7] = kb
    return ok


@numba.njit(cache=False)
def reference_fcp(va, vb, ca, cb, fa_normals, fb_normals, ea, eb, n_in, p_in, warm, ctol):
    """The FCP of a0b04b7 (state array, one hint pair, normalised before every test)."""
    state = np.empty(8)
    n0, n1, n2, c = initial_plane(ca, cb, n_in, p_in, warm)
    ok, mxa, mnb, ka, kb = support_gap(va, vb, n0, n1, n2, 0, 0, -_INF)
    state[0] = n0
    state[1] = n1
    state[2] = n2
    state[3] = mnb - mxa
    state[4] = mxa
    state[5] = mnb
    state[6] = ka
    state[7] = kb
    iters = 1
    early = state[3] > ctol

    # face normals of A (B beyond A's face) and of B (reversed)
    if not early:
        for f in range(fa_normals.shape[0]):
            _ref_consider(va, vb, fa_normals[f, 0], fa_normals[f, 1], fa_normals[f, 2], state)
            iters += 1
            if state[3] > ctol:
                early = True
                break
    if not early:
        for f in range(fb_normals.shape[0]):
            _ref_consider(va, vb, -fb_normals[f, 0], -fb_normals[f, 1], -fb_normals[f, 2], state)
            iters += 1
            if state[3] > ctol:
                early = True
                break
    # edge-edge cross products, both signs
    if not early:
        for i in range(ea.shape[0]):
            a0, a1, a2 = ea[i, 0], ea[i, 1], ea[i, 2]
            aa = a0 * a0 + a1 * a1 + a2 * a2
            for j in range(eb.shape[0]):
                b0, b1, b2 = eb[j, 0], eb[j, 1], eb[j, 2]
                m0 = a1 * b2 - a2 * b1
                m1 = a2 * b0 - a0 * b2
                m2 = a0 * b1 - a1 * b0
                mm = m0 * m0 + m1 * m1 + m2 * m2
                if mm <= 1e-24 * aa * (b0 * b0 + b1 * b1 + b2 * b2):
                    continue  # parallel edges: no plane defined
                _ref_consider(va, vb, m0, m1, m2, state)
                _ref_consider(va, vb, -m0, -m1, -m2, state)
                iters += 2
                if state[3] > ctol:
                    early = True
                    break
            if early:
                break

    # separated blocks: FCP types a and d from the nearest vertices, iterated
    if not early and state[3] > 0.0:
        scale = 0.0
        for i in range(va.shape[0]):
            for k in range(3):
                scale = max(scale, abs(va[i, k] - ca[k]))
        for j in range(vb.shape[0]):
            for k in range(3):
                scale = max(scale, abs(vb[j, k] - cb[k]))
        tie = 1e-9 * scale
        tia = np.empty(_MAX_TIES, np.int64)
        tib = np.empty(_MAX_TIES, np.int64)
        for _round in range(_MAX_ROUNDS):
            improved = False
            n0, n1, n2 = state[0], state[1], state[2]
            # nearest vertices of the current best plane (up to _MAX_TIES each)
            nta = 0
            for i in range(va.shape[0]):
                d = va[i, 0] * n0 + va[i, 1] * n1 + va[i, 2] * n2
                if d >= state[4] - tie and nta < _MAX_TIES:
                    tia[nta] = i
                    nta += 1
            ntb = 0
            for j in range(vb.shape[0]):
                d = vb[j, 0] * n0 + vb[j, 1] * n1 + vb[j, 2] * n2
                if d <= state[5] + tie and ntb < _MAX_TIES:
                    tib[ntb] = j
                    ntb += 1
            for ti in range(nta):
                i = tia[ti]
                for tj in range(ntb):
                    j = tib[tj]
                    d0 = vb[j, 0] - va[i, 0]
                    d1 = vb[j, 1] - va[i, 1]
                    d2 = vb[j, 2] - va[i, 2]
                    if _ref_consider(va, vb, d0, d1, d2, state):  # type a
                        improved = True
                    iters += 1
                    for e in range(ea.shape[0] + eb.shape[0]):  # type d
                        if e < ea.shape[0]:
                            e0, e1, e2 = ea[e, 0], ea[e, 1], ea[e, 2]
                        else:
                            r = e - ea.shape[0]
                            e0, e1, e2 = eb[r, 0], eb[r, 1], eb[r, 2]
                        ee = e0 * e0 + e1 * e1 + e2 * e2
                        if ee <= 0.0:
                            continue
                        t = (d0 * e0 + d1 * e1 + d2 * e2) / ee
                        if _ref_consider(va, vb, d0 - t * e0, d1 - t * e1, d2 - t * e2, state):
                            improved = True
                        iters += 1
                    if state[3] > ctol:
                        break
                if state[3] > ctol:
                    break
            if not improved or state[3] > ctol:
                break

    n, p, gap, da, db = finish_plane(
        va, vb, state[0], state[1], state[2], c, state[4], state[5], int(state[6]), int(state[7])
    )
    return n, p, gap, da, db, iters


def _same(va, vb, fa, fb, ea, eb, n_in, p_in, warm, ctol):
    ca = va.mean(0)
    cb = vb.mean(0)
    got = fast_common_plane(va, vb, ca, cb, fa, fb, ea, eb, n_in, p_in, warm, ctol)
    ref = reference_fcp(va, vb, ca, cb, fa, fb, ea, eb, n_in, p_in, warm, ctol)
    for g, r in zip(got, ref, strict=True):
        assert np.asarray(g).tobytes() == np.asarray(r).tobytes(), (got, ref)
    return ref


def _edges(v, idx):
    return np.ascontiguousarray(v[idx[:, 1]] - v[idx[:, 0]])


_BOX_EDGES = np.array([[0, 4], [0, 2], [0, 1]])  # box(): x, y, z edges from vertex 0
_BOX_N = np.vstack([np.eye(3), -np.eye(3)])


@st.composite
def polyhedra_pairs(draw):
    """Two random convex polyhedra (6-13 vertices on scaled spheres), B placed along a random
    direction at a gap or overlap in [-0.4, 0.3], scaled and translated as a whole."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    polys = []
    for _ in range(2):
        p = rng.normal(size=(int(rng.integers(6, 14)), 3))
        p /= np.linalg.norm(p, axis=1)[:, None]
        polys.append(p * rng.uniform(0.5, 1.5, 3))
    pa, pb = polys
    pb = pb @ rand_rot(rng).T
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    gap = draw(st.one_of(st.floats(-0.4, 0.3), st.sampled_from([0.0, 1e-9, -1e-9, 1e-6])))
    pb = pb + ((pa @ u).max() - (pb @ u).min() + gap) * u
    return _placed(draw, rng, pa, pb)


def _placed(draw, rng, pa, pb):
    scale = draw(st.sampled_from([1.0, 1e-3, 0.37, 25.0, 1e3]))
    shift = rng.normal(size=3) * draw(st.sampled_from([0.0, 1.0, 30.0, 1e4]))
    return pa * scale + shift, pb * scale + shift


@st.composite
def cube_pairs(draw):
    """Unit cubes as in the stacked cube scene: B a face, edge or corner neighbour of A, both
    slightly rotated, at a tiny gap or overlap (many tied candidates and nearest vertices)."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    off = np.array(draw(st.sampled_from([(1, 0, 0), (0, 0, 1), (1, 1, 0), (0, 1, 1), (1, 1, 1),
                                         (-1, 1, 0), (1, -1, -1)])), float)
    tilt = draw(st.sampled_from([0.0, 1e-9, 1e-6, 1e-3]))
    gap = draw(st.sampled_from([0.0, 1e-12, 1e-9, -1e-9, 1e-6, -1e-5, 3e-3]))
    a = box([-0.5] * 3, [0.5] * 3)
    ra = rot(rng.normal(size=3), tilt * rng.uniform(-1, 1))
    rb = rot(rng.normal(size=3), tilt * rng.uniform(-1, 1))
    pa = a @ ra.T
    pb = a @ rb.T + off * (1.0 + gap)
    return _placed(draw, rng, pa, pb) + (ra, rb)


@settings(max_examples=300, deadline=None)
@given(polyhedra_pairs(), st.booleans(), st.sampled_from([10.0, 0.02, 1e-3, 0.0]))
def test_same_bits_on_random_polyhedra(pair, warm, ctol):
    va, vb = pair
    fa, eai = hull(va)
    fb, ebi = hull(vb)
    ea, eb = _edges(va, eai), _edges(vb, ebi)
    n_in = np.zeros(3)
    p_in = np.zeros(3)
    if warm:  # a previous plane a little off the optimum
        ref = reference_fcp(va, vb, va.mean(0), vb.mean(0), fa, fb, ea, eb, n_in, p_in, False,
                            10.0)
        n_in = ref[0] + 0.01 * np.array([0.3, -0.2, 0.1])
        n_in /= np.linalg.norm(n_in)
        p_in = ref[1].copy()
    _same(va, vb, fa, fb, ea, eb, n_in, p_in, warm, ctol)


@settings(max_examples=300, deadline=None)
@given(cube_pairs(), st.booleans(), st.sampled_from([0.02, 10.0]))
def test_same_bits_on_cube_neighbours(pair, warm, ctol):
    va, vb, ra, rb = pair
    fa = np.ascontiguousarray(_BOX_N @ ra.T)
    fb = np.ascontiguousarray(_BOX_N @ rb.T)
    ea, eb = _edges(va, _BOX_EDGES), _edges(vb, _BOX_EDGES)
    d = vb.mean(0) - va.mean(0)
    n_in = d / np.linalg.norm(d)
    if warm:  # the stack's warm start: the face normal towards B, as a previous plane
        k = int(np.argmax(np.abs(d)))
        n_in = np.zeros(3)
        n_in[k] = math.copysign(1.0, d[k])
    p_in = 0.5 * (va.mean(0) + vb.mean(0))
    _same(va, vb, fa, fb, ea, eb, n_in, p_in, warm, ctol)
