"""Contact geometry update: common planes, contact types and sub-contacts with history.

Run every ``detect_every`` steps and whenever contacts were created: each contact's common plane
is re-optimised (warm start), contacts whose gap exceeds CTOL are deleted, and the sub-contacts
are rebuilt from the current contact region. History (shear force, shear displacement,
dilation, failure state) moves from the old sub-contacts to the new ones by nearest position in
A's body frame: a sub-contact that persists keeps its values exactly, a new corner takes the
shear stress of its nearest predecessor, so the contact's shear resistance is continuous as the
region changes (3DEC reallocates sub-contact forces for the same reason). The overlaps are
re-read from the geometry, but each contact's spring energy (normal and shear) is carried over
unchanged (``carry_spring_energy``): a geometry update must not put energy into the springs
that a collision would then release as block speed (issue 16).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..jit import access, inline_kernel, kernel
from .algorithms import find_plane, uses_face_normals
from .common_plane import type_code
from .laws import FAILED
from .subcontacts import POLYGON, region_in, region_scratch

# The contact arrays the geometry update reads and writes.
# ``ia``/``ib`` are the bodies (block rows), ``ka``/``kb`` the convex pieces in contact.
Planes = namedtuple("Planes", "ia ib ka kb normal point gap ctype warm")


@inline_kernel
def _plane(a, b, shapes, R, scratch, n_in, p_in, warm, alg):
    """Common plane of convex pieces a and b. The algorithms that read world face normals
    and edge directions (:func:`.algorithms.uses_face_normals`) get the two pieces' rotated
    into ``scratch`` (:func:`plane_scratch`) here, per contact: an array of every piece's
    (~7 MB for 64,000 cubes) was the peak of the start's first update, the set-up's, and most
    of a periodic update's fixed cost when it re-detects a few contacts."""
    vs, fs, es = shapes.vert_start, shapes.face_start, shapes.edir_start
    va = shapes.verts_world[vs[a]:vs[a + 1]]
    vb = shapes.verts_world[vs[b]:vs[b + 1]]
    na, nb, ea, eb = scratch
    if uses_face_normals(alg):
        pb = shapes.piece_block
        _to_world(R, pb[a], shapes.normals_local, fs[a], fs[a + 1], na)
        _to_world(R, pb[b], shapes.normals_local, fs[b], fs[b + 1], nb)
        _to_world(R, pb[a], shapes.edirs_local, es[a], es[a + 1], ea)
        _to_world(R, pb[b], shapes.edirs_local, es[b], es[b + 1], eb)
    x = shapes.piece_x
    return find_plane(alg, va, vb, x[a], x[b], na[:fs[a + 1] - fs[a]], nb[:fs[b + 1] - fs[b]],
                      ea[:es[a + 1] - es[a]], eb[:es[b + 1] - es[b]], n_in, p_in, warm)


@inline_kernel
def _to_world(R, b, local, f0, f1, out):
    """``out[:f1 - f0]``: body-frame vectors ``local[f0:f1]`` of block b rotated to the
    world."""
    for f in range(f0, f1):
        for k in range(3):
            out[f - f0, k] = R[b, k, 0] * local[f, 0] + R[b, k, 1] * local[f, 1] \
                + R[b, k, 2] * local[f, 2]


@kernel
def plane_scratch(shapes):
    """Room for two pieces' world face normals and edge directions (:func:`_plane`)."""
    mf = 0
    me = 0
    for p in range(shapes.face_start.shape[0] - 1):
        mf = max(mf, shapes.face_start[p + 1] - shapes.face_start[p])
        me = max(me, shapes.edir_start[p + 1] - shapes.edir_start[p])
    return np.empty((mf, 3)), np.empty((mf, 3)), np.empty((me, 3)), np.empty((me, 3))


@kernel
def _grow(a, size):
    """``a`` enlarged to ``size`` rows (contents kept)."""
    out = np.empty((size,) + a.shape[1:], a.dtype)
    out[:a.shape[0]] = a
    return out


@inline_kernel
def _spring_sums(area, un, dil, fs):
    """(sum A (un + dil)^2 over compressed sub-contacts, sum |fs|^2 / A): a contact's normal
    and shear spring energies times 2 kn and 2 ks."""
    en = 0.0
    es = 0.0
    for s in range(area.shape[0]):
        a = area[s]
        if a > 0.0:
            d = un[s] + dil[s]
            if d > 0.0:
                en += a * d * d
            es += (fs[s, 0] ** 2 + fs[s, 1] ** 2 + fs[s, 2] ** 2) / a
    return en, es


@inline_kernel
def carry_spring_energy(old_area, old_un, old_dil, old_fs, area, un, dil, fs):
    """Scale one refreshed contact's new sub-contacts so that the geometry update neither
    stores nor releases spring energy (issue 16).

    The new sub-contacts take their overlap ``un`` from the geometry and their shear force from
    the nearest old sub-contact. Read as is, that re-tensions the springs whenever the region
    changes: an edge contact carried by two ``point_area`` springs that becomes a face contact
    (twenty times the area at the same overlap), a corner that appears already overlapped, an
    old shear force copied to several new corners, or, the other way, a compressed corner
    dropped from the region. A collision then pays the difference out as block speed (energy
    created) or it is lost. So the contact's normal-spring energy ``sum kn A (un + dil)^2 / 2``
    (compressed sub-contacts) and shear-spring energy ``sum |fs|^2 / (2 ks A)`` are each set
    back to their values before the update by scaling the compressions ``un + dil`` and the
    shear forces uniformly: the geometry gives the distribution over the region, the history
    its energy (``kn``, ``ks`` cancel in the ratios). A persistent sub-contact, whose geometric
    overlap equals its tracked one, is unchanged. Energy held by sub-contacts that are all
    open after the update cannot be carried and is released (lost).
    """
    en0, es0 = _spring_sums(old_area, old_un, old_dil, old_fs)
    en1, es1 = _spring_sums(area, un, dil, fs)
    if en1 > 0.0 and en1 != en0:
        f = np.sqrt(en0 / en1)
        for s in range(area.shape[0]):
            d = un[s] + dil[s]
            if d > 0.0:
                un[s] = f * d - dil[s]
    if es1 > 0.0 and es1 != es0:
        f = np.sqrt(es0 / es1)
        for s in range(area.shape[0]):
            for m in range(3):
                fs[s, m] *= f


@kernel
def _copy_rows(dst, d0, src, s0, s1):
    """``dst[d0:d0 + s1 - s0] = src[s0:s1]`` for C-ordered arrays of equal row width, as one
    slice of the flat arrays (numba copies that 2x faster than an indexed loop, 6x faster than
    a loop per row and column)."""
    w = 1
    for k in range(1, src.ndim):
        w *= src.shape[k]
    dst.reshape(-1)[d0 * w:(d0 + s1 - s0) * w] = src.reshape(-1)[s0 * w:s1 * w]


@kernel
def _same_layout(keep, new_start, old_start):
    """Whether an update kept every contact and each one's number of sub-contacts."""
    for c in range(keep.shape[0]):
        if keep[c] == 0 or new_start[c + 1] != old_start[c + 1]:
            return False
    return True


@kernel
def _new_subs(n, state_dtype_like, hist_width):
    """Empty sub-contact columns for ``n`` rows: (pa, area, un, fs, us, dil, state, hist)."""
    return (np.empty((n, 3)), np.empty(n), np.empty(n), np.empty((n, 3)), np.empty((n, 3)),
            np.empty(n), np.empty(n, state_dtype_like.dtype), np.empty((n, hist_width)))


# runs of fewer sub-contacts than this are copied row by row: a slice copy of each column
# costs ~100 ns before it moves a byte, and a periodic update that re-detects a few hundred
# scattered contacts copies as many short runs (8 columns each; 1.1 of the 3.6 ms of such
# an update of the 10³ cube stack went to those calls)
SHORT_RUN = 32


@inline_kernel
def _copy_subs(dst, d0, src, s0, s1):
    """Rows ``s0:s1`` of every sub-contact column of ``src`` to ``dst`` from row ``d0`` (both
    (pa, area, un, fs, us, dil, state, hist))."""
    if s1 - s0 >= SHORT_RUN:
        _copy_rows(dst[0], d0, src[0], s0, s1)
        _copy_rows(dst[1], d0, src[1], s0, s1)
        _copy_rows(dst[2], d0, src[2], s0, s1)
        _copy_rows(dst[3], d0, src[3], s0, s1)
        _copy_rows(dst[4], d0, src[4], s0, s1)
        _copy_rows(dst[5], d0, src[5], s0, s1)
        _copy_rows(dst[6], d0, src[6], s0, s1)
        _copy_rows(dst[7], d0, src[7], s0, s1)
        return
    pa, area, un, fs, us, dil, state, hist = dst
    spa, sarea, sun, sfs, sus, sdil, sstate, shist = src
    for s in range(s0, s1):
        d = d0 + s - s0
        for m in range(3):
            pa[d, m] = spa[s, m]
            fs[d, m] = sfs[s, m]
            us[d, m] = sus[s, m]
        area[d] = sarea[s]
        un[d] = sun[s]
        dil[d] = sdil[s]
        state[d] = sstate[s]
        for m in range(hist.shape[1]):
            hist[d, m] = shist[s, m]


# (the new sub-contact columns are returned: the caller puts them in the store, ``in_place``
# writes them over the old ones)
@access(reads="x R point_area ia ib ka kb normal point warm sc_pa sc_area sc_un sc_fs sc_us "
              "sc_dil sc_state sc_hist",
        writes="normal point gap ctype warm sc_pa sc_area sc_un sc_fs sc_us sc_dil sc_state "
               "sc_hist")
@kernel
def refresh_contacts(x, R, shapes, planes, old_start, old, todo, ctol, touch_frac, alg,
                     trim=True, in_place=False):
    """Re-detect contacts; returns (keep, new_start, pa, area, un, fs, us, dil, state, hist).

    ``shapes`` (:class:`pdem.model.blocks.Shapes`): ``point_area[b]`` is the area given to
    each vertex/edge sub-contact involving block b (the smaller of the two blocks' values is
    used). ``planes`` (:data:`Planes`) and ``old`` (:class:`pdem.model.contacts.Subs`, CSR
    ``old_start``) are the contacts before the update. ``touch_frac`` * CTOL is the distance
    within which a vertex counts as touching the common plane. Contacts with ``todo[c] == 0``
    keep their plane and sub-contacts unchanged (only new contacts need detecting between the
    periodic geometry updates). ``alg``: the common-plane algorithm (:mod:`.algorithms`).

    Two passes: the contacts to update write their new sub-contacts into side arrays (a few
    thousand rows at a periodic update); then the outputs are allocated at their exact size and
    filled from the side arrays and, for each run of untouched contacts, with one contiguous
    copy of their old rows. (One pass into arrays grown on demand re-copied everything when a
    refreshed face contact went from 4 sub-contacts to 8 and then trimmed the slack: ~40 ns per
    untouched sub-contact, 9 of the 13 ms of an update of the 20³ cube stack.) When every
    contact is updated (the first update) the side arrays are the outputs, trimmed to their
    size with ``trim``; without it they are views of the side arrays: while every large array
    is its own mapping (set-up, pdem.memory.map_large_blocks) the untouched slack was never
    faulted in and holds no memory, and the trimming copy would only add its size to the
    set-up's peak (~11 MB per rank for 64,000 cubes on 2 ranks, bench/setup.py).

    With ``in_place``, when no contact is deleted and every updated one keeps its number of
    sub-contacts (a resting stack's periodic update, most of the time), the updated rows are
    written over their old ones and the old columns are returned: no copy of the untouched
    sub-contacts, which cost ~0.5 ms a periodic update of the 10³ cube stack whatever it
    updated. The caller must not need the old rows after the call.
    """
    c_ia, c_ib, c_normal, c_point = planes.ia, planes.ib, planes.normal, planes.point
    c_ka, c_kb = planes.ka, planes.kb
    c_gap, c_ctype, c_warm = planes.gap, planes.ctype, planes.warm
    old_pa, old_area, old_un, old_fs = old.pa, old.area, old.un, old.fs
    old_us, old_dil, old_state, old_hist = old.us, old.dil, old.state, old.hist
    vert_start, verts_world, point_area = shapes.vert_start, shapes.verts_world, shapes.point_area
    nc = c_ia.shape[0]
    # side capacity: the updated contacts' old sub-contacts, a few for each new contact (none
    # before) and a little slack, grown on demand
    n_todo = 0
    n_new = 0
    cap = 64
    for c in range(nc):
        if todo[c] != 0:
            n_todo += 1
            k = old_start[c + 1] - old_start[c]
            cap += k + (k >> 1)
            if k == 0:
                n_new += 1
    cap += 4 * n_new
    keep = np.zeros(nc, np.uint8)
    # each contact's sub-contact count at c + 1, summed into the CSR start in place below (no
    # count array of its own: it would add to the start's first update, the set-up's peak)
    new_start = np.zeros(nc + 1, np.int64)
    # state: the store's dtype (uint8 bits)
    pa, area, un, fs, us, dil, state, hist = _new_subs(cap, old_state, old_hist.shape[1])
    scratch = plane_scratch(shapes)
    max_verts = 0
    for k in range(vert_start.shape[0] - 1):
        max_verts = max(max_verts, vert_start[k + 1] - vert_start[k])
    region = region_scratch(max_verts)
    pos = 0
    for c in range(nc):
        a = c_ia[c]
        b = c_ib[c]
        if todo[c] == 0:
            keep[c] = 1
            new_start[c + 1] = old_start[c + 1] - old_start[c]
            continue
        ka = c_ka[c]
        kb = c_kb[c]
        n, p, gap = _plane(ka, kb, shapes, R, scratch, c_normal[c], c_point[c], c_warm[c] == 1,
                           alg)
        if gap > ctol:
            continue
        keep[c] = 1
        c_normal[c] = n
        c_point[c] = p
        c_gap[c] = gap
        c_warm[c] = 1
        va = verts_world[vert_start[ka]:vert_start[ka + 1]]
        vb = verts_world[vert_start[kb]:vert_start[kb + 1]]
        pts, ovl, ar, kind, e, cnt = region_in(va, vb, n, p, touch_frac * ctol, region)
        c_ctype[c] = type_code(cnt[0], cnt[1])  # Table 1
        apt = min(point_area[a], point_area[b])
        k = pts.shape[0]
        if pos + k > cap:
            cap = cap + (cap >> 2) + k
            pa, fs, us = _grow(pa, cap), _grow(fs, cap), _grow(us, cap)
            area, un, dil, state = _grow(area, cap), _grow(un, cap), _grow(dil, cap), \
                _grow(state, cap)
            hist = _grow(hist, cap)
        o0 = old_start[c]
        o1 = old_start[c + 1]
        for i in range(k):
            s = pos + i
            wx = p[0] + pts[i, 0] * e[0] + pts[i, 1] * e[3]
            wy = p[1] + pts[i, 0] * e[1] + pts[i, 1] * e[4]
            wz = p[2] + pts[i, 0] * e[2] + pts[i, 1] * e[5]
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
                for m in range(hist.shape[1]):
                    hist[s, m] = old_hist[best, m]
            else:
                for m in range(3):
                    fs[s, m] = 0.0
                    us[s, m] = 0.0
                dil[s] = 0.0
                for m in range(hist.shape[1]):
                    hist[s, m] = 0.0
                # a joint that forms open has no bond: no tension or cohesion
                state[s] = FAILED if ovl[i] < 0.0 else 0
        if o1 > o0:
            carry_spring_energy(old_area[o0:o1], old_un[o0:o1], old_dil[o0:o1], old_fs[o0:o1],
                                area[pos:pos + k], un[pos:pos + k], dil[pos:pos + k],
                                fs[pos:pos + k])
        new_start[c + 1] = k
        pos += k
    tot = 0
    for c in range(nc):
        tot += new_start[c + 1]
        new_start[c + 1] = tot
    if n_todo == nc:  # every contact updated: the side arrays, in contact order, are the result
        if trim and cap > tot + (tot >> 3) + 64:  # a copy (memcpy) rather than hold the slack
            # one array at a time, each original freed once copied: the update's peak is the
            # sub-contacts plus one copy, not twice the sub-contacts (the start's first update)
            pa = pa[:tot].copy()
            area = area[:tot].copy()
            un = un[:tot].copy()
            fs = fs[:tot].copy()
            us = us[:tot].copy()
            dil = dil[:tot].copy()
            state = state[:tot].copy()
            hist = hist[:tot].copy()
            return keep, new_start, pa, area, un, fs, us, dil, state, hist
        return keep, new_start, pa[:tot], area[:tot], un[:tot], fs[:tot], us[:tot], \
            dil[:tot], state[:tot], hist[:tot]
    side_rows = (pa, area, un, fs, us, dil, state, hist)
    old_rows = (old_pa, old_area, old_un, old_fs, old_us, old_dil, old_state, old_hist)
    if in_place and _same_layout(keep, new_start, old_start):
        side = 0
        for c in range(nc):
            if todo[c] != 0:
                k = new_start[c + 1] - new_start[c]
                _copy_subs(old_rows, new_start[c], side_rows, side, side + k)
                side += k
        return keep, new_start, old_pa, old_area, old_un, old_fs, old_us, old_dil, old_state, \
            old_hist
    out = _new_subs(tot, old_state, old_hist.shape[1])
    side = 0
    c = 0
    while c < nc:
        if todo[c] != 0:  # updated (or deleted: no rows): from the side arrays
            k = new_start[c + 1] - new_start[c]
            _copy_subs(out, new_start[c], side_rows, side, side + k)
            side += k
            c += 1
            continue
        c1 = c + 1  # a run of untouched contacts: their old rows, contiguous, in one copy
        while c1 < nc and todo[c1] == 0:
            c1 += 1
        _copy_subs(out, new_start[c], old_rows, old_start[c], old_start[c1])
        c = c1
    return keep, new_start, out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7]
