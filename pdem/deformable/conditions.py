"""Boundary conditions on zoned blocks, at their gridpoints and surface faces (3DEC's
``zone gridpoint fix velocity`` and ``zone face apply stress``).

A scene's selection (``boundary.velocity``, ``boundary.stress``, a stage's ``fix``, ``free``,
``velocity``, ``stress``, ``force``) takes rigid blocks as blocks (by name, group, centroid
in ``range``) and zoned blocks by their grids: ``names``/``groups`` choose the zoned blocks
(all of them if neither is given), ``range`` the gridpoints (or surface faces, by centroid)
inside its box, on the block's **reference** positions (those it was built with: a selection
does not depend on the motion, so a restart's replay selects what the straight run did).

What a condition sets lives on the :class:`~pdem.deformable.body.DeformableBody` and travels
with it between ranks: ``fixed``/``fixed_vel`` per degree of freedom, ``vhist`` (the index of a
velocity history in :attr:`GridConditions.histories`, -1 none), ``applied``/``loaded`` (a
stage's ``force``). Boundary stresses are kept by the :class:`GridConditions` as surface
triangles by block gid (every rank holds all; each rank loads the grids it owns every step,
from the triangles' current positions: the traction deforms with the face).
"""

from __future__ import annotations

import math

import numpy as np

from ..mpi import allgather
from .motion import GW_BOUNDARY
from .zones import add_zone_forces


def zoned_entries(scene) -> np.ndarray:
    """Whether each scene block entry is zoned."""
    return np.array([b.zones is not None for b in scene.blocks], bool)


def zoned_mask(s, gids) -> np.ndarray:
    """Which of ``gids`` are zoned blocks."""
    gids = np.asarray(gids, np.int64)
    if s.grids is None or not len(gids):
        return np.zeros(len(gids), bool)
    return zoned_entries(s.scene)[np.asarray(s.specs.entry[gids])]


def zoned_gids(s) -> np.ndarray:
    """The gids of every zoned block of the model."""
    n = len(s.specs)
    return np.nonzero(zoned_mask(s, np.arange(n)))[0].astype(np.int64)


def _in_box(x: np.ndarray, sel) -> np.ndarray:
    if sel.range is None:
        return np.ones(len(x), bool)
    box = sel.range.box
    return np.all((x >= np.asarray(box.min)) & (x <= np.asarray(box.max)), axis=1)


def held_grids(s, sel):
    """``(d, body)`` of the grids this rank holds (owned and ghost copies) whose block the
    selection's names and groups take (every zoned block if it gives neither)."""
    g = s.grids
    if g is None or not len(g):
        return []
    gids = np.asarray(g.gids, np.int64)
    keep = s.specs.matching(gids, sel.names, sel.groups)
    out = s.glob.out[gids] if "out" in vars(s.glob) else np.zeros(len(gids))
    return [(d, g.bodies[d]) for d in np.nonzero(keep & (out == 0))[0]]


def gridpoints(s, sel) -> list:
    """``(d, body, node ids)`` of the held grids' gridpoints a selection takes (reference
    positions in ``range``); empty node lists left out."""
    hits = []
    for d, body in held_grids(s, sel):
        idx = np.nonzero(_in_box(body.nodes0, sel))[0]
        if len(idx):
            hits.append((d, body, idx))
    return hits


def owned_count(s, hits) -> int:
    """How many grids of the model the hits touch (each counted at its owner; collective)."""
    n_owned = s.grids.n_owned if s.grids is not None else 0
    return int(sum(allgather(s.comm, sum(1 for h in hits if h[0] < n_owned))))


class GridConditions:
    """The boundary conditions in force on zoned blocks (every rank alike): velocity
    histories by index, and the surface triangles under stress."""

    def __init__(self):
        self.histories: list[tuple] = []  # (VelocityHistory, t0)
        self.t_gid = np.zeros(0, np.int64)  # triangles under stress: block gid,
        self.t_vert = np.zeros((0, 3), np.int64)  # its piece's vertices (outward order),
        self.t_sigma = np.zeros((0, 3, 3))  # the stress (world, tension positive)
        self._map = None  # (grid store, flat gridpoints of each owned triangle, rows)
        # quiet boundaries: triangles (block gid, vertices) with dashpots normal and/or shear
        self.q_gid = np.zeros(0, np.int64)
        self.q_vert = np.zeros((0, 3), np.int64)
        self.q_on = np.zeros((0, 2), bool)
        self._qmap = None  # the grid store whose ``quiet`` holds them
        # wave input (sigma = 2 rho C v on a quiet face): triangles and their history's index
        self.waves: list[tuple] = []  # (VelocityHistory, t0)
        self.w_gid = np.zeros(0, np.int64)
        self.w_vert = np.zeros((0, 3), np.int64)
        self.w_hist = np.zeros(0, np.int64)
        self._wmap = None

    # ---------------------------------------------------------------- velocities
    def fix(self, hits, dofs, value, motion_too: bool, history=None, t0: float = 0.0,
            book: bool = False) -> None:
        """Prescribe ``value (3,)`` (or ``history``'s velocity from ``t0``) on ``dofs`` of the
        gridpoints ``hits``; ``motion_too``: their velocities too (a restart has them).
        ``book``: the kinetic energy the newly held components had goes out through the
        boundary (``GW_BOUNDARY``): a run's stage, not the set-up (before the budget's start)
        nor a restart's replay."""
        code = -1
        if history is not None:
            self.histories.append((history, float(t0)))
            code = len(self.histories) - 1
        for _, body, idx in hits:
            for k in dofs:
                if book:
                    _book_switch(body, idx, k, -1.0)
                body.fixed[idx, k] = True
                body.fixed_vel[idx, k] = value[k]
                body.vhist[idx, k] = code
                if motion_too:
                    body.vel[idx, k] = value[k]

    @staticmethod
    def free(hits, book: bool = False) -> None:
        """Release every degree of freedom of the gridpoints ``hits``; ``book``: the kinetic
        energy their prescribed velocities leave them with was put in through the boundary
        (as :meth:`fix`)."""
        for _, body, idx in hits:
            if book:
                for k in range(3):
                    _book_switch(body, idx, k, 1.0)
            body.fixed[idx] = False
            body.fixed_vel[idx] = 0.0
            body.vhist[idx] = -1

    def prescribe(self, s, velocity_at) -> None:
        """Before a step from t: the histories' velocities at ``t + dt/2`` on the gridpoints
        of the owned grids that follow them (``velocity_at(history, t)``)."""
        g = s.grids
        if not self.histories or g is None:
            return
        t = s.time + 0.5 * s.dt
        for d in range(g.n_owned):
            body = g.bodies[d]
            if body.vhist.max(initial=-1) < 0:  # (most grids follow no history)
                continue
            codes = np.unique(body.vhist)
            for h in codes[codes >= 0]:
                hist, t0 = self.histories[h]
                v = velocity_at(hist, t - t0)
                on = body.vhist == h
                body.fixed_vel[on] = np.broadcast_to(v, body.vel.shape)[on]

    # ---------------------------------------------------------------- stresses
    def add_stress(self, s, sel, sigma, exposed) -> int:
        """Put ``sigma`` on the exposed surface triangles of the zoned blocks the selection
        takes (centroid in ``range``); ``exposed(gids)``: (gid, face rows) of the exposed
        faces of blocks ``gids`` of the scene's store (pdem.boundary.exposed_face_rows).
        Returns the triangles taken."""
        gid, vert = exposed_triangles(s, sel, exposed)
        self.t_gid = np.concatenate([self.t_gid, gid])
        self.t_vert = np.concatenate([self.t_vert, vert])
        self.t_sigma = np.concatenate([self.t_sigma,
                                       np.repeat(np.asarray(sigma, float)[None], len(gid), 0)])
        self._map = None
        return len(gid)

    def add_quiet(self, s, sel, normal: bool, shear: bool, exposed) -> int:
        """Dashpots (a quiet boundary, :meth:`dashpots`) on the exposed surface triangles of
        the zoned blocks the selection takes (as :meth:`add_stress`); returns their count."""
        gid, vert = exposed_triangles(s, sel, exposed)
        self.q_gid = np.concatenate([self.q_gid, gid])
        self.q_vert = np.concatenate([self.q_vert, vert])
        self.q_on = np.concatenate([self.q_on, np.tile([normal, shear], (len(gid), 1))])
        self._qmap = None
        return len(gid)

    def release_held(self, s, sel, loads: bool, exposed) -> None:
        """Free every held degree of freedom of the owned grids' gridpoints on the exposed
        triangles the selection takes and, with ``loads``, give each the force that held it
        as a constant load (``applied``): minus the zone, contact, gravity and applied forces
        on it now (a restart's replay frees them alone: the loads are in its checkpoint)."""
        g = s.grids
        gid, vert = exposed_triangles(s, sel, exposed)
        if g is None or not len(gid):
            return
        for d, _rows, tri in owned_triangles(g, gid, vert):
            body = g.bodies[d]
            idx = np.unique(tri.ravel()) - g.node_start[d]
            held = body.fixed[idx]
            if not held.any():
                continue
            if loads:
                zone = np.zeros((len(body.nodes), 3))
                add_zone_forces(body.tets, body.grad, body.vol, body.stress, zone)
                a = g.node_start[d]
                total = (zone[idx] + g.force[a + idx] + np.outer(body.gravity_mass[idx], g.gravity)
                         + body.applied[idx])
                body.applied[idx] -= np.where(held, total, 0.0)
                body.loaded = True
            elif body.applied[idx].any():
                body.loaded = True
            body.fixed[idx] = False
            body.fixed_vel[idx] = 0.0
            body.vhist[idx] = -1

    def add_wave(self, s, sel, history, t0: float, exposed) -> int:
        """A wave put in through the exposed surface triangles the selection takes (as
        :meth:`add_stress`): the traction ``2 rho (Cp (v.n) n + Cs (v - (v.n) n))`` of the
        history's particle velocity ``v`` (:meth:`tractions`); returns their count."""
        gid, vert = exposed_triangles(s, sel, exposed)
        self.waves.append((history, float(t0)))
        self.w_gid = np.concatenate([self.w_gid, gid])
        self.w_vert = np.concatenate([self.w_vert, vert])
        self.w_hist = np.concatenate([self.w_hist, np.full(len(gid), len(self.waves) - 1)])
        self._wmap = None
        return len(gid)

    def dashpots(self, s) -> None:
        """The owned grids' dashpot matrices (``GridStore.quiet``) from the quiet triangles,
        made again when the store is new (after a distribution): each triangle's area ``A``
        and unit normal ``n`` on the block's reference (build) positions (the same matrices
        on any rank count and after a restart) give each of its three gridpoints
        ``A/3 rho (Cp n n^T + Cs (I - n n^T))`` (the directions not chosen left out):
        Lysmer and Kuhlemeyer's viscous boundary, ``rho`` and the wave speeds ``Cp =
        sqrt((K + 4G/3)/rho)``, ``Cs = sqrt(G/rho)`` of the block's material."""
        g = s.grids
        if g is None or (self._qmap is g) or not len(self.q_gid):
            return
        g.quiet[:] = 0.0
        for d in range(g.n_owned):
            g.bodies[d].quieted = False
        for d, rows, tri in owned_triangles(g, self.q_gid, self.q_vert):
            body = g.bodies[d]
            x = body.nodes0[g.surf[d][self.q_vert[rows]]]
            area, n = _area_normal(x)
            cp, cs = wave_impedances(body.params)
            a = area / 3.0 * cp * self.q_on[rows, 0]
            b = area / 3.0 * cs * self.q_on[rows, 1]
            # a nn^T + b (I - nn^T), upper triangle: xx yy zz xy yz zx
            c = np.empty((len(rows), 6))
            for k, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0))):
                c[:, k] = (a - b) * n[:, i] * n[:, j] + (b if i == j else 0.0)
            for k in range(3):
                np.add.at(g.quiet, tri[:, k], c)
            body.quieted = True
        self._qmap = g

    def tractions(self, s, velocity_at) -> None:
        """The owned grids' boundary loads (``GridStore.bload``) from the triangles under
        stress at their positions at t: ``sigma . (area vector)`` shared by its three
        gridpoints; and the waves' tractions (:meth:`add_wave`) at t, their histories'
        velocities ``velocity_at(history, t)``."""
        g = s.grids
        if g is None:
            return
        g.bload[:] = 0.0
        g.bloaded = bool(len(self.t_gid) or len(self.w_gid))
        if not g.bloaded:
            return
        self._stress_loads(g)
        self._wave_loads(s, g, velocity_at)

    def _stress_loads(self, g) -> None:
        if self._map is None or self._map[0] is not g:
            tri = [(rows, t) for _, rows, t in owned_triangles(g, self.t_gid, self.t_vert)]
            rows = np.concatenate([r for r, _ in tri]) if tri else np.zeros(0, np.int64)
            flat = np.concatenate([t for _, t in tri]) if tri else np.zeros((0, 3), np.int64)
            self._map = (g, flat, rows)
        _, tri, rows = self._map
        if not len(rows):
            return
        x = g.nodes[tri]
        area = 0.5 * np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
        f = np.einsum("tij,tj->ti", self.t_sigma[rows], area) / 3.0
        for k in range(3):
            np.add.at(g.bload, tri[:, k], f)

    def _wave_loads(self, s, g, velocity_at) -> None:
        if not len(self.w_gid):
            return
        if self._wmap is None or self._wmap[0] is not g:
            self._wmap = (g, owned_triangles(g, self.w_gid, self.w_vert))
        v_of = [velocity_at(h, s.time - t0) for h, t0 in self.waves]
        for d, rows, tri in self._wmap[1]:
            x = g.nodes[tri]
            area, n = _area_normal(x)
            cp, cs = wave_impedances(g.bodies[d].params)
            v = np.array([v_of[h] for h in self.w_hist[rows]]).reshape(-1, 3)
            vn = np.einsum("ti,ti->t", v, n)[:, None]
            f = 2.0 * (area / 3.0)[:, None] * (cp * vn * n + cs * (v - vn * n))
            for k in range(3):
                np.add.at(g.bload, tri[:, k], f)



def exposed_triangles(s, sel, exposed) -> tuple[np.ndarray, np.ndarray]:
    """``(gid, vertices (k, 3))`` of the exposed surface triangles of the zoned blocks the
    selection's names and groups take whose centroid lies in its ``range`` (the vertices
    numbered in the block's piece, in outward order); ``exposed(gids)``: (gid, face rows)
    of the exposed faces of blocks ``gids`` of the scene's store."""
    g = s.glob
    gids = zoned_gids(s)
    gids = gids[s.specs.matching(gids, sel.names, sel.groups)]
    gids = gids[g.out[gids] == 0]
    gid, rows = exposed(gids)
    verts, keep = [], []
    for b, f in zip(gid, rows, strict=True):
        p = g.piece_start[b]
        v = g.face_verts[g.fvert_start[f]:g.fvert_start[f + 1]]
        x = g.verts_local[v] + g.x[b]
        if sel.range is not None and not _in_box(x.mean(axis=0)[None], sel)[0]:
            keep.append(False)
            verts.append((0, 0, 0))
            continue
        area = np.cross(x[1] - x[0], x[2] - x[0])
        if np.dot(area, g.normals_local[f]) < 0.0:
            v = v[[0, 2, 1]]
        keep.append(True)
        verts.append(tuple(v - g.vert_start[p]))
    keep = np.array(keep, bool)
    return gid[keep], np.array(verts, np.int64).reshape(-1, 3)[keep]


def owned_triangles(g, gid: np.ndarray, vert: np.ndarray) -> list:
    """``(d, rows, flat gridpoints (k, 3))`` per owned grid ``d`` of the triangles
    ``(gid, vert)`` on it (a condition's list, every rank alike), in grid order."""
    d_of = {int(b): d for d, b in enumerate(g.gids[:g.n_owned])}
    out = []
    on = np.array([int(b) in d_of for b in gid], bool)
    for b in np.unique(gid[on]):
        d = d_of[int(b)]
        rows = np.nonzero(gid == b)[0]
        out.append((d, rows, g.node_start[d] + g.surf[d][vert[rows]]))
    out.sort(key=lambda r: r[0])
    return out


def _area_normal(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Areas (k,) and unit outward normals (k, 3) of triangles ``x (k, 3, 3)``."""
    c = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    norm = np.linalg.norm(c, axis=1)
    return 0.5 * norm, c / norm[:, None]


def wave_impedances(params) -> tuple[float, float]:
    """``(rho Cp, rho Cs)`` of a zone material: ``sqrt(rho (K + 4G/3))``, ``sqrt(rho G)``."""
    rho = params.density
    return (math.sqrt(rho * (params.bulk + 4.0 * params.shear / 3.0)),
            math.sqrt(rho * params.shear))


def _book_switch(body, idx, k: int, sign: float) -> None:
    """The kinetic energy of component ``k`` of the gridpoints ``idx`` that change between
    prescribed and free: what a held component takes out (``sign`` -1, of those free now) or
    a freed one brings (+1, of those held now), on the body's ``GW_BOUNDARY`` (the budget
    counts no kinetic energy in a prescribed component)."""
    on = idx[body.fixed[idx, k] == (sign > 0.0)]
    if len(on):
        body.work[GW_BOUNDARY] += sign * 0.5 * float(np.sum(body.emass[on] * body.vel[on, k] ** 2))


def wholly_fixed(s) -> tuple[np.ndarray, np.ndarray]:
    """``(gids, fixed)`` of every zoned block, gathered from the owners (collective, every
    rank alike): fixed when every gridpoint is held at zero velocity in every direction."""
    g = s.grids
    mine = [] if g is None else [
        (g.gids[d], bool(g.bodies[d].fixed.all() and not g.bodies[d].fixed_vel.any()
                         and (g.bodies[d].vhist < 0).all()))
        for d in range(g.n_owned)]
    rows = sorted({r for part in allgather(s.comm, mine) for r in part})
    return (np.array([r[0] for r in rows], np.int64), np.array([r[1] for r in rows], bool))


def spread_force(hits, force) -> None:
    """A stage's ``force`` on the zoned blocks ``hits`` (whole blocks): spread over their
    gridpoints by mass, as ``blocks[i].force`` is."""
    force = np.asarray(force, float)
    for _, body, _idx in hits:
        m = body.gravity_mass
        body.applied[:] = np.outer(m / m.sum(), force)
        body.loaded = bool(force.any())
