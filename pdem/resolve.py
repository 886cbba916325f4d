"""Every ``auto`` value of a scene resolved once, from the scene and its built blocks.

The resolved numbers (CTOL, cell size, timestep, damping constant, ghost margin, rank grid,
...) are computed here and nowhere else, stored in every output and checkpoint, and read by
the stepper; a restart takes them from the checkpoint rather than re-deriving them.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import asdict, dataclass

import numpy as np

from .config.schema import MassScaling
from .deformable.motion import rayleigh_limit, undamped_limit
from .dynamics.damping import DAMPING
from .dynamics.kinematics import refresh_pose
from .dynamics.timestep import (
    critical_steps,
    limiting_block,
    mass_scale_factors,
    timestep_extremes,
    timestep_from_extremes,
)
from .errors import UserError
from .geometry import face_areas
from .mpi import (
    LOCAL,
    allgather,
    allreduce_max_array,
    exact_mean,
    exact_sum,
    first_extreme,
    kth_smallest,
)
from .parallel.decomposition import choose_dims

log = logging.getLogger("pdem")

# vertices within this fraction of CTOL of the common plane count as touching it
TOUCH_FRACTION = 0.5
# u_acc trigger of a block's remap into the cell space (pdem.stepper), as a fraction of CTOL.
# 3DEC remaps at CTOL; at CTOL/2 no pair can close a gap larger than CTOL unseen (each block
# moves less than CTOL/2 between searches), so a contact always exists before two blocks touch.
REMAP_FRACTION = 0.5
# partial mass scaling is refused when the blocks it would scale carry more than this share
# of the free blocks' mass: the dynamics of most of the model would then be the scaled one
# (use a smaller timestep, or mass_scaling: true for a static solve)
MAX_SCALED_MASS_FRACTION = 0.5
# the start-up log suggests partial mass scaling when the block limiting the step is this
# many times below the median block's critical step
SUGGEST_RATIO = 10.0


@dataclass(frozen=True)
class Resolved:
    ctol: float  # contact tolerance CTOL (m)
    cell_size: float  # cell-space cell edge (m)
    overlap_tolerance: float  # initial overlap allowed (m)
    snap_tol: float  # common-plane vertex snap tolerance (m), one for every rank
    refresh_tolerance: float  # motion that makes a resting contact's geometry stale (m)
    dt: float  # timestep (s)
    alpha: float  # damping constant at the start (adaptive: the servo's start value)
    margin: float  # ghost margin (m)
    dims: tuple[int, int, int]  # ranks per axis
    domain_lo: tuple[float, float, float]  # decomposition box
    domain_hi: tuple[float, float, float]
    ref_force: float  # unbalanced-ratio scale (N)
    speed_limit: float  # runaway threshold at t = 0 (m/s)
    speed_growth: float  # its growth per second (m/s2)

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @staticmethod
    def from_json(text: str) -> Resolved:
        d = json.loads(text)
        d["dims"] = tuple(d["dims"])
        d["domain_lo"] = tuple(d["domain_lo"])
        d["domain_hi"] = tuple(d["domain_hi"])
        return Resolved(**d)


def block_sizes(specs, gids=None) -> np.ndarray:
    """Equivalent size (cube root of the volume) of every block, gid order, or of blocks
    ``gids`` (a SpecTable's)."""
    if hasattr(specs, "volume"):  # a SpecTable (after set-up): the column
        return np.asarray(specs.volume if gids is None else specs.volume[gids],
                          float) ** (1.0 / 3.0)
    return np.array([s.volume for s in specs]) ** (1.0 / 3.0)


def smallest_size(specs) -> float:
    """The smallest block's equivalent size: over the distinct volumes of a SpecTable's
    column (one a run: the same value as over every block, without a per-block array)."""
    if hasattr(specs, "volume"):
        return float((specs.volume.run_values() ** (1.0 / 3.0)).min())
    return float(block_sizes(specs).min())


def surface_areas(specs) -> np.ndarray:
    """Each block's surface (its pieces' face areas summed, ``spec.face_areas.sum()``),
    vectorised: the areas in one batch, one-piece blocks summed row-wise in stacks of equal
    face counts (numpy sums each row as it sums the block's 1-D array: bitwise the same)."""
    if hasattr(specs, "surface"):  # a SpecTable (after set-up): the sums kept at release
        return np.array(specs.surface)
    face_areas([p for s in specs if s.pieces is not None for p in s.pieces])  # one batch
    surf = np.empty(len(specs))
    stacks: dict[int, list[int]] = {}
    for r, s in enumerate(specs):
        if s.pieces is None:  # released after set-up: its sum kept (the same bits)
            surf[r] = s.surface
        elif len(s.pieces) == 1:
            stacks.setdefault(s.pieces[0].n_faces, []).append(r)
        else:
            surf[r] = s.face_areas.sum()
    for rows in stacks.values():
        surf[rows] = np.array([specs[r].pieces[0].face_areas() for r in rows]).sum(axis=1)
    return surf


def estimated_stiffness(specs, joints, gids=None) -> np.ndarray:
    """Per block, the stiffness of contacts on a third of its surface (top and bottom of a
    cube): the timestep must be stable before the first contact forms, and must not depend
    on which contacts a rank holds. ``gids``: of these blocks only (a SpecTable's)."""
    kmax = float(np.maximum(joints.kn, joints.ks).max())
    surf = surface_areas(specs) if gids is None else np.asarray(specs.surface[gids], float)
    # an absurd stiffness overflows to inf (dt = 0), refused by preflight.check_derived with
    # the joint named; numpy's warning would only add noise before that message
    with np.errstate(over="ignore"):
        return kmax * surf / 3.0


def zoned_rows(scene, specs, gid) -> np.ndarray | None:
    """Whether each block of ``gid`` is zoned (None for a scene without ``zones``): by its
    scene entry, the same on every rank and in a restart's replay."""
    entries = np.array([b.zones is not None for b in scene.blocks], bool)
    if not entries.any():
        return None
    gid = np.asarray(gid, np.int64)
    entry = np.asarray(specs.entry)[gid] if hasattr(specs, "volume") \
        else np.array([specs[g].entry for g in gid], np.int64)
    return entries[entry]


def _rigid_fixed(scene, rows, zoned):
    """The ``fixed`` flags the rigid estimate reads: without mass scaling a zoned block
    counts as fixed (it is no rigid block: its grid bounds its own step, eq. 84 with its
    joint springs, pdem.deformable.store.GridStore); with mass scaling as it is (the grids
    are scaled to the rigid step, which counts them as blocks)."""
    if zoned is None or scene.solve.mass_scaling:
        return rows.fixed
    return np.where(zoned, 1, rows.fixed).astype(rows.fixed.dtype)


def scene_timestep(scene, rows, k, names=None, key: str = "solve.mass_scaling.timestep",
                   comm=LOCAL, n: int | None = None, zoned: np.ndarray | None = None) -> float:
    """The step (eq. 87 + rotational bound); with mass scaling, sets ``rows.mscale`` (eq. 89;
    partial: only the blocks whose own critical step is below ``timestep``).

    ``zoned``: which rows are zoned blocks (:func:`zoned_rows`; None: a scene without
    zones). Without mass scaling the step is the rigid blocks' alone (the grids' own step is
    taken with it by pdem.deformable.store.GridStore), ``inf`` when no rigid block is free.

    ``rows``: the per-block fields (gid, mass, inertia, radius, fixed, mscale) of the blocks
    this rank holds, ``k`` their stiffness estimates (:func:`estimated_stiffness`, from the
    blocks' surfaces and the stiffest joint, not from the contacts of the moment: the same on
    every rank and after a restart, which recomputes them from the scene, and each stage's at
    its start, see pdem.stages). The first ``n`` rows (default all) are this rank's own, the
    blocks no other rank counts (its build share, or the blocks it owns): the step is reduced
    over theirs on ``comm`` (minima and maxima, exact sums for the means: the same bits on any
    rank count). Every row's ``mscale`` is set.

    Rayleigh damping's stiffness term (``beta``, :attr:`pdem.config.schema.Damping.rayleigh`)
    puts dashpots on the joints (pdem.contact.forces.dashpot), which lower the stable step as
    in the zones (:func:`pdem.deformable.motion.rayleigh_limit`): the estimate is ``frac``
    times the damped limit of the undamped critical step ``dt_crit``, ``dt_crit (sqrt(1 +
    xi^2) - xi)``, ``xi = beta / dt_crit``; with mass scaling the blocks are made heavy enough
    for ``dt`` under the dashpots."""
    ts = scene.solve.timestep
    ms = scene.solve.mass_scaling
    n = len(rows.mass) if n is None else n
    beta = scene.solve.damping.rayleigh[1]
    if isinstance(ms, MassScaling):
        # partial (dynamic) scaling: the light blocks are made heavy enough for `timestep`
        dt = ms.timestep
        rows.mscale[:] = mass_scale_factors(rows.mass, k, damped_target(dt, ts.frac, beta),
                                            ts.frac, rows.inertia, rows.radius)
        _check_partial(rows, dt, names, key, comm, n)
    elif ms:
        # static solve: every block gets the critical step of the mean block (eq. 89)
        free = rows.fixed[:n] == 0
        dt = ts.dt or ts.frac * 2.0 * math.sqrt(
            exact_mean(comm, rows.mass[:n][free]) / exact_mean(comm, k[:n][free]))
        rows.mscale[:] = mass_scale_factors(rows.mass, k, damped_target(dt, ts.frac, beta),
                                            ts.frac, rows.inertia, rows.radius)
    elif ts.dt is not None:
        dt = ts.dt
    else:
        fixed = _rigid_fixed(scene, rows, zoned)
        extremes = allreduce_max_array(comm, timestep_extremes(
            rows.mass[:n], k[:n], rows.inertia[:n], rows.radius[:n], fixed[:n],
            rows.mscale[:n]))
        if beta > 0.0:  # the joints' dashpots: the damped limit of the critical step
            dt = ts.frac * rayleigh_limit(timestep_from_extremes(1.0, extremes), beta)
        else:
            dt = timestep_from_extremes(ts.frac, extremes)
        if zoned is not None:
            return float(dt)  # inf: no free rigid block, the grids' step alone
    if not math.isfinite(dt):
        raise UserError("solve.timestep: no free block, cannot choose a timestep; give dt")
    return float(dt)


def damped_target(dt: float, frac: float, beta: float) -> float:
    """The undamped step mass scaling aims at so that ``dt`` is stable under the joints'
    Rayleigh dashpots ``beta``: ``frac`` times the undamped limit whose damped limit is
    ``dt / frac`` (:func:`pdem.deformable.motion.undamped_limit`); ``dt`` itself when
    ``beta`` is 0."""
    if beta <= 0.0:
        return dt
    return frac * undamped_limit(dt / frac, beta)


def _name(names, g: int) -> str:
    return repr(names[g]) if names is not None else f"#{g}"


def _count(comm, mask) -> int:
    return sum(allgather(comm, int(np.count_nonzero(mask))))


def _largest_factor(rows, free, comm, n: int):
    """``(factor, gid)`` of the free block with the largest mass scale (the first in gid
    order of equal ones), over every rank's own rows; None without a free block."""
    msc = rows.mscale[:n]
    local = None
    if free.any():
        r = int(np.argmax(np.where(free, msc, -np.inf)))
        local = (-float(msc[r]), int(rows.gid[r]))
    found = first_extreme(comm, local)
    return None if found is None else (-found[0], found[1])


def _check_partial(rows, dt: float, names, key: str, comm=LOCAL, n: int | None = None) -> None:
    """Refuse partial scaling that would scale most of the model (by mass)."""
    n = len(rows.mass) if n is None else n
    free = rows.fixed[:n] == 0
    mass, msc = rows.mass[:n], rows.mscale[:n]
    if not all(allgather(comm, bool(np.isfinite(msc).all()))):
        raise UserError(f"{key}: the blocks' stiffness estimate overflows, so no mass scale "
                        "makes them stable: a joint's kn or ks is far outside the usual range "
                        "(docs/limits.md)")
    scaled = free & (msc > 1.0)
    total, heavy = exact_sum(comm, np.stack([np.where(free, mass, 0.0),
                                             np.where(scaled, mass, 0.0)], axis=1))
    share = float(heavy) / float(total) if total > 0.0 else 0.0
    if share > MAX_SCALED_MASS_FRACTION:
        factor, g = _largest_factor(rows, free, comm, n)
        raise UserError(
            f"{key}: {dt:.4g} s would scale {_count(comm, scaled)} of {_count(comm, free)} "
            f"free blocks, {100.0 * share:.3g} % of the free mass (more than "
            f"{100.0 * MAX_SCALED_MASS_FRACTION:g} %; largest factor {factor:.4g} on "
            f"block {_name(names, g)}): that is no longer partial scaling; give a smaller "
            "timestep, or mass_scaling: true for a static solve")


def mass_scaling_summary(rows, comm=LOCAL, n: int | None = None) -> dict:
    """The inertia partial mass scaling added (free blocks): how many blocks, the added mass
    (kg and % of the free mass), the largest factor and its block (gid). ``rows``: mass,
    mscale, fixed and gid of this rank's blocks, its own the first ``n`` (default all),
    reduced over ``comm`` (exact sums)."""
    n = len(rows.mass) if n is None else n
    free = rows.fixed[:n] == 0
    mass, msc = rows.mass[:n], rows.mscale[:n]
    scaled = free & (msc > 1.0)
    added, total = (float(v) for v in exact_sum(comm, np.stack(
        [np.where(scaled, mass * (msc - 1.0), 0.0), np.where(free, mass, 0.0)], axis=1)))
    largest = _largest_factor(rows, free, comm, n)
    return {"blocks": _count(comm, scaled), "free_blocks": _count(comm, free),
            "added_mass": added,
            "added_percent": 100.0 * added / total if total > 0.0 else 0.0,
            "model_mass": total, "max_factor": largest[0] if largest else 1.0,
            "max_block": largest[1] if largest else -1}


def timestep_report(scene, rows, k, dt: float, names, comm=LOCAL,
                    n: int | None = None, zoned: np.ndarray | None = None) -> list[str]:
    """The start-up log lines about the step: which block limits it and by how much (no mass
    scaling or a fixed dt), or the inertia partial mass scaling added. ``rows``, ``k``,
    ``comm``, ``n``, ``zoned``: as :func:`scene_timestep`'s (the median of the blocks' critical
    steps by an exact distributed selection, pdem.mpi.kth_smallest). In a scene with zones the
    block named is the rigid blocks' (the grids' step has its own line, GridStore.resolve)."""
    ts = scene.solve.timestep
    ms = scene.solve.mass_scaling
    n = len(rows.mass) if n is None else n
    fixed = _rigid_fixed(scene, rows, zoned)
    free = fixed[:n] == 0
    if not _count(comm, free) or not (math.isfinite(dt) and dt > 0.0):
        return []  # refused by preflight.check_derived, naming the joint
    if isinstance(ms, MassScaling):
        r = mass_scaling_summary(rows, comm, n)
        if not r["blocks"]:
            return [f"partial mass scaling to dt = {dt:.3g} s: no block needed it"]
        return [f"partial mass scaling to dt = {dt:.3g} s: {r['blocks']} of {r['free_blocks']} "
                f"free blocks scaled, added inertia {r['added_mass']:.4g} kg "
                f"({r['added_percent']:.3g} % of the free blocks' {r['model_mass']:.4g} kg), "
                f"largest factor {r['max_factor']:.4g} on block {_name(names, r['max_block'])}"
                " (scaled blocks keep their weight: they accelerate factor times slower and "
                "ring sqrt(factor) times slower on their contacts)"]
    if ms:
        return []
    mass, kk, inertia, radius, msc = (rows.mass[:n], k[:n], rows.inertia[:n], rows.radius[:n],
                                      rows.mscale[:n])
    steps = critical_steps(mass, kk, ts.frac, inertia, radius, msc)
    own = steps[free]
    own = own[np.isfinite(own)]
    n_own = _count(comm, np.ones(len(own), bool))
    k_max = float(allreduce_max_array(comm, np.array([kk[free].max(initial=-np.inf)]))[0])
    local = limiting_block(mass, kk, ts.frac, inertia, radius, fixed[:n], msc, k_max)
    if local is not None:  # its own critical step rides along
        local = (local[0], int(rows.gid[local[1]]), float(steps[local[1]]))
    found = first_extreme(comm, local)
    if found is None or not n_own:
        return []
    _, g, mine = found
    median = kth_smallest(comm, own, n_own // 2)
    if not mine > 0.0:
        return []
    what = "the step" if zoned is None else "the rigid blocks' step"
    if ts.dt is None:
        line = f"block {_name(names, g)} limits {what}: its critical step {mine:.3g} s"
    else:
        line = (f"solve.timestep.dt = {dt:.3g} s; block {_name(names, g)} has the smallest "
                f"critical step{'' if zoned is None else ' of the rigid blocks'}, {mine:.3g} s")
    if median >= 2.0 * mine:
        line += (" is" if ts.dt is None else ",") + \
            f" {median / mine:.3g} x below the median {median:.3g} s"
    beta = scene.solve.damping.rayleigh[1]
    undamped = damped_target(dt, ts.frac, beta) if ts.dt is None else dt
    if ts.dt is None and undamped < mine * (1.0 - 1e-9):
        line += (" (eq. 87 pairs its mass with the stiffest block's stiffness: dt = "
                 f"{undamped:.3g} s)")
    if ts.dt is None and beta > 0.0:
        line += (f"; Rayleigh damping's dashpots on the joints (beta = {beta:.3g} s) lower it "
                 f"{undamped / dt:.3g} x, to {dt:.3g} s")
    if median > SUGGEST_RATIO * mine:
        line += f"; consider solve.mass_scaling: {{timestep: {_round_down(median):.2g}}}"
    return [line]


def _round_down(x: float) -> float:
    """``x`` cut to two significant digits (a suggested step never above the one it quotes)."""
    unit = 10.0 ** (math.floor(math.log10(x)) - 1)
    return math.floor(x / unit) * unit


def damping_alpha(d, current: float | None = None) -> float:
    """The damping constant of ``solve.damping`` ``d``: Rayleigh's mass-proportional
    constant, the given ``alpha``, the mode's default, or (a stage's viscous damping without
    alpha) the ``current`` one."""
    if d.mode == "rayleigh":
        return d.rayleigh[0]
    if d.alpha is not None:
        return d.alpha
    default = DAMPING[d.mode].default_alpha
    if default is not None:
        return default
    if current is None:
        raise UserError(f"solve.damping.alpha: {d.mode} damping needs alpha (1/s)")
    return current


def _alpha(scene) -> float:
    return damping_alpha(scene.solve.damping)


def contact_tolerance(scene, specs) -> float:
    """CTOL: ``contact.ctol``, or 2% of the smallest block's equivalent size."""
    cs = scene.contact
    return float(0.02 * smallest_size(specs)) if cs.ctol == "auto" else float(cs.ctol)


def resolve(scene, comm_size: int, specs, glob, joints, verts_max: float | None = None,
            rows=None, comm=LOCAL) -> Resolved:
    """Resolve the scene's ``auto`` values for the scene's blocks (with mass scaling
    ``mscale`` is set here, on ``rows``).

    ``verts_max``: the largest world vertex coordinate (absolute) of every block, when
    ``glob`` has no geometry (each rank built its share, pdem.state); else ``glob`` has the
    geometry and its poses are refreshed here. ``rows``: the store whose rows hold the
    per-block fields read (envelopes ``lo``/``hi`` padded by CTOL/2, velocities, applied
    forces, mass, inertia, radius, fixed): this rank's build share, reduced over ``comm``
    (maxima and minima, and exact sums for the means, so the same bits on any rank count);
    default ``glob``, every block. ``point_area`` and ``mscale`` are set on ``rows``."""
    cs = scene.contact
    rows = glob if rows is None else rows
    ctol = contact_tolerance(scene, specs)
    has_table = hasattr(specs, "volume")
    sizes = block_sizes(specs, rows.gid if has_table else None)
    rows.point_area[:] = cs.point_area * sizes**2 if has_table \
        else (cs.point_area * sizes**2)[rows.gid]
    if verts_max is None:
        refresh_pose(glob, 0.5 * ctol)
        verts_max = float(np.abs(glob.verts_world).max(initial=1.0))
    lo, hi = rows.lo, rows.hi
    free = rows.fixed == 0
    any_free = sum(allgather(comm, int(free.sum()))) > 0
    ext = (hi - lo)[free] if any_free else hi - lo
    cell_size = exact_mean(comm, ext.max(axis=1, initial=0.0)) if cs.cell_size == "auto" \
        else float(cs.cell_size)
    # the timestep's reads of this rank's rows (mass, inertia, radius, fixed; mscale set)
    k = estimated_stiffness(specs, joints, rows.gid if hasattr(specs, "surface") else None)
    # a SpecTable's names column (read by index, in messages), or a list's
    names = specs.names if hasattr(specs, "names") else [sp.name for sp in specs]
    zoned = zoned_rows(scene, specs, rows.gid)
    dt = scene_timestep(scene, rows, k, names, comm=comm, zoned=zoned)
    for line in timestep_report(scene, rows, k, dt, names, comm, zoned=zoned):
        log.info("%s", line)
    # Runaway threshold: no block can honestly move faster than its start speed plus a fall
    # across the whole model (or what gravity and applied loads add over time); ten times
    # that is a blow-up, typically a timestep too large for the stiffness.
    gravity = np.array(scene.gravity, float)
    acc = float(np.linalg.norm(gravity))
    # maxima (order-free: the same bits on any rank count) of this rank's rows, then all's;
    # the box's low corner as the maximum of -lo
    box = np.concatenate([-lo.min(0, initial=np.inf), hi.max(0, initial=-np.inf)])
    applied = np.linalg.norm(rows.applied_force[free], axis=1) / rows.mass[free]
    speed = np.linalg.norm(rows.v, axis=1) + np.linalg.norm(rows.w, axis=1) * rows.radius
    most = allreduce_max_array(comm, np.concatenate(
        [box, [applied.max(initial=-np.inf), speed.max(initial=0.0)]]))
    domain_lo, domain_hi = -most[:3], most[3:6]
    if any_free:
        acc += float(most[6])
    size = float(np.linalg.norm(domain_hi - domain_lo))
    v0 = float(most[7])
    if any_free:
        ref = np.linalg.norm(rows.mass[free, None] * gravity + rows.applied_force[free], axis=1)
        ref_force = exact_mean(comm, ref) or 1.0
    else:
        ref_force = 1.0
    par = scene.parallel
    dims = choose_dims(comm_size, domain_hi - domain_lo, gravity) if par.dims == "auto" \
        else list(par.dims)
    return Resolved(
        ctol=float(ctol),
        cell_size=cell_size,
        overlap_tolerance=0.1 * ctol if cs.overlap_tolerance == "auto"
        else float(cs.overlap_tolerance),
        snap_tol=1e-9 * max(1.0, verts_max),
        refresh_tolerance=cs.refresh_tolerance * ctol,
        dt=dt,
        alpha=float(_alpha(scene)),
        margin=cell_size if par.margin == "auto" else float(par.margin),
        dims=tuple(int(d) for d in dims),
        domain_lo=tuple(float(v) for v in domain_lo),
        domain_hi=tuple(float(v) for v in domain_hi),
        ref_force=ref_force,
        speed_limit=10.0 * (v0 + math.sqrt(2.0 * acc * size)) + 1.0,
        speed_growth=2.0 * acc,
    )
