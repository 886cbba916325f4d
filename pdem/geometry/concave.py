"""Concave polyhedra as unions of convex pieces (a block given by its faces that is not convex).

The decomposition cuts the polyhedron's convex hull by the plane of every face that is not on
the hull, and keeps the cells of that arrangement that lie inside the polyhedron. No face of
the polyhedron crosses the interior of a cell (a face on the hull bounds it, any other face
lies in one of the cutting planes), so every cell is wholly inside or wholly outside; the
inside test of one interior point (the winding number) decides. The pieces tile the
polyhedron exactly (their volumes add up to its volume, checked). The count grows with the
number of concave face planes, which in blocks users give (an L, a notch, a stepped block) is
a handful.
"""

from __future__ import annotations

import numpy as np

from pdem.geometry.builders import from_vertices
from pdem.geometry.cutting import cut_blocks
from pdem.geometry.errors import GeometryError
from pdem.geometry.hull import default_tolerance
from pdem.geometry.polyhedron import ConvexPolyhedron, newell_normal


def _faces_checked(v: np.ndarray, faces) -> list[np.ndarray]:
    """Face index arrays, checked to form a closed two-manifold with consistent orientation;
    oriented outward (all reversed if the input was inward)."""
    out = []
    for i, f in enumerate(faces):
        f = np.asarray(f, np.int64)
        if f.ndim != 1 or len(f) < 3:
            raise GeometryError(f"face {i} needs at least 3 vertex ids")
        if f.min() < 0 or f.max() >= len(v):
            raise GeometryError(f"face {i} names a vertex outside 0..{len(v) - 1}")
        if len(set(f.tolist())) != len(f):
            raise GeometryError(f"face {i} repeats a vertex")
        out.append(f)
    edges: dict[tuple[int, int], int] = {}
    for i, f in enumerate(out):
        for a, b in zip(f, np.roll(f, -1), strict=True):
            key = (int(a), int(b))
            if key in edges:
                raise GeometryError(f"faces {edges[key]} and {i} run along edge {key} the same "
                                    "way: faces must all be ordered counter-clockwise seen from "
                                    "outside (or all clockwise)")
            edges[key] = i
    for (a, b), i in edges.items():
        if (b, a) not in edges:
            raise GeometryError(f"edge ({a}, {b}) of face {i} has no neighbouring face: the "
                                "surface is not closed")
    if signed_volume(v, out) < 0.0:
        out = [f[::-1] for f in out]
    return out


def signed_volume(v: np.ndarray, faces) -> float:
    """Volume enclosed by the faces (positive when they are ordered outward)."""
    vol = 0.0
    for f in faces:
        p0 = v[f[0]]
        for k in range(1, len(f) - 1):
            vol += float(np.dot(p0, np.cross(v[f[k]], v[f[k + 1]])))
    return vol / 6.0


def winding_number(v: np.ndarray, faces, point: np.ndarray) -> float:
    """Winding number of the closed surface about ``point`` (1 inside, 0 outside), from the
    solid angles of the fan triangles (Van Oosterom and Strackee)."""
    total = 0.0
    for f in faces:
        a = v[f[0]] - point
        for k in range(1, len(f) - 1):
            b = v[f[k]] - point
            c = v[f[k + 1]] - point
            la, lb, lc = np.linalg.norm(a), np.linalg.norm(b), np.linalg.norm(c)
            num = float(np.dot(a, np.cross(b, c)))
            den = la * lb * lc + np.dot(a, b) * lc + np.dot(a, c) * lb + np.dot(b, c) * la
            total += 2.0 * np.arctan2(num, den)
    return total / (4.0 * np.pi)


def convex_pieces(vertices, faces, rel_tol: float = 1e-9) -> list[ConvexPolyhedron]:
    """Convex pieces tiling the closed polyhedron ``faces`` over ``vertices`` (one piece, the
    polyhedron itself, when it is convex)."""
    v = np.asarray(vertices, np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
        raise GeometryError(f"vertices must be finite, shape (n, 3); got {v.shape}")
    fs = _faces_checked(v, faces)
    volume = signed_volume(v, fs)
    size = float(np.ptp(v, axis=0).max())
    tol = max(rel_tol * size, default_tolerance(v))
    if not volume > tol * size * size:
        raise GeometryError(f"the faces enclose no volume ({volume:.3g})")
    planes = []
    for i, f in enumerate(fs):
        n = newell_normal(v[f])
        norm = np.linalg.norm(n)
        if norm == 0.0:
            raise GeometryError(f"face {i} has no area")
        n = n / norm
        d = float(np.mean(v[f] @ n))
        if np.abs(v[f] @ n - d).max() > 1e3 * tol:
            raise GeometryError(f"face {i} is not planar (a vertex lies "
                                f"{np.abs(v[f] @ n - d).max():.3g} off its plane)")
        if (v @ n - d).max() > 1e3 * tol:  # not a supporting plane: the block is concave here
            if not any(np.allclose(n, m) and abs(d - e) <= 1e3 * tol for m, e in planes):
                planes.append((n, d))
    hull = from_vertices(v)
    if not planes:
        return [hull]
    pieces = [hull]
    for n, d in planes:
        pieces, _ = cut_blocks(pieces, -1, n, [d], tol=0.0)
    inside = [p for p in pieces if winding_number(v, fs, _interior_point(p)) > 0.5]
    got = sum(p.volume for p in inside)
    if abs(got - volume) > 1e-6 * volume:
        raise GeometryError(f"could not decompose into convex pieces (pieces hold {got:.6g} of "
                            f"{volume:.6g}); is the surface self-intersecting?")
    return inside


def _interior_point(p: ConvexPolyhedron) -> np.ndarray:
    return np.asarray(p.centroid)
