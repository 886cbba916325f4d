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
"""

from __future__ import annotations

import json
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
from .dynamics import quiet as dashpot
from .dynamics.damping import CombinedDamping, LocalDamping, ViscousDamping
from .dynamics.rotation import quat_to_matrix
from .errors import SimulationError
from .mpi import allgather
from .registry import Registry
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


class ConditionError(Exception):
    """A condition that cannot be put on the blocks it selects, whatever else it takes
    (:func:`apply_conditions` names it with its key path)."""


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
        # rigid blocks' quiet faces (pdem.dynamics.quiet), by face: gid, A, n_b, c_b, and the
        # impedances per area (rho Cp normal, rho Cs shear; zero for a direction not chosen)
        self.d_gid = np.zeros(0, np.int64)
        self.d_area = np.zeros(0)
        self.d_normal = np.zeros((0, 3))
        self.d_center = np.zeros((0, 3))
        self.d_coef = np.zeros((0, 2))
        self.d_rate = 0.0  # the largest lambda(M^-1 D) of a quiet block (1/s)
        self._pending = None  # this step's dashpot loads, booked after the motion
        # held rigid blocks a quiet condition released, by gid, and the force and moment that
        # held them (world; NaN until a restart's checkpoint gives them: restore_released)
        self.r_gid = np.zeros(0, np.int64)
        self.r_load = np.zeros((0, 6))
        # rigid blocks' faces taking a wave: as above, and the history's index in ``waves``
        self.waves: list[tuple] = []  # (VelocityHistory, t0)
        self.w_gid = np.zeros(0, np.int64)
        self.w_area = np.zeros(0)
        self.w_normal = np.zeros((0, 3))
        self.w_center = np.zeros((0, 3))
        self.w_coef = np.zeros((0, 2))
        self.w_hist = np.zeros(0, np.int64)
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
            rows, mine = _owned_rows(b, n, self.f_gid)
            R = _rotations(b.q[rows])
            nw = np.einsum("fij,fj->fi", R, self.f_normal[mine])
            arm = np.einsum("fij,fj->fi", R, self.f_center[mine])
            f = self.f_area[mine, None] * np.einsum("fij,fj->fi", self.f_sigma[mine], nw)
            np.add.at(b.bforce, rows, f)
            np.add.at(b.bmoment, rows, np.cross(arm, f))
        if len(self.w_gid):
            rows, mine = _owned_rows(b, n, self.w_gid)
            R = _rotations(b.q[rows])
            v_of = np.array([history_velocity(h, s.time - t0) for h, t0 in self.waves])
            f = dashpot.wave_loads(self.w_area[mine], self.w_coef[mine],
                                   _rotate(R, self.w_normal[mine]),
                                   v_of[self.w_hist[mine]].reshape(-1, 3))
            np.add.at(b.bforce, rows, f)
            np.add.at(b.bmoment, rows, np.cross(_rotate(R, self.w_center[mine]), f))

    # ------------------------------------------------------------------ quiet faces, waves
    def rigid_faces(self, s, cond, gids):
        """The exposed faces of rigid blocks ``gids`` whose centroid (on the scene's poses)
        is in the condition's ``range``, with their material's ``(rho Cp, rho Cs)`` per
        face: ``(gid, area, n_b, c_b, coef (k, 2))``."""
        box = cond.range.box if cond.range is not None else None
        gid, area, nb, cb = exposed_faces(s.glob, np.asarray(gids, np.int64), s.ctol, box)
        imp = {int(g): rigid_impedances(s, int(g)) for g in np.unique(gid)}
        coef = np.array([imp[int(g)] for g in gid], float).reshape(-1, 2)
        return gid, area, nb, cb, coef

    def add_quiet(self, s, cond, gids, motion_too: bool = True) -> int:
        """Dashpots on the exposed faces of rigid blocks ``gids`` in the condition's range
        (pdem.dynamics.quiet), and with ``release`` the held ones among them freed
        (:meth:`release_held`); the number of faces."""
        gid, area, nb, cb, coef = self.rigid_faces(s, cond, gids)
        if not len(gid):
            return 0
        if cond.release:
            self.release_held(s, np.unique(gid), motion_too)
        coef = coef * np.array([["normal" in cond.directions, "shear" in cond.directions]])
        self.d_gid = np.concatenate([self.d_gid, gid])
        self.d_area = np.concatenate([self.d_area, area])
        self.d_normal = np.concatenate([self.d_normal, nb])
        self.d_center = np.concatenate([self.d_center, cb])
        self.d_coef = np.concatenate([self.d_coef, coef])
        self.d_rate = self._dashpot_rate(s)
        return len(gid)

    def release_held(self, s, gids, motion_too: bool) -> None:
        """Free the held (fixed or prescribed) blocks of ``gids`` and keep, from now on, the
        force and moment that held them as constant loads (the held components': every one
        of a fixed or wholly prescribed block, the prescribed translations of another); with
        ``motion_too`` computed now (collective), else (a restart's replay) given by its
        checkpoint (:meth:`restore_released`)."""
        flags = s.scene_fields(("fixed", "vfix"))
        held = np.array([g for g in gids if flags.fixed[g] or flags.vfix[g]], np.int64)
        if not len(held):
            return
        code = np.where(flags.fixed[held] != 0, motion.VFIX_ALL, flags.vfix[held]).astype(int)
        mask = np.zeros((len(held), 6))
        mask[code == motion.VFIX_ALL] = 1.0
        for k in range(3):
            mask[(code != motion.VFIX_ALL) & ((code & (motion.VFIX_X << k)) != 0), k] = 1.0
        load = self._reactions(s, held) * mask if motion_too else np.full((len(held), 6),
                                                                          np.nan)
        set_block_fields(s, held, fixed=0, vfix=0)
        self.release(held)
        self.r_gid = np.concatenate([self.r_gid, held])
        self.r_load = np.concatenate([self.r_load, load])

    def _reactions(self, s, gids) -> np.ndarray:
        """Minus the force (with gravity, applied and boundary loads) and moment on the
        blocks ``gids`` now (k, 6), every rank alike (collective); at the set-up, before any
        contact force, their gravity and applied force. The contacts' part is summed from
        each contact's force in key order (:func:`contact_loads`): a held block's own row
        lacks the contacts other ranks computed; it is written into the owners' rows."""
        if s.blocks is None:
            g = s.glob
            f = g.applied_force[gids] + g.mass[gids, None] * s.gravity[None]
            return -np.concatenate([f, np.zeros_like(f)], axis=1)
        b, n = s.blocks, s.n_owned
        rows, mine = _owned_rows(b, n, gids) if n else (np.zeros(0, np.int64),
                                                        np.zeros(len(gids), bool))
        f = (b.applied_force[rows] + b.bforce[rows]) + b.mass[rows, None] * s.gravity[None]
        part = [(int(g), f[k].tolist() + b.bmoment[rows[k]].tolist())
                for k, g in enumerate(gids[mine])]
        got = dict(r for p in allgather(s.comm, part) for r in p)
        loads = np.array([got[int(g)] for g in gids], float).reshape(-1, 6)
        contact = contact_loads(s, gids)
        # the freed blocks' first step takes these contact sums: their owner now computes
        # all their contacts (a fixed block's own row summed only those it held)
        b.force[rows] = contact[mine, :3]
        b.moment[rows] = contact[mine, 3:]
        return -(contact + loads)

    def released(self) -> str:
        """The released blocks' loads (JSON, a checkpoint's attribute): ``[[gid, fx, fy, fz,
        mx, my, mz], ...]``."""
        return json.dumps([[int(g), *map(float, ld)] for g, ld in zip(
            self.r_gid, self.r_load, strict=True)])

    def restore_released(self, text: str) -> None:
        """The released blocks' loads from a checkpoint's attribute (:meth:`released`)."""
        for g, *ld in json.loads(text):
            self.r_load[self.r_gid == g] = ld

    def _released_loads(self, s) -> None:
        """The released blocks' loads onto this rank's owned rows (``bforce``/``bmoment``)."""
        b, n = s.blocks, s.n_owned
        if not len(self.r_gid) or n == 0:
            return
        rows, mine = _owned_rows(b, n, self.r_gid)
        if np.isnan(self.r_load).any():  # (every rank alike)
            raise SimulationError("a rigid block released by a quiet condition has no load "
                                  "(a checkpoint without the released loads)")
        np.add.at(b.bforce, rows, self.r_load[mine, :3])
        np.add.at(b.bmoment, rows, self.r_load[mine, 3:])

    def _dashpot_rate(self, s) -> float:
        """The largest ``lambda(M^-1 D)`` of the quiet blocks (body frame: pose-free; the
        true masses, which mass scaling only raises) (every rank alike)."""
        blocks, index = np.unique(self.d_gid, return_inverse=True)
        d = dashpot.block_dashpots(index, len(blocks), self.d_area, self.d_coef,
                                   self.d_normal, self.d_center)
        f = s.scene_fields(("mass", "inertia"))
        return max(dashpot.dashpot_rate(d[k], f.mass[g], f.inertia[g])
                   for k, g in enumerate(blocks))

    def add_wave(self, s, cond, gids, t0: float) -> int:
        """A wave put in through the exposed faces of rigid blocks ``gids`` in the
        condition's range (pdem.dynamics.quiet.wave_loads); the number of faces."""
        gid, area, nb, cb, coef = self.rigid_faces(s, cond, gids)
        if not len(gid):
            return 0
        self.waves.append((cond.wave, float(t0)))
        self.w_gid = np.concatenate([self.w_gid, gid])
        self.w_area = np.concatenate([self.w_area, area])
        self.w_normal = np.concatenate([self.w_normal, nb])
        self.w_center = np.concatenate([self.w_center, cb])
        self.w_coef = np.concatenate([self.w_coef, coef])
        self.w_hist = np.concatenate([self.w_hist, np.full(len(gid), len(self.waves) - 1)])
        return len(gid)

    def _quiet_blocks(self, s):
        """This rank's owned quiet blocks the integrator moves (not fixed, held inactive or
        wholly prescribed): ``(rows, D (k, 6, 6) world, R (k, 3, 3))``, or None."""
        b, n = s.blocks, s.n_owned
        if not len(self.d_gid) or n == 0:
            return None
        rows, mine = _owned_rows(b, n, self.d_gid)
        fixed = b.still if s.scene.solve.inactive is not None else b.fixed
        moves = (fixed[rows] == 0) & (b.vfix[rows] != motion.VFIX_ALL)
        if not moves.any():
            return None
        faces = np.nonzero(mine)[0][moves]
        blocks, index = np.unique(rows[moves], return_inverse=True)
        R = _rotations(b.q[rows[moves]])
        d = dashpot.block_dashpots(index, len(blocks), self.d_area[faces], self.d_coef[faces],
                                   _rotate(R, self.d_normal[faces]),
                                   _rotate(R, self.d_center[faces]))
        return blocks, d, _rotations(b.q[blocks])

    def _clear_loads(self, s) -> None:
        """``bforce``/``bmoment`` zeroed when no stress or wave on rigid faces set them
        this step (:meth:`tractions` does)."""
        if not (len(self.f_gid) or len(self.w_gid)):
            s.blocks.bforce[:] = 0.0
            s.blocks.bmoment[:] = 0.0

    def start_dashpots(self, s) -> None:
        """Before the run's first step: the dashpots' loads at the start velocities (the
        staggered start, pdem.dynamics.motion.stagger_start, takes them in)."""
        self._clear_loads(s)
        self._released_loads(s)
        q = self._quiet_blocks(s)
        if q is None:
            return
        rows, d, _ = q
        b = s.blocks
        load = -dashpot.matvec(d, np.concatenate([b.v[rows], b.w[rows]], axis=1))
        b.bforce[rows] += load[:, :3]
        b.bmoment[rows] += load[:, 3:]

    def dashpots(self, s) -> None:
        """Before a step from t: the quiet blocks' dashpot loads that make the step centred
        (pdem.dynamics.quiet.centred_dashpots), added to ``bforce``/``bmoment`` after the
        stresses and waves; kept for :meth:`book_dashpots`."""
        self._pending = None
        self._clear_loads(s)
        if not len(self.d_gid):
            return
        self._released_loads(s)
        args = s.damping_args()
        if isinstance(args, LocalDamping | CombinedDamping) \
                and args.alpha * s.dt * self.d_rate >= 1.0:
            raise SimulationError(
                f"step {s.step} (t={s.time:.6g} s): a rigid block's quiet faces take "
                f"dt lambda(M^-1 D) = {s.dt * self.d_rate:.3g} of its momentum a step; under "
                f"{type(args).__name__} (alpha {args.alpha:g}) that is unstable from "
                f"1/alpha = {1.0 / args.alpha:.3g} on: use damping none, viscous or rayleigh "
                "in a dynamic stage (local damping falsifies the dynamics a quiet boundary "
                "is for), or a smaller solve.timestep")
        q = self._quiet_blocks(s)
        if q is None:
            return
        rows, d, R = q
        b = s.blocks
        ms = b.mscale[rows]
        mass = b.mass[rows] * ms
        inertia = b.inertia[rows] * ms[:, None]
        iso = (inertia[:, 0] == inertia[:, 1]) & (inertia[:, 1] == inertia[:, 2])
        if s.scalar_inertia:  # as the integrator: the mean principal moment
            inertia = np.where(iso[:, None], inertia, inertia.mean(axis=1)[:, None])
            iso[:] = True
        world = np.zeros((len(rows), 3, 3))
        for i in range(3):
            for j in range(3):
                world[:, i, j] = np.where(iso, inertia[:, 0] * (i == j), (
                    R[:, i, 0] * inertia[:, 0] * R[:, j, 0] + R[:, i, 1] * inertia[:, 1]
                    * R[:, j, 1] + R[:, i, 2] * inertia[:, 2] * R[:, j, 2]))
        a = 0.5 * args.alpha * s.dt if isinstance(args, ViscousDamping) else 0.0
        force = b.force[rows] + (b.applied_force[rows] + b.bforce[rows]) \
            + b.mass[rows, None] * np.asarray(s.gravity)[None]
        moment = b.moment[rows] + b.bmoment[rows]
        code = b.vfix[rows].astype(np.int64)
        held = np.stack([(code & (motion.VFIX_X << k)) != 0 for k in range(3)], 1)
        u0 = np.concatenate([b.v[rows], b.w[rows]], axis=1)
        load = dashpot.centred_dashpots(d, mass, world, u0, b.L[rows].copy(), force, moment,
                                        s.dt, a, held)
        b.bforce[rows] += load[:, :3]
        b.bmoment[rows] += load[:, 3:]
        self._pending = (rows, load, u0, (~held).astype(float))

    def book_dashpots(self, s) -> None:
        """After the motion: what this step's dashpot loads took out, with the integrator's
        velocities (pdem.dynamics.quiet.absorbed), moved from the applied work (the
        integrator books every boundary load there) to ``WORK_QUIET``."""
        if self._pending is None:
            return
        rows, load, u0, free = self._pending
        self._pending = None
        b = s.blocks
        u1 = np.concatenate([b.v[rows], b.w[rows]], axis=1)
        e = dashpot.absorbed(load, u0, u1, free, s.dt)
        b.work[rows, motion.WORK_APPLIED] += e
        b.work[rows, motion.WORK_QUIET] += e


def _owned_rows(b, n: int, gids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, mine)``: the owned rows of the entries of ``gids`` this rank owns (``mine``
    their mask)."""
    order = np.argsort(b.gid[:n])
    pos = np.searchsorted(b.gid[:n], gids, sorter=order)
    pos = np.minimum(pos, n - 1)
    rows = order[pos]
    mine = b.gid[rows] == gids
    return rows[mine], mine


def _rotate(R: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``R x`` (k, 3) of stacked rotations (k, 3, 3) and vectors (k, 3), by explicit sums."""
    return np.stack([R[:, i, 0] * x[:, 0] + R[:, i, 1] * x[:, 1] + R[:, i, 2] * x[:, 2]
                     for i in range(3)], 1)


def rigid_impedances(s, gid: int) -> tuple[float, float]:
    """``(rho Cp, rho Cs)`` of rigid block ``gid``'s material (its young and poisson; a
    material without them is refused, naming the key)."""
    spec = s.specs[gid]
    m = s.scene.materials[spec.material]
    for key in ("young", "poisson"):
        if getattr(m, key) is None:
            raise ConditionError(
                f"the rigid block {spec.name!r}: its material {spec.material!r} has no {key} "
                f"(materials.{spec.material}.{key}): a rigid block's quiet and wave faces take "
                "rho Cp and rho Cs of its material's density, young and poisson")
    return dashpot.impedances(m.density, m.young, m.poisson)


def contact_loads(s, gids: np.ndarray) -> np.ndarray:
    """The contact force and moment (about the centroid) on each block of ``gids`` (k, 6),
    the same bits on any rank count (collective): each contact's force on B, ``fs + fn n``
    summed over its sub-contacts at their arms from A's centroid (as
    pdem.contact.forces.contact_forces makes it, ``fn`` by its law in its stored state),
    gathered from every rank holding it, each contact once, summed in key order."""
    c, b = s.contacts, s.blocks
    on = np.nonzero(np.isin(c.ga, gids) | np.isin(c.gb, gids))[0] if c.n else []
    part = []
    if len(on):
        fn = c.normal_forces(s.joints.kernel_args)
        pa, fs = c.sub["sc_pa"], c.sub["sc_fs"]
        for k in on:
            a, bb = int(c.ia[k]), int(c.ib[k])
            R, n = b.R[a], c.normal[k]
            acc = [0.0] * 6
            for j in range(int(c.sc_start[k]), int(c.sc_start[k + 1])):
                p = pa[j]
                r = [R[i, 0] * p[0] + R[i, 1] * p[1] + R[i, 2] * p[2] for i in range(3)]
                f = [fs[j, i] + fn[j] * n[i] for i in range(3)]
                acc = [acc[0] + f[0], acc[1] + f[1], acc[2] + f[2],
                       acc[3] + (r[1] * f[2] - r[2] * f[1]),
                       acc[4] + (r[2] * f[0] - r[0] * f[2]),
                       acc[5] + (r[0] * f[1] - r[1] * f[0])]
            d = b.x[a] - b.x[bb]
            fb = acc[:3]
            mb = [acc[3] + (d[1] * fb[2] - d[2] * fb[1]), acc[4] + (d[2] * fb[0] - d[0] * fb[2]),
                  acc[5] + (d[0] * fb[1] - d[1] * fb[0])]
            key = (int(c.pga[k]), int(c.pgb[k]))
            if int(c.ga[k]) in gids:
                part.append((key, int(c.ga[k]), [-x for x in fb] + [-x for x in acc[3:]]))
            if int(c.gb[k]) in gids:
                part.append((key, int(c.gb[k]), fb + mb))
    got = {(key, g): v for p in allgather(s.comm, part) for key, g, v in p}
    index = {int(g): i for i, g in enumerate(gids)}
    out = np.zeros((len(gids), 6))
    for key, g in sorted(got):
        out[index[g]] += got[(key, g)]
    return out


def _rotations(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (k, 3, 3) of quaternions (k, 4) (w, x, y, z)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], 1)


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
    R = _rotations(g.q)
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
        if not boundary.add_wave(s, cond, gids, t0):
            return "the selected rigid blocks have no exposed face in range"
        return None
    if not boundary.add_stress(s, cond, gids):
        return "the selected blocks have no exposed face"
    return None


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
    if not boundary.add_quiet(s, cond, gids, motion_too):
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


def _dashpots(boundary, s):
    boundary.grid.dashpots(s)
    boundary.dashpots(s)


def _start_dashpots(boundary, s):
    boundary.grid.dashpots(s)
    boundary.start_dashpots(s)


def _book_dashpots(boundary, s):
    boundary.book_dashpots(s)


def _stress_select(s, cond):
    return by_faces(s, cond) if cond.wave is not None else selected(s, cond)


BOUNDARY_KINDS: Registry[BoundaryKind] = Registry("boundary condition")
# velocities first: their histories are written into v before the tractions are computed
BOUNDARY_KINDS.register("velocity", BoundaryKind(
    BoundaryVelocity, _add_velocity, lambda b: bool(b.histories or b.grid.histories),
    _prescribe, zoned=_zoned_velocity))
BOUNDARY_KINDS.register("stress", BoundaryKind(
    BoundaryStress, _add_stress,
    lambda b: (len(b.f_gid) > 0 or len(b.w_gid) > 0 or len(b.grid.t_gid) > 0
               or len(b.grid.w_gid) > 0),
    _tractions, at_start=_tractions, whole_scene=True, zoned=_zoned_stress,
    rigid_select=_stress_select))
# after the stresses: the dashpots' centred solve takes every other load of the step
BOUNDARY_KINDS.register("quiet", BoundaryKind(
    BoundaryQuiet, _add_quiet, lambda b: len(b.grid.q_gid) > 0 or len(b.d_gid) > 0, _dashpots,
    at_start=_start_dashpots, whole_scene=True, zoned=_zoned_quiet, rigid_select=by_faces,
    after_motion=_book_dashpots))
# the scene grammar's keys follow the kinds: one registration here, from anywhere, is a kind
CONDITION_MODELS.follow(BOUNDARY_KINDS, lambda kind: kind.condition)
