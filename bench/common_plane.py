"""Time Cundall's common plane against the fast common plane (FCP), in microseconds per call.

Run: ``python bench/common_plane.py``. Cases: unit-cube pairs (face-face, edge-edge,
vertex-face, separated 0.05) and pairs of ~20-vertex random convex polyhedra (gap in
[-0.3, 0.3]); cold start (new contact) and warm start from the converged plane.
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from pdem.contact.common_plane import K_MAX_DEFAULT, K_MIN_DEFAULT, common_plane
from pdem.contact.fast_common_plane import fast_common_plane

Z3 = np.zeros(3)


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
    normals, tris = [], []
    for i, j, k in itertools.combinations(range(len(pts)), 3):
        m = np.cross(pts[j] - pts[i], pts[k] - pts[i])
        s = np.linalg.norm(m)
        if s < 1e-12:
            continue
        m /= s
        d = (pts - pts[i]) @ m
        if np.all(d <= tol) or np.all(d >= -tol):
            normals.append(m if np.all(d <= tol) else -m)
            tris.append((i, j, k))
    edges = sorted({(min(a, b), max(a, b)) for t in tris for a, b in itertools.combinations(t, 2)})
    e = np.array(edges)
    return np.array(normals), pts[e[:, 1]] - pts[e[:, 0]]


def cube_case(rng, kind):
    a = np.array(list(itertools.product((0.0, 1.0), repeat=3)))
    ra = np.eye(3)
    if kind == "face-face":
        rb, off = np.eye(3), np.array([0.2, 0.1, 1.0 - 1e-3])
    elif kind == "separated":
        rb, off = np.eye(3), np.array([0.2, 0.1, 1.05])
    elif kind == "edge-edge":
        ra = np.array(
            [
                [1, 0, 0],
                [0, 0.7071067811865476, -0.7071067811865476],
                [0, 0.7071067811865476, 0.7071067811865476],
            ]
        )
        rb = np.array(
            [
                [0.7071067811865476, 0, 0.7071067811865476],
                [0, 1, 0],
                [-0.7071067811865476, 0, 0.7071067811865476],
            ]
        )
        off = np.array([0.0, 0.0, 1.414 - 1e-3])
    else:  # vertex-face
        rb = rand_rot(rng)
        off = None
    a = (a - 0.5) @ ra.T
    b = (np.array(list(itertools.product((0.0, 1.0), repeat=3))) - 0.5) @ rb.T
    if off is None:
        b = b + [0.1, 0.05, 0.5 - b[:, 2].min() - 1e-3]
    else:
        b = b + off
    fa = np.vstack([np.eye(3), -np.eye(3)]) @ ra.T
    fb = np.vstack([np.eye(3), -np.eye(3)]) @ rb.T
    return a, b, fa, fb, ra.T.copy(), rb.T.copy()


def poly_case(rng, nv=20):
    polys = []
    for _ in range(2):
        p = rng.normal(size=(nv, 3))
        p /= np.linalg.norm(p, axis=1)[:, None]
        polys.append(p * rng.uniform(0.7, 1.3, 3))
    a, b = polys
    b = b @ rand_rot(rng).T
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    b = b + ((a @ u).max() - (b @ u).min() + rng.uniform(-0.3, 0.3)) * u
    fa, ea = hull(a)
    fb, eb = hull(b)
    return a, b, fa, fb, ea, eb


def timeit(fn, args, reps):
    fn(*args)
    t0 = time.perf_counter()
    for _ in range(reps):
        fn(*args)
    return (time.perf_counter() - t0) / reps * 1e6


def run(cases, label, reps=200):
    tc = tf = tcw = tfw = 0.0
    its = []
    km, kn = K_MAX_DEFAULT, K_MIN_DEFAULT
    for a, b, fa, fb, ea, eb in cases:
        ca, cb = a.mean(0), b.mean(0)
        cold_c = (a, b, ca, cb, Z3, Z3, False, 10.0, km, kn, 1e-12)
        cold_f = (a, b, ca, cb, fa, fb, ea, eb, Z3, Z3, False, 10.0)
        r = common_plane(*cold_c)
        its.append(r[5])
        n, p = r[0], r[1]
        warm_c = (a, b, ca, cb, n, p, True, 10.0, km, kn, 1e-12)
        warm_f = (a, b, ca, cb, fa, fb, ea, eb, n, p, True, 10.0)
        tc += timeit(common_plane, cold_c, reps)
        tf += timeit(fast_common_plane, cold_f, reps)
        tcw += timeit(common_plane, warm_c, reps)
        tfw += timeit(fast_common_plane, warm_f, reps)
    m = len(cases)
    print(
        f"{label:38s} cold: Cundall {tc / m:7.2f} us  FCP {tf / m:7.2f} us | "
        f"warm: Cundall {tcw / m:6.2f} us  FCP {tfw / m:7.2f} us | "
        f"Cundall cold cycles {min(its)}-{max(its)} (mean {np.mean(its):.1f})"
    )


def main():
    rng = np.random.default_rng(0)
    for kind in ("face-face", "edge-edge", "vertex-face", "separated"):
        run([cube_case(rng, kind) for _ in range(5)], f"cubes {kind} (8 v, 3 edge dirs)")
    cases = [poly_case(rng) for _ in range(20)]
    ne = np.mean([len(c[4]) for c in cases])
    nf = np.mean([len(c[2]) for c in cases])
    run(cases, f"20-vertex polyhedra ({nf:.0f} f, {ne:.0f} e)", reps=50)


if __name__ == "__main__":
    main()
