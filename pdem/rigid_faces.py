"""Quiet faces, wave input and released supports on rigid blocks (docs/dynamics.md, "Quiet
boundaries and wave input"): the state of the ``quiet`` and ``stress: wave:`` conditions on
rigid blocks' exposed faces, kept by pdem.boundary.Boundary as ``rigid`` (every rank holds
all of it, by gid), and its work each step (the physics: pdem.dynamics.quiet).

Each face keeps its area, body-frame normal and centroid and its material's impedances
``rho Cp``, ``rho Cs`` (a rigid material needs ``young`` and ``poisson``). Before each step,
after the boundary stresses and the waves (:meth:`RigidFaces.wave_loads`): the released
blocks' loads, then the dashpots' centred loads, into ``bforce``/``bmoment``; after the
motion, what the dashpots absorbed moves from the applied work to ``WORK_QUIET``. A
``release`` frees the held blocks among a quiet condition's and keeps the force and moment
that held them (summed contact by contact: :func:`contact_loads`).
"""

from __future__ import annotations

import json

import numpy as np

from .dynamics import motion
from .dynamics import quiet as dashpot
from .dynamics.damping import CombinedDamping, LocalDamping, ViscousDamping
from .errors import ConditionError, SimulationError
from .mpi import allgather
from .selection import set_block_fields


class RigidFaces:
    """The rigid blocks' quiet faces, wave faces and released blocks (every rank alike)."""

    def __init__(self):
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

    def faces(self, s, cond, gids, exposed):
        """The exposed faces of rigid blocks ``gids`` whose centroid (on the scene's poses)
        is in the condition's ``range``, with their material's ``(rho Cp, rho Cs)`` per
        face: ``(gid, area, n_b, c_b, coef (k, 2))``; ``exposed(gids, box)``: (gid, area,
        body-frame normal and centroid) of the exposed faces of blocks ``gids`` whose
        centroid is in ``box`` (pdem.boundary.exposed_faces)."""
        box = cond.range.box if cond.range is not None else None
        gid, area, nb, cb = exposed(np.asarray(gids, np.int64), box)
        imp = {int(g): rigid_impedances(s, int(g)) for g in np.unique(gid)}
        coef = np.array([imp[int(g)] for g in gid], float).reshape(-1, 2)
        return gid, area, nb, cb, coef

    def add_quiet(self, s, cond, gids, motion_too: bool, exposed, released) -> int:
        """Dashpots on the exposed faces of rigid blocks ``gids`` in the condition's range
        (:meth:`faces`), and with ``release`` the held ones among them freed
        (:meth:`release_held`; ``released(gids)``: their velocity histories end); the number
        of faces."""
        gid, area, nb, cb, coef = self.faces(s, cond, gids, exposed)
        if not len(gid):
            return 0
        if cond.release:
            self.release_held(s, np.unique(gid), motion_too, released)
        coef = coef * np.array([["normal" in cond.directions, "shear" in cond.directions]])
        self.d_gid = np.concatenate([self.d_gid, gid])
        self.d_area = np.concatenate([self.d_area, area])
        self.d_normal = np.concatenate([self.d_normal, nb])
        self.d_center = np.concatenate([self.d_center, cb])
        self.d_coef = np.concatenate([self.d_coef, coef])
        self.d_rate = self._dashpot_rate(s)
        return len(gid)

    def release_held(self, s, gids, motion_too: bool, released) -> None:
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
        released(held)
        self.r_gid = np.concatenate([self.r_gid, held])
        self.r_load = np.concatenate([self.r_load, load])

    def _reactions(self, s, gids) -> np.ndarray:
        """Minus the force (with gravity, applied and boundary loads) and moment on the
        blocks ``gids`` now (k, 6), every rank alike (collective); at the set-up, before any
        contact force, their gravity and applied force. The contacts' part is summed from
        each contact's force in key order (:func:`contact_loads`): a held block's own row
        lacks the contacts other ranks computed."""
        if s.blocks is None:
            g = s.glob
            f = g.applied_force[gids] + g.mass[gids, None] * s.gravity[None]
            return -np.concatenate([f, np.zeros_like(f)], axis=1)
        b, n = s.blocks, s.n_owned
        rows, mine = owned_rows(b, n, gids) if n else (np.zeros(0, np.int64),
                                                        np.zeros(len(gids), bool))
        f = (b.applied_force[rows] + b.bforce[rows]) + b.mass[rows, None] * s.gravity[None]
        part = [(int(g), f[k].tolist() + b.bmoment[rows[k]].tolist())
                for k, g in enumerate(gids[mine])]
        got = dict(r for p in allgather(s.comm, part) for r in p)
        loads = np.array([got[int(g)] for g in gids], float).reshape(-1, 6)
        # (the stage start then hands the freed blocks' contacts to their owners and sums
        # their forces afresh: pdem.stages.apply_stage)
        return -(contact_loads(s, gids) + loads)

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
        rows, mine = owned_rows(b, n, self.r_gid)
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

    def add_wave(self, s, cond, gids, t0: float, exposed) -> int:
        """A wave put in through the exposed faces of rigid blocks ``gids`` in the
        condition's range (:meth:`faces`, pdem.dynamics.quiet.wave_loads); the number of
        faces."""
        gid, area, nb, cb, coef = self.faces(s, cond, gids, exposed)
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
        rows, mine = owned_rows(b, n, self.d_gid)
        fixed = b.still if s.scene.solve.inactive is not None else b.fixed
        moves = (fixed[rows] == 0) & (b.vfix[rows] != motion.VFIX_ALL)
        if not moves.any():
            return None
        faces = np.nonzero(mine)[0][moves]
        blocks, index = np.unique(rows[moves], return_inverse=True)
        R = rotations(b.q[rows[moves]])
        d = dashpot.block_dashpots(index, len(blocks), self.d_area[faces], self.d_coef[faces],
                                   rotate(R, self.d_normal[faces]),
                                   rotate(R, self.d_center[faces]))
        return blocks, d, rotations(b.q[blocks])

    @staticmethod
    def _clear_loads(s, loaded: bool) -> None:
        """``bforce``/``bmoment`` zeroed unless ``loaded``: the boundary's stresses and
        waves were made this step (pdem.boundary.Boundary.tractions zeroes them first)."""
        if not loaded:
            s.blocks.bforce[:] = 0.0
            s.blocks.bmoment[:] = 0.0

    def start_dashpots(self, s, loaded: bool) -> None:
        """Before the run's first step: the released loads and the dashpots' loads at the
        start velocities (the staggered start, pdem.dynamics.motion.stagger_start, takes
        them in); ``loaded``: as :meth:`_clear_loads`."""
        self._clear_loads(s, loaded)
        self._released_loads(s)
        q = self._quiet_blocks(s)
        if q is None:
            return
        rows, d, _ = q
        b = s.blocks
        load = -dashpot.matvec(d, np.concatenate([b.v[rows], b.w[rows]], axis=1))
        b.bforce[rows] += load[:, :3]
        b.bmoment[rows] += load[:, 3:]

    def dashpots(self, s, loaded: bool) -> None:
        """Before a step from t: the released loads, then the quiet blocks' dashpot loads
        that make the step centred (pdem.dynamics.quiet.centred_dashpots), added to
        ``bforce``/``bmoment`` after the stresses and waves; kept for :meth:`book_dashpots`.
        ``loaded``: as :meth:`_clear_loads`."""
        self._pending = None
        self._clear_loads(s, loaded)
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

    def wave_loads(self, s, velocity_at) -> None:
        """The waves' loads at t on this rank's owned rows (``bforce``/``bmoment``, after the
        stresses), their histories' velocities ``velocity_at(history, t)``."""
        b, n = s.blocks, s.n_owned
        if not len(self.w_gid) or n == 0:
            return
        rows, mine = owned_rows(b, n, self.w_gid)
        R = rotations(b.q[rows])
        v_of = np.array([velocity_at(h, s.time - t0) for h, t0 in self.waves])
        f = dashpot.wave_loads(self.w_area[mine], self.w_coef[mine],
                               rotate(R, self.w_normal[mine]),
                               v_of[self.w_hist[mine]].reshape(-1, 3))
        np.add.at(b.bforce, rows, f)
        np.add.at(b.bmoment, rows, np.cross(rotate(R, self.w_center[mine]), f))


def owned_rows(b, n: int, gids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, mine)``: the owned rows of the entries of ``gids`` this rank owns (``mine``
    their mask)."""
    order = np.argsort(b.gid[:n])
    pos = np.searchsorted(b.gid[:n], gids, sorter=order)
    pos = np.minimum(pos, n - 1)
    rows = order[pos]
    mine = b.gid[rows] == gids
    return rows[mine], mine


def rotate(R: np.ndarray, x: np.ndarray) -> np.ndarray:
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


def rotations(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (k, 3, 3) of quaternions (k, 4) (w, x, y, z)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], 1)
