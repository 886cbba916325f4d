"""Boundary conditions: prescribed velocities (whole block or chosen components, constant or
in time) and boundary stresses (tractions on the exposed faces of blocks).

Conditions come from the scene's ``boundary:`` (in force from the start) and from the stages'
``velocity:`` and ``stress:`` (from the stage's start). Both are declarative, so a restart
rebuilds them from the scene (and the stage replay) exactly as the straight run made them.
Each kind (these two, or one registered from outside pdem's tree) is one entry of
:data:`BOUNDARY_KINDS` carrying its condition model, its scene key and its hooks.

Velocities (docs/scene-file.md, ``boundary.velocity``)
    The block's ``vfix`` code says what is prescribed (pdem.dynamics.motion.VFIX_*): the whole
    motion (all three components: velocity and angular velocity), or a mask of translation
    components. A history is evaluated before every step at the leap-frog's mid-step time
    ``t + dt/2`` (the time level of the velocities the step makes) and written into ``v``;
    the integrator keeps the prescribed components and books the contacts' work on them as
    work of the prescribed motion (``boundary_work``).

Stresses (docs/theory.md, "Boundary stress")
    When a condition is applied, the exposed faces of its blocks are found once: a face is
    exposed unless another convex piece (of another block, or another piece of the same
    block) has a face with the opposite normal (cosine below ``-COVER_COS``), in the same
    plane (offsets within CTOL) whose polygon contains this face's centroid or whose centroid
    lies in this face's polygon. Each exposed face keeps its area ``A``, its outward normal
    ``n_b`` and its centroid ``c_b`` in the block's body frame. Every step, with the block's
    rotation ``R`` at t: ``n = R n_b``, ``f = A sigma n`` at the point ``x + R c_b``, summed
    into the block's ``bforce`` and ``bmoment = (R c_b) x f``; the integrator adds them to the
    unbalanced force and moment and books their work as applied work.

Quiet faces and waves (docs/dynamics.md, "Quiet boundaries and wave input")
    A ``quiet`` condition, or a ``stress`` with a ``wave``, takes the blocks its names and
    groups give (every block if neither) and, of their exposed faces, those whose centroid
    is in its ``range`` (zoned blocks: pdem.deformable.conditions). On a rigid block each
    such face keeps its area, body-frame normal and centroid and its material's impedances
    ``rho Cp``, ``rho Cs``. Before each step, after the stresses and waves: the dashpots'
    centred loads (pdem.dynamics.quiet), added to ``bforce``/``bmoment``; after the motion,
    what they absorbed is moved from the applied work to ``WORK_QUIET``. ``release`` frees
    the held rigid blocks among them and keeps the force and moment that held them as loads.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .config import ConfigError
from .config.schema import (
    CONDITION_MODELS,
    BoundaryQuiet,
    BoundaryStress,
    BoundaryVelocity,
    Selection,
)
from .deformable.conditions import (
    GridConditions,
    gridpoints,
    owned_count,
    wholly_fixed,
    zoned_mask,
)
from .dynamics import motion
from .dynamics.rotation import quat_to_matrix
from .errors import ConditionError
from .registry import Registry
from .rigid_faces import RigidFaces, owned_rows, rotations
from .selection import selected, set_block_fields

COVER_COS = 1.0 - 1e-6  # antiparallel faces: n_a . n_b < -COVER_COS
_BIT = {"x": motion.VFIX_X, "y": motion.VFIX_Y, "z": motion.VFIX_Z}


def vfix_code(cond) -> int:
    """The ``vfix`` code of a :class:`pdem.config.schema.BoundaryVelocity`."""
    if cond.all_components:
        return motion.VFIX_ALL
    return int(sum(_BIT[c] for c in cond.components))


def history_velocity(h, t: float) -> np.ndarray:
    """Velocity of a :class:`pdem.config.schema.VelocityHistory` at time ``t`` (s)."""
    if h.harmonic is not None:
        a = h.harmonic
        s = math.sin(2.0 * math.pi * a.frequency * t + math.radians(a.phase))
        return np.array(a.amplitude, float) * s
    if h.record is not None:  # a history file, resolved once when the scene was validated
        return h.record.at(t)
    tab = np.asarray(h.table, float)
    return np.array([np.interp(t, tab[:, 0], tab[:, k]) for k in (1, 2, 3)])


class Boundary:
    """The conditions in force on a model (every rank holds all of them, by gid)."""

    def __init__(self):
        # velocity histories: [gids, vfix code, history, t0]
        self.histories: list[list] = []
        # exposed faces under stress, by face: gid, A, n_b, c_b, sigma (3x3)
        self.f_gid = np.zeros(0, np.int64)
        self.f_area = np.zeros(0)
        self.f_normal = np.zeros((0, 3))
        self.f_center = np.zeros((0, 3))
        self.f_sigma = np.zeros((0, 3, 3))
        # the quiet faces and waves on rigid blocks' faces, and the blocks they released
        self.rigid = RigidFaces()
        # the conditions on zoned blocks' gridpoints and surface faces
        self.grid = GridConditions()

    @property
    def active(self) -> bool:
        """Some condition acts on the blocks (the steps then run in Python, pdem.stepper)."""
        return any(kind.active(self) for kind in BOUNDARY_KINDS.values())

    def at_start(self, s) -> None:
        """The conditions' loads before the run's first step (the staggered start)."""
        for kind in BOUNDARY_KINDS.values():
            if kind.at_start is not None and kind.active(self):
                kind.at_start(self, s)

    def before_step(self, s) -> None:
        """What each condition in force does before a step from t (in registry order)."""
        for kind in BOUNDARY_KINDS.values():
            if kind.active(self):
                kind.before_step(self, s)

    def after_motion(self, s) -> None:
        """What each condition in force books once the blocks have moved (the step's new
        velocities, before the forces at t + dt)."""
        for kind in BOUNDARY_KINDS.values():
            if kind.after_motion is not None and kind.active(self):
                kind.after_motion(self, s)

    # ------------------------------------------------------------------ velocities
    def release(self, gids) -> None:
        """Blocks fixed, freed or given a new velocity: their histories end."""
        for h in self.histories:
            h[0] = h[0][~np.isin(h[0], gids)]
        self.histories = [h for h in self.histories if len(h[0])]

    def add_velocity(self, s, cond, gids, t0: float, motion_too: bool = True) -> None:
        """Prescribe ``cond`` on ``gids`` (global store and this rank's rows); ``motion_too``:
        also set the velocities (a restart takes them from its checkpoint)."""
        code = vfix_code(cond)
        self.release(gids)
        set_block_fields(s, gids, fixed=0, vfix=code)
        if cond.history is not None:
            self.histories.append([np.asarray(gids, np.int64), code, cond.history, t0])
        if not motion_too:
            return
        if code == motion.VFIX_ALL:
            v0 = history_velocity(cond.history, 0.0) if cond.history is not None \
                else np.array(cond.velocity, float)
            set_block_fields(s, gids, v=v0, w=cond.angular_velocity)
            b = s.blocks
            if b is not None:
                for r in np.nonzero(np.isin(b.gid, gids))[0]:  # L of the prescribed spin
                    R = quat_to_matrix(b.q[r])
                    b.L[r] = R @ (b.inertia[r] * (R.T @ b.w[r]))
        else:
            v0 = history_velocity(cond.history, 0.0) if cond.history is not None \
                else np.array(cond.velocity, float)
            for c in cond.components:
                k = "xyz".index(c)
                for store in (s.glob, s.share, s.blocks):
                    if store is not None and "v" in vars(store):  # see selection.set_block_fields
                        store.v[np.isin(store.gid, gids), k] = v0[k]

    def prescribe(self, s) -> None:
        """Before a step from t: the histories' velocities at t + dt/2 into ``v``.

        The integrator books the contacts' work on a prescribed block with the new velocity,
        ``F(t) . v(t + dt/2) dt``, exact for a constant velocity. For a changing one the
        joints' stored energy changes by the work at the step's mean velocity
        ``(v(t - dt/2) + v(t + dt/2)) / 2`` (the leap-frog's, as for a free block), so the
        difference is booked here, keeping the budget closed to round-off."""
        b = s.blocks
        n = s.n_owned
        t = s.time + 0.5 * s.dt
        for gids, code, hist, t0 in self.histories:
            rows = np.nonzero(np.isin(b.gid, gids))[0]
            if not len(rows):
                continue
            v = history_velocity(hist, t - t0)
            mask = np.ones(3, bool) if code == motion.VFIX_ALL else \
                np.array([bool(code & (motion.VFIX_X << k)) for k in range(3)])
            own = rows[rows < n]
            dv = (v[None] - b.v[own]) * mask
            b.work[own, motion.WORK_BOUNDARY] += 0.5 * s.dt * np.einsum(
                "ij,ij->i", b.force[own], dv)
            for k in np.nonzero(mask)[0]:
                b.v[rows, k] = v[k]

    # ------------------------------------------------------------------ stresses
    def add_stress(self, s, cond, gids) -> int:
        """Find the exposed faces of ``gids`` (on the global store's poses) and put the
        condition's stress on them; returns the number of faces."""
        g = s.glob
        faces = exposed_faces(g, np.asarray(gids, np.int64), s.ctol)
        gid, area, nb, cb = faces
        sig = np.array(cond.sigma(), float)
        self.f_gid = np.concatenate([self.f_gid, gid])
        self.f_area = np.concatenate([self.f_area, area])
        self.f_normal = np.concatenate([self.f_normal, nb])
        self.f_center = np.concatenate([self.f_center, cb])
        self.f_sigma = np.concatenate([self.f_sigma, np.repeat(sig[None], len(gid), axis=0)])
        return len(gid)

    def tractions(self, s) -> None:
        """``bforce``/``bmoment`` of this rank's owned blocks from their pose at t: the
        stresses, then the waves (their histories' velocities at t)."""
        b = s.blocks
        n = s.n_owned
        b.bforce[:] = 0.0
        b.bmoment[:] = 0.0
        if n == 0:
            return
        if len(self.f_gid):
            rows, mine = owned_rows(b, n, self.f_gid)
            R = rotations(b.q[rows])
            nw = np.einsum("fij,fj->fi", R, self.f_normal[mine])
            arm = np.einsum("fij,fj->fi", R, self.f_center[mine])
            f = self.f_area[mine, None] * np.einsum("fij,fj->fi", self.f_sigma[mine], nw)
            np.add.at(b.bforce, rows, f)
            np.add.at(b.bmoment, rows, np.cross(arm, f))
        self.rigid.wave_loads(s, history_velocity)

def _face_geometry(g, f):
    """Area, centroid and vertices (body frame) of face row ``f`` of a store."""
    vs = g.verts_local[g.face_verts[g.fvert_start[f]:g.fvert_start[f + 1]]]
    p0 = vs[0]
    area_vec = np.zeros(3)
    cen = np.zeros(3)
    for k in range(1, len(vs) - 1):
        a = 0.5 * np.cross(vs[k] - p0, vs[k + 1] - p0)
        area_vec += a
        cen += np.linalg.norm(a) * (p0 + vs[k] + vs[k + 1]) / 3.0
    area = float(np.linalg.norm(area_vec))
    return area, cen / area if area > 0 else vs.mean(axis=0), vs


def _inside(p, vs, n, tol) -> np.ndarray:
    """Whether points ``p`` (k, 3; in the planes) lie in the convex polygons ``vs`` (k
    polygons of 3-vectors, each ccw about its normal ``n`` (k, 3)): one vectorised test over
    every edge of every polygon (a zoned face meets hundreds of coplanar triangles)."""
    sizes = np.array([len(v) for v in vs], np.int64)
    owner = np.repeat(np.arange(len(vs)), sizes)
    start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    v = np.concatenate(vs).reshape(-1, 3)
    nxt = np.arange(len(v)) + 1
    nxt[start + sizes - 1] = start  # each polygon's last vertex closes on its first
    e = v[nxt] - v
    side = np.einsum("ij,ij->i", np.cross(e, p[owner] - v), n[owner])
    bad = side < -tol * np.linalg.norm(e, axis=1)
    return ~np.logical_or.reduceat(bad, start) if len(vs) else np.zeros(0, bool)


def exposed_faces(g, gids: np.ndarray, ctol: float, box=None):
    """(gid, area, normal, centroid) of the exposed faces of blocks ``gids`` of the global
    store ``g`` at its poses (body-frame normal and centroid); see the module docstring.
    ``box`` (``min``, ``max``): only the faces whose centroid is in it."""
    gid, rows = exposed_face_rows(g, gids, ctol, box)
    geo = [_face_geometry(g, f) for f in rows]
    return (gid, np.array([a for a, _, _ in geo], float),
            g.normals_local[rows].reshape(-1, 3),
            np.array([c for _, c, _ in geo], float).reshape(-1, 3))


def exposed_face_rows(g, gids: np.ndarray, ctol: float,
                      box=None) -> tuple[np.ndarray, np.ndarray]:
    """(gid, face row of ``g``) of the exposed faces of blocks ``gids`` (module docstring);
    ``box`` (``min``, ``max``): only those whose centroid (world) is in it."""
    R = rotations(g.q)
    world = lambda b, p: g.x[b] + R[b] @ p  # noqa: E731
    n_pieces = len(g.piece_block)
    alive = g.out[g.piece_block] == 0
    # piece boxes in the world, to find the pieces near a face
    vblock = g.piece_block[np.repeat(np.arange(n_pieces), np.diff(g.vert_start))]
    vworld = g.x[vblock] + np.einsum("vij,vj->vi", R[vblock], g.verts_local)
    lo = np.minimum.reduceat(vworld, g.vert_start[:-1], axis=0)
    hi = np.maximum.reduceat(vworld, g.vert_start[:-1], axis=0)
    if box is not None:  # (a face's centroid lies in its piece's box)
        bmin, bmax = np.asarray(box.min, float), np.asarray(box.max, float)
        touches = np.all(lo <= bmax, axis=1) & np.all(hi >= bmin, axis=1)
    out = ([], [])
    pieces: dict[int, tuple] = {}  # a piece's faces in the world: normals, centroids, polygons

    def faces_of(q):
        if q not in pieces:
            bq = g.piece_block[q]
            fs = range(g.face_start[q], g.face_start[q + 1])
            geo = [_face_geometry(g, h) for h in fs]
            pieces[q] = (g.normals_local[g.face_start[q]:g.face_start[q + 1]] @ R[bq].T,
                         np.array([world(bq, c) for _, c, _ in geo]).reshape(-1, 3),
                         [g.x[bq] + vh @ R[bq].T for _, _, vh in geo])
        return pieces[q]

    for b in gids:
        for p in range(g.piece_start[b], g.piece_start[b + 1]):
            if box is not None and not touches[p]:
                continue
            for f in range(g.face_start[p], g.face_start[p + 1]):
                area, cb, vs = _face_geometry(g, f)
                if area <= 0.0:
                    continue
                nb = g.normals_local[f]
                n = R[b] @ nb
                c = world(b, cb)
                if box is not None and not (np.all(c >= bmin) and np.all(c <= bmax)):
                    continue
                vw = g.x[b] + vs @ R[b].T
                flo, fhi = vw.min(axis=0) - ctol, vw.max(axis=0) + ctol
                near = np.nonzero(alive & np.all(lo <= fhi, axis=1) & np.all(hi >= flo, axis=1))[0]
                covered = False
                for q in near:
                    if q == p:
                        continue
                    m, chw, vhw = faces_of(q)
                    # antiparallel faces in the same plane, then the polygons
                    cand = np.nonzero((m @ n < -COVER_COS)
                                      & (np.abs((chw - c) @ n) <= ctol))[0]
                    if len(cand) and (
                            _inside(np.broadcast_to(c, (len(cand), 3)), [vhw[h] for h in cand],
                                    m[cand], ctol).any()
                            or _inside(chw[cand], [vw] * len(cand),
                                       np.broadcast_to(n, (len(cand), 3)), ctol).any()):
                        covered = True
                        break
                if not covered:
                    out[0].append(b)
                    out[1].append(f)
    return np.array(out[0], np.int64), np.array(out[1], np.int64)


def apply_conditions(s, source, where: tuple, t0: float, motion_too: bool = True) -> None:
    """Put the conditions of every kind that ``source`` (the scene's ``boundary:`` or a
    stage) lists on the blocks they select (every rank alike); ``where``: the key path of
    ``source`` in the scene (for messages), ``t0``: when their histories start. Zoned
    blocks take a condition at their gridpoints or faces (the kind's ``zoned``,
    pdem.deformable.conditions); the rows of those left wholly fixed count as fixed."""
    zoned = s.grids is not None
    for key, kind in BOUNDARY_KINDS.items():
        # a scene validated before its kind was registered has none of its conditions
        for j, cond in enumerate(getattr(source, key, ())):
            at = s.scene.at(*where, key, j)
            gids = selected(s, cond) if kind.rigid_select is None else kind.rigid_select(s, cond)
            hit = 0
            if zoned:
                gids = gids[~zoned_mask(s, gids)]
                if kind.zoned is None:
                    if owned_count(s, gridpoints(s, cond)):
                        raise ConfigError([f"{at}: does not act on zoned blocks"])
                else:
                    hit = kind.zoned(s.boundary, s, cond, t0, motion_too, at)
            if not len(gids) and not hit:
                raise ConfigError([f"{at}: selects no block"])
            if len(gids):
                try:
                    problem = kind.add(s.boundary, s, cond, gids, t0, motion_too)
                except ConditionError as exc:
                    raise ConfigError([f"{at}: {exc}"]) from None
                if problem and not hit:
                    raise ConfigError([f"{at}: {problem}"])
    if zoned:
        sync_fixed_rows(s)


def sync_fixed_rows(s) -> None:
    """Every zoned block's row ``fixed`` from its grid (collective): fixed when every
    gridpoint is held at zero velocity (the row then counts as a fixed block: no contacts with
    other fixed blocks), else free."""
    gids, fixed = wholly_fixed(s)
    set_block_fields(s, gids[fixed], fixed=1)
    set_block_fields(s, gids[~fixed], fixed=0)


def apply_scene(s) -> None:
    """The scene's ``boundary:`` on a new model state (every rank alike)."""
    s.boundary = Boundary()
    apply_conditions(s, s.scene.boundary, ("boundary",), 0.0)


def needs_every_block(scene, stages_only: bool = False) -> bool:
    """Whether a condition of the scene's ``boundary:`` (unless ``stages_only``) or of a
    stage finds what it acts on among every block (its kind's ``whole_scene``: exposed
    faces), so every rank keeps every block's geometry (at set-up; after it too where a
    stage's condition needs it)."""
    return any(kind.whole_scene and ((not stages_only and getattr(scene.boundary, key, ()))
                                     or any(getattr(st, key, ()) for st in scene.stages))
               for key, kind in BOUNDARY_KINDS.items())


@dataclass(frozen=True)
class BoundaryKind:
    """One kind of boundary condition, by its scene key (its name in :data:`BOUNDARY_KINDS`:
    ``boundary.<key>`` and a stage's ``<key>``, lists of conditions).

    ``condition``: the pydantic model of one condition, a
    :class:`pdem.config.schema.Selection` (the blocks it acts on) with the kind's own keys;
    registering the kind makes the key a field of ``boundary:`` and of every stage (the
    grammar's ``CONDITION_MODELS`` follows this registry), unregistering it takes it away.
    ``add(boundary, s, cond, gids, t0, motion_too)`` puts a condition on its selected
    blocks and returns None, or the text of why it cannot (named with the condition's key
    path); ``active(boundary)``: some condition of the kind is in force;
    ``before_step(boundary, s)``: its work before each step from t; ``at_start``: before
    the first step (None: nothing); ``whole_scene``: it looks for what it acts on among
    every block, so set-up keeps every block's geometry on every rank. A stage with an
    active condition steps in Python (the compiled loop runs none yet). A kind keeps its
    own state on the :class:`Boundary` (an attribute it sets in ``add``). ``zoned(boundary,
    s, cond, t0, motion_too, at)``: the condition on zoned blocks (their gridpoints or
    faces, pdem.deformable.conditions; collective), the number of zoned blocks it took;
    None: a kind that does not act on zoned blocks (a selection of one is refused).
    ``add`` may raise :class:`ConditionError` for what is wrong whatever else the condition
    takes (named with its key path). ``rigid_select(s, cond)``: the rigid blocks (gids,
    collective) ``add`` gets (None: :func:`pdem.selection.selected`, a range by the blocks'
    centroids); ``after_motion(boundary, s)``: what it books once the blocks have moved
    (None: nothing)."""

    condition: type[Selection]
    add: Callable[..., str | None]
    active: Callable[[Boundary], bool]
    before_step: Callable[[Boundary, object], None]
    at_start: Callable[[Boundary, object], None] | None = None
    whole_scene: bool = False
    zoned: Callable[..., int] | None = None
    rigid_select: Callable[..., np.ndarray] | None = None
    after_motion: Callable[[Boundary, object], None] | None = None

    def __post_init__(self):
        if not (isinstance(self.condition, type) and issubclass(self.condition, Selection)):
            raise TypeError(f"BoundaryKind.condition: {self.condition!r} is not a "
                            "pdem.config.schema.Selection (the blocks a condition acts on)")


def _add_velocity(boundary, s, cond, gids, t0, motion_too):
    boundary.add_velocity(s, cond, gids, t0, motion_too)


def _zoned_velocity(boundary, s, cond, t0, motion_too, at) -> int:
    """A velocity condition at the gridpoints it selects (the grids' count, collective)."""
    hits = gridpoints(s, cond)
    n = owned_count(s, hits)
    if n and any(cond.angular_velocity):
        raise ConfigError([f"{at}.angular_velocity: a zoned block's gridpoints take a "
                           "constant velocity, not a rotation (prescribe velocity components)"])
    v0 = history_velocity(cond.history, 0.0) if cond.history is not None \
        else np.array(cond.velocity, float)
    # (a stage's, once the energy budget has started, books what it changes)
    boundary.grid.fix(hits, ["xyz".index(c) for c in cond.components], v0, motion_too,
                      cond.history, t0, book=motion_too and s.energy_start is not None)
    return n


def by_faces(s, cond) -> np.ndarray:
    """The rigid blocks a face condition (quiet, wave) looks at: those its names and groups
    take (every block if neither); its range then takes their faces by centroid, as on
    zoned blocks (collective)."""
    return selected(s, cond.model_copy(update={"range": None}))


def _add_stress(boundary, s, cond, gids, t0, motion_too):
    if cond.wave is not None:
        if not boundary.rigid.add_wave(s, cond, gids, t0, _exposed(s)):
            return "the selected rigid blocks have no exposed face in range"
        return None
    if not boundary.add_stress(s, cond, gids):
        return "the selected blocks have no exposed face"
    return None


def _exposed(s):
    """(gid, area, normal, centroid) of the exposed faces of blocks ``gids`` of the scene's
    store whose centroid is in ``box``, as ``exposed(gids, box)``."""
    return lambda gids, box: exposed_faces(s.glob, gids, s.ctol, box)


def _zoned_stress(boundary, s, cond, t0, motion_too, at) -> int:
    """A boundary stress (or a wave) on the exposed surface faces of the zoned blocks it
    selects."""
    exposed = lambda gids: exposed_face_rows(s.glob, gids, s.ctol)  # noqa: E731
    if cond.wave is not None:
        return boundary.grid.add_wave(s, cond, cond.wave, t0, exposed)
    return boundary.grid.add_stress(s, cond, cond.sigma(), exposed)


def _prescribe(boundary, s):
    boundary.prescribe(s)
    boundary.grid.prescribe(s, history_velocity)


def _tractions(boundary, s):
    boundary.tractions(s)
    boundary.grid.tractions(s, history_velocity)


def _add_quiet(boundary, s, cond, gids, t0, motion_too):
    if not boundary.rigid.add_quiet(s, cond, gids, motion_too, _exposed(s), boundary.release):
        return "the selected rigid blocks have no exposed face in range"
    return None


def _zoned_quiet(boundary, s, cond, t0, motion_too, at) -> int:
    """Dashpots on the exposed surface faces of the zoned blocks it selects."""
    n = boundary.grid.add_quiet(s, cond, "normal" in cond.directions,
                                "shear" in cond.directions,
                                lambda gids: exposed_face_rows(s.glob, gids, s.ctol))
    if cond.release:
        # (a restart's replay frees them alike; their loads come with its checkpoint)
        boundary.grid.release_held(s, cond, motion_too,
                                   lambda gids: exposed_face_rows(s.glob, gids, s.ctol))
    return n


def _loaded(boundary) -> bool:
    """Whether the stresses' and waves' loads on rigid blocks were made this step (their
    kind zeroes ``bforce``/``bmoment`` first)."""
    return len(boundary.f_gid) > 0 or len(boundary.rigid.w_gid) > 0


def _dashpots(boundary, s):
    boundary.grid.dashpots(s)
    boundary.rigid.dashpots(s, _loaded(boundary))


def _start_dashpots(boundary, s):
    boundary.grid.dashpots(s)
    boundary.rigid.start_dashpots(s, _loaded(boundary))


def _book_dashpots(boundary, s):
    boundary.rigid.book_dashpots(s)


def _stress_select(s, cond):
    return by_faces(s, cond) if cond.wave is not None else selected(s, cond)


BOUNDARY_KINDS: Registry[BoundaryKind] = Registry("boundary condition")
# velocities first: their histories are written into v before the tractions are computed
BOUNDARY_KINDS.register("velocity", BoundaryKind(
    BoundaryVelocity, _add_velocity, lambda b: bool(b.histories or b.grid.histories),
    _prescribe, zoned=_zoned_velocity))
BOUNDARY_KINDS.register("stress", BoundaryKind(
    BoundaryStress, _add_stress,
    lambda b: (len(b.f_gid) > 0 or len(b.rigid.w_gid) > 0 or len(b.grid.t_gid) > 0
               or len(b.grid.w_gid) > 0),
    _tractions, at_start=_tractions, whole_scene=True, zoned=_zoned_stress,
    rigid_select=_stress_select))
# after the stresses: the dashpots' centred solve takes every other load of the step
BOUNDARY_KINDS.register("quiet", BoundaryKind(
    BoundaryQuiet, _add_quiet, lambda b: len(b.grid.q_gid) > 0 or len(b.rigid.d_gid) > 0,
    _dashpots,
    at_start=_start_dashpots, whole_scene=True, zoned=_zoned_quiet, rigid_select=by_faces,
    after_motion=_book_dashpots))
# the scene grammar's keys follow the kinds: one registration here, from anywhere, is a kind
CONDITION_MODELS.follow(BOUNDARY_KINDS, lambda kind: kind.condition)
