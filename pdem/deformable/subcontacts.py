"""Sub-contacts of a zoned block at its surface gridpoints (3DEC's deformable-block contacts).

pdem's rigid sub-contacts are the corners of the common area of the two blocks' touching
faces (:mod:`pdem.contact.subcontacts`): for a zoned block that would load only the corners
of its contact face and leave its other gridpoints free (measured: a zoned column on a floor
settled 6x the joint closure at its base). 3DEC instead puts one sub-contact at every surface
gridpoint of the deformable block touching the other block, with the gridpoint's share of
the surface area. That is done here, after the common-plane update:

- the zoned side ``D`` is A if A is zoned, else B; ``O`` the other block's piece;
- a surface gridpoint ``g`` of ``D`` is a sub-contact if its area share below is positive
  (it faces ``O`` and part of its cell lies within ``O``'s outline) and its gap across
  ``O``'s faces that face ``D`` is within the touch tolerance: ``max_f (n_f . g - o_f)``
  over those faces (the overlap below with its sign turned). Not the distance outside all of
  ``O``'s face planes: a rim gridpoint just outside ``O``'s outline bears the part of its
  cell that ``O`` covers, and left out it let ``O``'s edge sink into ``D``'s face beside it
  (tests/verification/test_deformable_energy.py's soft row). For a zoned ``O`` its facing
  side counts by the plane of its nearest facing triangle only (the planes of its other,
  tilted triangles, extended across the piece, switched gridpoints near a junction in and
  out of contact: a zoned rock mass cut by a tunnel never settled);
- its area is ``sum_t max(0, n_t . u) A_t / 3`` over its surface triangles ``t``, ``u`` the
  direction from ``D`` to ``O`` (``n`` for D = A, ``-n`` for D = B): a flat contact face's
  shares sum to its area; its overlap ``un`` minus the same maximum over ``O``'s faces that
  face ``D`` (normals within 60 degrees of ``-u``), so that a gridpoint on the rim of two
  flush faces (on ``O``'s side planes) has the overlap across them; its point the gridpoint;
- its joint history (shear force and displacement, dilation, state bits, law columns) and its
  normal displacement ``un`` are the previous sub-contact's at the same gridpoint of the same
  contact, if there was one (:data:`CARRIED`): the gridpoints are material points, so this
  transfer is exact, and ``un`` is integrated from the relative velocity as in 3DEC (the
  overlap above is only a new sub-contact's start).

When none of D's gridpoints meets O (a rigid corner or edge, or a zoned block's gridpoint,
pressing into D's face between D's gridpoints), the sub-contacts are O's vertices within the
touch tolerance of D (distance outside D's nearest face plane), with a rigid O's
``point_area`` or a zoned O's facing gridpoint share: without them such a corner sank through
D's face until a gridpoint of D met O's faces (measured: a rigid wedge's edge 2.1 cm into a
zoned block after 3000 steps, still sinking at 0.3 m/s). 3DEC takes both sides of a
deformable-deformable contact always and halves the stiffness; pdem takes D's gridpoints and
O's corners only as the fallback, so face-to-face contacts keep their exact areas.
"""

from __future__ import annotations

import numpy as np

from ..jit import kernel
from ..model import csr
from ..model.contacts import ContactStore
from .columns import GNODE, TRI, W
from .contact import closest_on_triangle, locate


@kernel
def gridpoint_candidates(verts_d, face_d, fvert_d, face_verts, normals_d, nodes_row0, ux, uy,
                         uz, normals_o, offsets_o, tol, tris_o, tri_normals, tri_offsets):
    """For D's piece (vertex rows ``verts_d`` world, faces ``face_d`` range, world normals
    ``normals_d`` of those faces), the vertex offsets (from ``nodes_row0``) that are
    sub-contacts against O (world planes ``normals_o``, ``offsets_o``), their areas and
    overlaps."""
    nv = verts_d.shape[0]
    area = np.zeros(nv)
    for f in range(face_d[0], face_d[1]):
        j = fvert_d[f]
        p, q, t = face_verts[j] - nodes_row0, face_verts[j + 1] - nodes_row0, \
            face_verts[j + 2] - nodes_row0
        e1 = verts_d[q] - verts_d[p]
        e2 = verts_d[t] - verts_d[p]
        cx = e1[1] * e2[2] - e1[2] * e2[1]
        cy = e1[2] * e2[0] - e1[0] * e2[2]
        cz = e1[0] * e2[1] - e1[1] * e2[0]
        k = f - face_d[0]
        facing = normals_d[k, 0] * ux + normals_d[k, 1] * uy + normals_d[k, 2] * uz
        if facing <= 0.0:
            continue
        share = facing * 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz) / 3.0
        eps = 1e-9 * (np.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
                      + np.sqrt(e2[0] ** 2 + e2[1] ** 2 + e2[2] ** 2))
        for a, b, c in ((p, q, t), (q, t, p), (t, p, q)):
            # the gridpoint's third of the triangle (its barycentric cell), cut to where O
            # is (or within tol in front of it): a gridpoint on the rim of O's face bears
            # only the part of its share that O covers (its whole share made a 1 m2 rigid
            # face on a larger zoned one bear on 1.83 m2)
            area[a] += _covered_share(verts_d[a], verts_d[b], verts_d[c], share, facing,
                                      normals_d[k], normals_o, offsets_o, ux, uy, uz, tol, eps)
    sel = np.zeros(nv, np.int64)
    un = np.zeros(nv)
    m = 0
    for i in range(nv):
        if area[i] <= 0.0:  # (its cell lies outside O's outline, or faces away)
            continue
        # the gap across O's facing faces decides, not the distance outside O's side
        # planes: a rim gridpoint a little outside O's outline bears the part of its cell
        # that O covers (above); left out, O's edge pressed into D's face beside it
        # unresisted, and the gridpoint joined later 2.4 cm deep (a rigid cube's edge into a
        # soft zoned cube offset 1.3 cm: 55 % of the energy put in created at that update)
        _, dn = _outside(verts_d[i], normals_o, offsets_o, ux, uy, uz)
        if tris_o.shape[0]:  # a zoned O: across its nearest facing surface triangle
            dn = _triangle_outside(verts_d[i], tris_o, tri_normals, tri_offsets)
        if dn <= tol:
            sel[m] = i
            un[m] = -dn
            m += 1
    return sel[:m], area[sel[:m]], un[:m]


# a face of O within 30 degrees of facing a cell of D (cos 30): one the cell bears on
OPPOSED = 0.8660254037844386


@kernel
def _plane_distance(p, n, o):
    return n[0] * p[0] + n[1] * p[1] + n[2] * p[2] - o


@kernel
def _covered_share(a, b, c, share, facing, normal, normals_o, offsets_o, ux, uy, uz, tol,
                   eps):
    """Gridpoint ``a``'s area share of triangle ``abc`` (``share``: a third of its area times
    ``facing``; ``normal`` the triangle's) that lies where O is, or within the touch tolerance
    ``tol`` in front of it: its barycentric cell (``a``, the midpoints of ``ab`` and ``ac``,
    the centroid; a third of the triangle) clipped by O's face planes, each moved
    ``tol max(0, -n_f . u)`` towards D (O stretched by ``tol`` along ``-u``), but for those
    within 30 degrees of facing the triangle (``n_f . normal < -cos 30``): the faces the cell
    bears on, across which the gridpoint's gap and overlap are measured (a deformed zoned
    face is not flat: the planes of its triangles would cut a matching cell beside it). So
    the faces that face D at an angle bound how far in front of them a cell may lie, and the
    others O's outline. ``share`` itself, bitwise, when no plane cuts the cell by more than
    ``eps``.

    Only the outline once cut the cell (every face facing D within 60 degrees of ``-u`` was
    skipped): the cells of a zoned cube's faces beside an edge it shares with a diagonal
    neighbour in an array of cubes lie within the neighbour's outline, and their gridpoints
    in the planes of its faces, so an edge contact bore on 0.8 m2 of cells for a unit cube's
    0.01 m2 strips along the edge (1,000 zoned cubes: 6,260 m2 of edge and corner contacts
    beside the 2,800 m2 of faces, 124,128 of the 168,928 sub-contacts)."""
    m = normals_o.shape[0]
    poly = np.empty((4 + m, 3))
    poly[0] = a
    poly[1] = 0.5 * (a + b)
    poly[2] = (a + b + c) / 3.0
    poly[3] = 0.5 * (a + c)
    n = 4
    moved = np.empty(m)
    cut = False
    for f in range(m):
        towards = -(normals_o[f, 0] * ux + normals_o[f, 1] * uy + normals_o[f, 2] * uz)
        moved[f] = offsets_o[f] + tol * max(0.0, towards)
        if normals_o[f, 0] * normal[0] + normals_o[f, 1] * normal[1] \
                + normals_o[f, 2] * normal[2] < -OPPOSED:
            moved[f] = np.inf  # a face the cell bears on: not a bound
        if cut:
            continue
        for k in range(n):
            if _plane_distance(poly[k], normals_o[f], moved[f]) > eps:
                cut = True
                break
    if not cut:
        return share
    buf = np.empty((4 + m, 3))
    for f in range(m):
        if n == 0:
            break
        nf = normals_o[f]
        # Sutherland-Hodgman: keep the part of the polygon with n . x <= o
        k = 0
        for i in range(n):
            p, q = poly[i], poly[(i + 1) % n]
            dp = _plane_distance(p, nf, moved[f])
            dq = _plane_distance(q, nf, moved[f])
            if dp <= 0.0:
                buf[k] = p
                k += 1
            if (dp <= 0.0) != (dq <= 0.0):
                buf[k] = p + (dp / (dp - dq)) * (q - p)
                k += 1
        n = k
        poly[:n] = buf[:n]
    if n < 3:
        return 0.0
    sx = sy = sz = 0.0
    for i in range(1, n - 1):
        e1 = poly[i] - poly[0]
        e2 = poly[i + 1] - poly[0]
        sx += e1[1] * e2[2] - e1[2] * e2[1]
        sy += e1[2] * e2[0] - e1[0] * e2[2]
        sz += e1[0] * e2[1] - e1[1] * e2[0]
    return facing * 0.5 * np.sqrt(sx * sx + sy * sy + sz * sz)


@kernel
def _triangle_outside(p, tris, normals, offsets):
    """How far ``p`` lies outside the triangle (of ``tris``) nearest to it: behind its plane,
    minus the depth (the overlap across a zoned block's deformed surface: the planes of its
    other triangles, extended, are off by their tilt times the distance, as large as the
    overlaps); in front of it, the distance to the triangle (a point in the plane of a
    facing triangle but far beside it is not touching it)."""
    best = np.inf
    out = 0.0
    for t in range(tris.shape[0]):
        _, _, _, d2 = closest_on_triangle(p[0], p[1], p[2], tris[t, 0], tris[t, 1],
                                           tris[t, 2])
        if d2 < best:
            best = d2
            out = normals[t, 0] * p[0] + normals[t, 1] * p[1] + normals[t, 2] * p[2] \
                - offsets[t]
    return out


def facing_triangles(b, k, r, u):
    """The surface triangles of zoned piece ``k`` (row ``r``, identity pose) facing ``-u``
    (normals within 60 degrees): world vertices (m, 3, 3), normals, plane offsets."""
    f0, f1 = b.face_start[k], b.face_start[k + 1]
    n = b.normals_local[f0:f1]
    f = np.nonzero(n @ u < -0.5)[0]
    ids = b.face_verts[b.fvert_start[f0 + f][:, None] + np.arange(3)]
    tris = b.verts_local[ids] + b.x[r]
    return tris, n[f], b.offsets_local[f0 + f] + n[f] @ b.x[r]


_NO_TRIANGLES = (np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0))


@kernel
def _outside(p, normals, offsets, ux, uy, uz):
    """How far ``p`` lies outside a convex piece's face planes: over all of them (the touch
    test) and over those facing ``p``'s side (normals within 60 degrees of ``-u``, ``u`` the
    direction from ``p``'s block to the piece; all of them if none does): the overlap. A
    gridpoint on the rim of two flush faces lies on the other block's side planes; its overlap
    is the one across the faces, not 0 (measured: a zoned column cut in two closed its joint
    3.4x the closed form before)."""
    d = -np.inf
    dn = -np.inf
    for f in range(normals.shape[0]):
        val = normals[f, 0] * p[0] + normals[f, 1] * p[1] + normals[f, 2] * p[2] - offsets[f]
        d = max(d, val)
        if normals[f, 0] * ux + normals[f, 1] * uy + normals[f, 2] * uz < -0.5:
            dn = max(dn, val)
    return d, (dn if dn > -np.inf else d)


def _world_planes(b, k, r):
    f0, f1 = b.face_start[k], b.face_start[k + 1]
    n = b.normals_local[f0:f1] @ b.R[r].T
    return n, b.offsets_local[f0:f1] + n @ b.x[r]


# what a sub-contact at the same gridpoint of the same contact keeps over an update: its joint
# history and its normal displacement, integrated from the relative velocity since it was
# made (3DEC's incremental form). Its overlap measured afresh would throw away a closure that
# no geometry shows: the in-situ stress's (pdem.insitu), which the update after the first
# motion then lost (a zoned rock mass cut into pieces jumped out of its in-situ equilibrium).
CARRIED = ("sc_un", "sc_fs", "sc_us", "sc_dil", "sc_state", "sc_hist")


def carry_grid_columns(old: np.ndarray, old_start: np.ndarray, start: np.ndarray,
                       todo: np.ndarray) -> np.ndarray:
    """The ``sc_grid`` columns after a contact update (``start``: the updated store's
    sub-contact starts, contact for contact with ``old_start``): the contacts not updated keep
    their sub-contacts and so their columns; the updated ones' are void (-1 gridpoint) until
    :func:`regrid` sets those of the zoned blocks' contacts."""
    out = np.zeros((int(start[-1]), old.shape[1]))
    out[:, GNODE] = -1.0
    kept = np.nonzero(todo == 0)[0]
    src, _ = csr.take(old_start, kept)
    dst, _ = csr.take(start, kept)
    out[dst] = old[src]
    return out


def regrid(grid, old: ContactStore, new: ContactStore, todo: np.ndarray, b, tol: float
           ) -> ContactStore:
    """``new`` (after a common-plane update of the contacts ``todo``) with the sub-contacts of
    every updated contact of a zoned block at its gridpoints (module doc); history from
    ``old``'s sub-contacts at the same gridpoints (their ``sc_grid`` gridpoint), and the
    triangles and weights of the new sub-contacts on each zoned side (``sc_grid``, found
    once here: the weights then stay until the contact's next update, on every rank that
    computes the contact)."""
    ia, ib, ka, kb = new.ia, new.ib, new.ka, new.kb
    dz = grid.dindex
    redo = (todo != 0) & ((dz[ia] >= 0) | (dz[ib] >= 0))
    if not redo.any():
        return new
    old_keys = old.keys()
    keys = new.keys()
    parts = {k: [] for k in new.sub}
    counts = np.diff(new.sc_start).copy()
    old_grid = old.sub["sc_grid"]
    cursor = 0
    for c in np.nonzero(redo)[0]:
        # the untouched contacts before c keep their sub-contacts
        s0 = new.sc_start[cursor]
        s1 = new.sc_start[c]
        for k, a in new.sub.items():
            parts[k].append(a[s0:s1])
        cursor = c + 1
        a_side = dz[ia[c]] >= 0
        rd, kd = (ia[c], ka[c]) if a_side else (ib[c], kb[c])
        ro, ko = (ib[c], kb[c]) if a_side else (ia[c], ka[c])
        n = new.normal[c]
        u = n if a_side else -n
        v0, v1 = b.vert_start[kd], b.vert_start[kd + 1]
        verts = b.verts_local[v0:v1] + b.x[rd]  # identity pose
        normals_d = b.normals_local[b.face_start[kd]:b.face_start[kd + 1]]
        no, oo = _world_planes(b, ko, ro)
        tris = facing_triangles(b, ko, ro, u) if dz[ro] >= 0 else _NO_TRIANGLES
        sel, area, un = gridpoint_candidates(
            verts, np.array([b.face_start[kd], b.face_start[kd + 1]]), b.fvert_start,
            b.face_verts, normals_d, v0, u[0], u[1], u[2], no, oo, tol, *tris)
        nodes = grid.surf[dz[rd]][sel]  # block-local gridpoints
        points = verts[sel]
        if len(sel) == 0:  # none of D's gridpoints meets O: O's corners into D (module doc)
            points, area, un, nodes = _corners_into(grid, b, ro, ko, rd, kd, -u, tol)
        m = len(points)
        ra = b.R[ia[c]]
        sub = {"sc_pa": (points - b.x[ia[c]]) @ ra, "sc_area": area, "sc_un": un}
        for k in ("sc_fs", "sc_us", "sc_dil", "sc_state", "sc_hist", "sc_grid"):
            a = new.sub[k]
            sub[k] = np.zeros((m,) + a.shape[1:], a.dtype)
        sub["sc_grid"][:, GNODE] = nodes
        j = int(np.searchsorted(old_keys, keys[c]))
        if j < old.n and old_keys[j] == keys[c]:
            o0, o1 = old.sc_start[j], old.sc_start[j + 1]
            where = {int(g): o0 + i for i, g in enumerate(old_grid[o0:o1, GNODE]) if g != -1}
            for i, g in enumerate(nodes):
                s = where.get(int(g))
                if s is not None:
                    for k in CARRIED:
                        sub[k][i] = old.sub[k][s]
                    # the shear force is carried as a stress: the spring's energy
                    # fs^2 / (2 ks A) is then the old one scaled with the area, as the
                    # normal spring's (kn A un^2 / 2, un carried); a force kept on a
                    # share cut smaller made energy (1/A), found at stiff joints
                    a_old = float(old.sub["sc_area"][s])
                    if a_old > 0.0 and area[i] != a_old:
                        sub["sc_fs"][i] *= area[i] / a_old
        for k in parts:
            parts[k].append(sub[k])
        counts[c] = m
    for k, a in new.sub.items():
        parts[k].append(a[new.sc_start[cursor]:])
    out = ContactStore(new.arrays, {k: np.concatenate(v) for k, v in parts.items()},
                       csr.starts(counts))
    _locate(grid, out, redo, b)
    return out


def _corners_into(grid, b, ro, ko, rd, kd, u, tol):
    """Sub-contacts at the vertices of O's piece ``ko`` (block row ``ro``) within ``tol`` of
    D's piece (``max_f n_f . p - o_f`` over D's world face planes; ``u`` the direction from O
    to D): (world points, areas, overlaps, ``sc_grid`` ids ``-2 - vertex``, so that their
    history is carried by vertex). The area is a zoned O's gridpoint share facing D, or a rigid
    O's ``point_area`` (the smaller of the two blocks', as for rigid vertex sub-contacts)."""
    v0, v1 = b.vert_start[ko], b.vert_start[ko + 1]
    nd, od = _world_planes(b, kd, rd)
    tris = facing_triangles(b, kd, rd, u)  # D's, facing O
    if grid.dindex[ro] >= 0:  # zoned O: its gridpoints, areas as D's above
        verts = b.verts_local[v0:v1] + b.x[ro]
        sel, area, un = gridpoint_candidates(
            verts, np.array([b.face_start[ko], b.face_start[ko + 1]]), b.fvert_start,
            b.face_verts, b.normals_local[b.face_start[ko]:b.face_start[ko + 1]], v0, u[0],
            u[1], u[2], nd, od, tol, *tris)
        return verts[sel], area, un, -2 - sel
    verts = b.verts_local[v0:v1] @ b.R[ro].T + b.x[ro]
    d = np.empty(len(verts))
    dn = np.empty(len(verts))
    for i, p in enumerate(verts):
        d[i], dn[i] = _outside(p, nd, od, u[0], u[1], u[2])
        if len(tris[0]):
            dn[i] = _triangle_outside(p, *tris)
    sel = np.nonzero(d <= tol)[0]
    area = np.full(len(sel), min(float(b.point_area[ro]), float(b.point_area[rd])))
    return verts[sel], area, -dn[sel], -2 - sel


def _locate(grid, c: ContactStore, redo: np.ndarray, b) -> None:
    """The triangles and weights (``sc_grid``) of the sub-contacts of the contacts ``redo``
    on their zoned sides, at the gridpoints now."""
    n = c.n_sub
    sc_node = np.zeros((n, 2, 3), np.int64)
    sc_w = np.zeros((n, 2, 3))
    locate(c.ia, c.ib, c.ka, c.kb, c.sc_start, c.sub["sc_pa"], b.x, b.R, b.face_start,
           b.fvert_start, b.face_verts, grid.nodes, grid.vnode_rows, grid.dindex,
           redo.astype(np.uint8), sc_node, sc_w)
    counts = np.diff(c.sc_start)
    rows = np.repeat(np.arange(c.n), counts)
    done = redo[rows]
    g = c.sub["sc_grid"]
    for side, blk in enumerate((c.ia, c.ib)):
        d = grid.dindex[blk[rows]]
        zoned = done & (d >= 0)
        base = grid.node_start[np.maximum(d, 0)]
        g[zoned, TRI[side]] = (sc_node[zoned, side] - base[zoned, None]).astype(float)
        g[zoned, W[side]] = sc_w[zoned, side]
