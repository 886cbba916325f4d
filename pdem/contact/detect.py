"""Contact geometry update: common planes, contact types and sub-contacts with history.

Run every ``detect_every`` steps and whenever contacts were created: each contact's common plane
is re-optimised (warm start), contacts whose gap exceeds CTOL are deleted, and the sub-contacts
are rebuilt from the current contact region. History (shear force, shear displacement,
dilation, failure state) moves from the old sub-contacts to the new ones by nearest position in
A's body frame: a sub-contact that persists keeps its values exactly, a new corner takes the
shear stress of its nearest predecessor, so the contact's shear resistance is continuous as the
region changes (3DEC reallocates sub-contact forces for the same reason).
"""

from __future__ import annotations

import numpy as np

from ..jit import kernel
from .common_plane import common_plane
from .fast_common_plane import fast_common_plane
from .joint import FAILED
from .subcontacts import POLYGON, contact_region

CUNDALL = 0
FAST = 1
ALGORITHMS = {"cundall": CUNDALL, "fast": FAST}

K_MAX = np.tan(np.radians(5.0))
K_MIN = np.tan(np.radians(0.01))


@kernel
def update_verts_world(x, R, vert_start, verts_local, verts_world):
    """World vertices from the pose (no drift: always from the body-frame geometry)."""
    for b in range(vert_start.shape[0] - 1):
        for v in range(vert_start[b], vert_start[b + 1]):
            for k in range(3):
                verts_world[v, k] = x[b, k] + R[b, k, 0] * verts_local[v, 0] + \
                    R[b, k, 1] * verts_local[v, 1] + R[b, k, 2] * verts_local[v, 2]


@kernel
def _world_normals(R, b, face_start, normals_local):
    """Rows face_start[b]..face_start[b+1] of body-frame vectors, rotated to the world."""
    f0 = face_start[b]
    f1 = face_start[b + 1]
    out = np.empty((f1 - f0, 3))
    for f in range(f0, f1):
        for k in range(3):
            out[f - f0, k] = R[b, k, 0] * normals_local[f, 0] + R[b, k, 1] * normals_local[f, 1] \
                + R[b, k, 2] * normals_local[f, 2]
    return out


@kernel
def find_plane(a, b, x, R, vert_start, verts_world, face_start, normals_local, edir_start,
               edirs, n_in, p_in, warm, ctol, algorithm, snap_tol):
    """Common plane of blocks a, b: (n, p, gap). Cundall's iteration (eqs. 5-10) or the fast
    common plane (DDA §3), warm-started from an existing contact's plane for Cundall."""
    va = verts_world[vert_start[a]:vert_start[a + 1]]
    vb = verts_world[vert_start[b]:vert_start[b + 1]]
    if algorithm == FAST:
        n, p, gap, _, _, _ = fast_common_plane(
            va, vb, x[a], x[b],
            _world_normals(R, a, face_start, normals_local),
            _world_normals(R, b, face_start, normals_local),
            _world_normals(R, a, edir_start, edirs),
            _world_normals(R, b, edir_start, edirs), n_in, p_in, warm, ctol)
    else:
        n, p, gap, _, _, _ = common_plane(va, vb, x[a], x[b], n_in, p_in, warm, ctol, K_MAX,
                                          K_MIN, snap_tol)
    return n, p, gap


@kernel
def refresh_contacts(x, R, vert_start, verts_world, face_start, normals_local, edir_start, edirs,
                     point_area, c_ia, c_ib, c_normal, c_point, c_gap, c_ctype, c_warm,
                     old_start, old_pa, old_area, old_un, old_fs, old_us, old_dil, old_state,
                     todo, ctol, touch_frac, algorithm, snap_tol):
    """Re-detect every contact; returns (keep, new_start, pa, area, un, fs, us, dil, state).

    ``point_area[b]`` is the area given to each vertex/edge sub-contact involving block b (the
    smaller of the two blocks' values is used); ``touch_frac`` * CTOL is the distance within
    which a vertex counts as touching the common plane. Contacts with ``todo[c] == 0`` keep
    their plane and sub-contacts unchanged (only new contacts need detecting between the
    periodic geometry updates).
    """
    nc = c_ia.shape[0]
    cap = 0
    for c in range(nc):
        cap += (old_start[c + 1] - old_start[c]) + (vert_start[c_ia[c] + 1] - vert_start[c_ia[c]]) + \
            (vert_start[c_ib[c] + 1] - vert_start[c_ib[c]]) + 1
    keep = np.zeros(nc, np.uint8)
    counts = np.zeros(nc, np.int64)
    pa = np.empty((cap, 3))
    area = np.empty(cap)
    un = np.empty(cap)
    fs = np.zeros((cap, 3))
    us = np.zeros((cap, 3))
    dil = np.zeros(cap)
    state = np.zeros(cap, np.int64)
    pos = 0
    base = np.empty(nc, np.int64)
    for c in range(nc):
        a = c_ia[c]
        b = c_ib[c]
        base[c] = pos
        if todo[c] == 0:
            keep[c] = 1
            k = old_start[c + 1] - old_start[c]
            for i in range(k):
                o = old_start[c] + i
                s = pos + i
                pa[s] = old_pa[o]
                area[s] = old_area[o]
                un[s] = old_un[o]
                fs[s] = old_fs[o]
                us[s] = old_us[o]
                dil[s] = old_dil[o]
                state[s] = old_state[o]
            counts[c] = k
            pos += k
            continue
        n, p, gap = find_plane(a, b, x, R, vert_start, verts_world, face_start, normals_local,
                               edir_start, edirs, c_normal[c], c_point[c], c_warm[c] == 1, ctol,
                               algorithm, snap_tol)
        if gap > ctol:
            continue
        keep[c] = 1
        c_normal[c] = n
        c_point[c] = p
        c_gap[c] = gap
        c_warm[c] = 1
        va = verts_world[vert_start[a]:vert_start[a + 1]]
        vb = verts_world[vert_start[b]:vert_start[b + 1]]
        pts, ovl, ar, kind, e1, e2, cnt = contact_region(va, vb, n, p, touch_frac * ctol)
        c_ctype[c] = min(cnt[0], 3) * 4 + min(cnt[1], 3)
        apt = min(point_area[a], point_area[b])
        k = pts.shape[0]
        o0 = old_start[c]
        o1 = old_start[c + 1]
        for i in range(k):
            s = pos + i
            wx = p[0] + pts[i, 0] * e1[0] + pts[i, 1] * e2[0]
            wy = p[1] + pts[i, 0] * e1[1] + pts[i, 1] * e2[1]
            wz = p[2] + pts[i, 0] * e1[2] + pts[i, 1] * e2[2]
            dx = wx - x[a, 0]
            dy = wy - x[a, 1]
            dz = wz - x[a, 2]
            # into A's body frame: R^T d
            for m in range(3):
                pa[s, m] = R[a, 0, m] * dx + R[a, 1, m] * dy + R[a, 2, m] * dz
            area[s] = ar[i] if kind == POLYGON else apt
            un[s] = ovl[i]
            # history from the nearest old sub-contact of this contact
            best = -1
            bd = np.inf
            for o in range(o0, o1):
                d = (old_pa[o, 0] - pa[s, 0]) ** 2 + (old_pa[o, 1] - pa[s, 1]) ** 2 + \
                    (old_pa[o, 2] - pa[s, 2]) ** 2
                if d < bd:
                    bd = d
                    best = o
            if best >= 0:
                ratio = area[s] / old_area[best] if old_area[best] > 0.0 else 1.0
                for m in range(3):
                    fs[s, m] = old_fs[best, m] * ratio
                    us[s, m] = old_us[best, m]
                dil[s] = old_dil[best]
                state[s] = old_state[best]
            elif ovl[i] < 0.0:
                # a joint that forms open has no bond: no tension or cohesion
                state[s] = FAILED
        counts[c] = k
        pos += k
    new_start = np.zeros(nc + 1, np.int64)
    # compact, dropping deleted contacts' (empty) ranges
    tot = 0
    for c in range(nc):
        new_start[c] = tot
        tot += counts[c]
    new_start[nc] = tot
    # sub-contacts were written at base[c] == new_start[c] already (sequential fill)
    return keep, new_start, pa[:tot], area[:tot], un[:tot], fs[:tot], us[:tot], dil[:tot], \
        state[:tot]
