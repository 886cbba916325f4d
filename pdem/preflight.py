"""Pre-flight: what a scene will cost and whether it can run, checked before anything is built.

Two stages, both called from :meth:`pdem.state.ModelState.create` (so ``pdem check`` and
``pdem run`` refuse the same scenes):

* :func:`preflight` reads only the scene: the block count the generators (``array``,
  ``random``) imply, the contacts and memory per rank that follow, against ``limits:``;
  physical parameters outside their usual range are logged as warnings.
* :func:`check_derived` reads the built blocks and resolved values: the timestep is finite
  and positive, ``time``/dt steps are representable, and gravity does not push a free block
  deeper into its support than a fraction of its size (a joint far too soft).

Every refusal is a :class:`ConfigError` naming the key path, the number and the limit.
See docs/limits.md for how the numbers were chosen.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass

import numpy as np

from .config.errors import ConfigError
from .config.sizes import parse_bytes
from .model.blocks import VERT_ROW
from .model.fields import BLOCK, CONTACT, HELD_WIDTH, SUB, held_width
from .model.shapes import shape_size
from .mpi import LOCAL, allgather

log = logging.getLogger("pdem")

# contacts per block in a dense packing: each block touches 6-14 neighbours, a contact is shared
# by two blocks; 8 is the upper end of what the example scenes reach (conservative)
CONTACTS_PER_BLOCK = 8
# sub-contacts per contact: face-face contacts carry one per vertex of the overlap polygon
SUBS_PER_CONTACT = 6
# Python objects per block (BlockSpec, ConvexPolyhedron and its arrays), measured with
# tracemalloc on 2 500 boxes and 10-vertex random polyhedra: about 2.3 KB, rounded up
PY_BYTES_PER_BLOCK = 4096
# what every rank makes and keeps of every scene block at set-up when it builds only its share
# (a spec without shape, the gathered catalogue and spec columns, and the heap they leave):
# bench/scale.py's fit on the cube stack, 0.48 KB, rounded up
SCENE_BYTES_PER_BLOCK = 1024
# a rank holds its owned blocks plus ghosts; a slab of ghosts about as thick as a block on each
# side of a brick, at most as many again as it owns
GHOST_FACTOR = 2.0
# the fraction of physical memory the ranks may plan for by default: the rest is the OS, MPI's
# buffers, HDF5's chunk cache and numba's compiled code. The estimate is of the set-up peak
# (bench/scale.py, 10^6 cubes: 9.26 GiB estimated, 7.15 GiB measured on 2 ranks; 10.9 against
# 11.3 GiB on 1)
MEMORY_FRACTION = 0.85
# static overlap m g / (kn A) beyond this fraction of the block size: the joint is too soft for
# the load (the contact detection and the common plane assume small overlaps)
MAX_STATIC_OVERLAP = 0.1
# time advances by adding dt: past 2**52 steps t + dt == t in double precision, the end time is
# never reached
MAX_TIME_STEPS = 2**52
# a block may move at most this fraction of CTOL in one step: the search runs when a block's
# accumulated motion passes CTOL/2 (pdem.resolve.REMAP_FRACTION), so a block that jumps further
# in one step can land inside (or beyond) a thin block before any contact exists (tunnelling;
# tests/extremes/test_extreme_impact.py)
MAX_STEP_MOTION = 0.5

# documented physical ranges: outside them a warning is logged, nothing is refused
# (name, key path pattern, lo, hi, units, what usual values are)
STIFFNESS_RANGE = (1.0e6, 1.0e13)  # Pa/m: soft clay-filled joints to intact hard rock
DENSITY_RANGE = (100.0, 25000.0)  # kg/m3: foams/wood to the densest metals
GRAVITY_MAX = 100.0  # m/s2: ten g (centrifuge models go further, on purpose)


def _bytes_text(n: float) -> str:
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} B"


def machine_memory() -> float:
    """Physical memory of this machine in bytes (inf when the OS does not say)."""
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return math.inf


def _row_bytes(fields) -> int:
    return sum(f.width * np.dtype(f.dtype).itemsize for f in fields)


@dataclass(frozen=True)
class Estimate:
    blocks: int
    contacts: int  # per rank
    bytes_per_rank: float
    max_blocks: int
    max_bytes: float

    def __str__(self) -> str:
        return (f"{self.blocks} blocks, ~{self.contacts} contacts and ~"
                f"{_bytes_text(self.bytes_per_rank)} per rank (limits: {self.max_blocks} blocks, "
                f"{_bytes_text(self.max_bytes)} per rank)")


def rescaled(est: Estimate, n_blocks: int) -> Estimate:
    """The estimate for the block count the scene turned out to make (cuts and meshes are
    counted only once built): contacts and bytes scale with the blocks."""
    f = n_blocks / max(est.blocks, 1)
    return Estimate(n_blocks, math.ceil(est.contacts * f), est.bytes_per_rank * f,
                    est.max_blocks, est.max_bytes)


def estimate(scene, comm_size: int, memory: float | None = None, whole: bool = False
             ) -> tuple[Estimate, list[tuple[int, int]]]:
    """The scene's cost from its entries alone (nothing built); also (entry, blocks) per entry.
    ``memory``: the physical memory to plan for (default: this machine's); ``whole``: every
    rank builds every block's store (pdem.state.needs_whole_scene), else its share."""
    block_row = _row_bytes(BLOCK)
    # the declared rows (the contacts' ``held`` has columns only with solve.inactive)
    contact_row = _row_bytes(CONTACT) + SUBS_PER_CONTACT * _row_bytes(SUB) \
        - 8 * (HELD_WIDTH - held_width(scene.solve.inactive is not None))
    vert_row = np.dtype(VERT_ROW).itemsize
    per_entry = []
    n_total = 0
    # Set-up (pdem.state.ModelState.create): every rank keeps the per-block catalogue
    # (SCENE_BYTES_PER_BLOCK); it builds the shapes and store of its share of the gids (of
    # every block when ``whole``; cuts, joins and excavations work on the blocks spread over
    # the ranks, pdem.model.spread) and then holds its own blocks and ghosts
    # (pdem.parallel.migrate)
    built_bytes = 0.0  # a block's row, geometry and shape objects while it is built
    held_bytes = 0.0  # a block's row and geometry in a rank's store
    for i, b in enumerate(scene.blocks):
        n, v, f, e = shape_size(b)  # the shape kind's estimate (pdem.model.shapes)
        per_entry.append((i, n))
        n_total += n
        # vertices local + world, face normals/offsets/starts, edge directions (float64 and
        # int64 starts); face vertex lists (2E) and edges (2E) of vertex rows; plus the
        # block row
        geom = 8 * (6 * v + 6 * f + 3 * e + 4) + vert_row * (2 * e + 2 * e)
        built_bytes += float(n) * (geom + block_row + PY_BYTES_PER_BLOCK)
        held_bytes += float(n) * (geom + block_row)
    built_fraction = 1.0 if whole else 1.0 / max(comm_size, 1)
    static_bytes = SCENE_BYTES_PER_BLOCK * float(n_total) + built_fraction * built_bytes
    share = n_total / max(comm_size, 1)
    contacts = math.ceil(share * CONTACTS_PER_BLOCK / 2)
    avg_block = static_bytes / max(n_total, 1)
    avg_held = held_bytes / max(n_total, 1)
    # the rank's own store: its blocks, plus ghosts when there are other ranks
    local = 1.0 + (GHOST_FACTOR - 1.0 if comm_size > 1 else 0.0)
    per_rank = static_bytes + share * local * avg_held + contacts * contact_row
    lim = scene.limits
    memory = machine_memory() if memory is None else memory
    max_bytes = (MEMORY_FRACTION * memory / max(comm_size, 1)
                 if lim.max_memory_per_rank == "auto" else parse_bytes(lim.max_memory_per_rank))
    if lim.max_blocks == "auto":
        # the count whose estimate fits the memory limit (every rank holds the static model)
        per_block = avg_block + avg_held * local / max(comm_size, 1) \
            + CONTACTS_PER_BLOCK / 2 * contact_row / max(comm_size, 1)
        max_blocks = int(min(max_bytes / per_block, 2**62)) if math.isfinite(max_bytes) else 2**62
    else:
        max_blocks = int(lim.max_blocks)
    return Estimate(n_total, contacts, per_rank, max_blocks, max_bytes), per_entry


def _generator_text(b) -> str:
    if b.shape_kind == "array":
        c = b.array.count
        return f".array.count: {c[0]} x {c[1]} x {c[2]} = {math.prod(c):.4g} blocks"
    if b.shape_kind == "random":
        return f".random.count: {b.random.count:.4g} blocks"
    return ""


def preflight(scene, comm_size: int, memory: float | None = None, warn: bool = True,
              whole: bool = False) -> Estimate:
    """Refuse a scene too large for ``limits:`` before any block is made; log warnings for
    physical parameters outside their usual ranges (``warn``: on one rank only). Every rank
    must decide alike (or the others wait forever): give them the same ``memory``. ``whole``:
    every rank builds every block (see :func:`estimate`)."""
    est, per_entry = estimate(scene, comm_size, memory, whole)
    if est.blocks > est.max_blocks or est.bytes_per_rank > est.max_bytes:
        big = sorted(per_entry, key=lambda t: -t[1])[:3]
        where = "; ".join(f"blocks[{i}] ({scene.blocks[i].name!r}){_generator_text(scene.blocks[i])}"
                          for i, n in big if n > 1) or f"{len(scene.blocks)} entries"
        msgs = []
        explicit = scene.limits.max_blocks != "auto"
        # the memory message says more (the bytes and the blocks) unless max_blocks was given
        if est.blocks > est.max_blocks and (explicit or est.bytes_per_rank <= est.max_bytes):
            src = "auto: what fits in limits.max_memory_per_rank" if scene.limits.max_blocks \
                == "auto" else "limits.max_blocks"
            msgs.append(f"limits.max_blocks: the scene makes {est.blocks:.4g} blocks, more than "
                        f"the limit {est.max_blocks:.4g} ({src}); from {where}")
        else:
            src = (f"auto: {MEMORY_FRACTION:g} x this machine's memory / {comm_size} ranks"
                   if scene.limits.max_memory_per_rank == "auto" else "limits.max_memory_per_rank")
            msgs.append(f"limits.max_memory_per_rank: the scene needs ~{_bytes_text(est.bytes_per_rank)}"
                        f" per rank ({est.blocks:.4g} blocks, ~{est.contacts:.4g} contacts per rank), more "
                        f"than the limit {_bytes_text(est.max_bytes)} ({src}); from {where}")
        raise ConfigError(msgs)
    if warn:
        _warn_ranges(scene)
    return est


def _warn_ranges(scene) -> None:
    lo, hi = STIFFNESS_RANGE
    for name, j in scene.joints.items():
        for key in ("kn", "ks"):
            v = getattr(j, key)
            if not lo <= v <= hi:
                log.warning("joints.%s.%s = %.4g Pa/m is outside the usual range %.0e-%.0e Pa/m "
                            "(docs/limits.md)", name, key, v, lo, hi)
    lo, hi = DENSITY_RANGE
    for name, m in scene.materials.items():
        if not lo <= m.density <= hi:
            log.warning("materials.%s.density = %.4g kg/m3 is outside the usual range %g-%g kg/m3"
                        " (docs/limits.md)", name, m.density, lo, hi)
    g = math.hypot(*scene.gravity)
    if g > GRAVITY_MAX:
        log.warning("gravity: |g| = %.4g m/s2 is more than %g m/s2 (docs/limits.md)", g, GRAVITY_MAX)


def check_derived(scene, specs, rows, joints, group_names, dt: float, warn: bool = True,
                  ctol: float | None = None, comm=LOCAL) -> None:
    """Refuse what the built model makes impossible: no usable timestep, an end time that
    double precision cannot reach or a step count beyond ``limits.max_steps``, free blocks
    sinking into their support under gravity, and (given ``ctol``) blocks started so fast that
    they move more than ``MAX_STEP_MOTION`` x CTOL in one step.

    ``rows``: the blocks checked (their per-block fields and gids): every block, or this
    rank's build share with ``comm`` the ranks sharing the scene (collective: each rank checks
    its rows and every rank refuses the worst block of all, the same message)."""
    if not (math.isfinite(dt) and dt > 0.0):
        name = max(scene.joints, key=lambda j: max(scene.joints[j].kn, scene.joints[j].ks))
        j = scene.joints[name]
        raise ConfigError([
            f"solve.timestep: the timestep is {dt:.4g} s, not a usable step; the stiffest "
            f"joint (joints.{name}: kn={j.kn:.4g}, ks={j.ks:.4g} Pa/m) "
            f"overflows the stability estimate (usual range {STIFFNESS_RANGE[0]:.0e}-"
            f"{STIFFNESS_RANGE[1]:.0e} Pa/m)"])
    if scene.solve.time is not None:
        steps = scene.solve.time / dt
        if not steps <= MAX_TIME_STEPS:
            raise ConfigError([
                f"solve.time: {scene.solve.time:.4g} s at dt={dt:.4g} s is {steps:.4g} steps, "
                f"more than {MAX_TIME_STEPS:.4g} (beyond it t + dt == t in double precision)"])
        if warn and scene.solve.max_steps is not None and steps > scene.solve.max_steps:
            log.warning("solve.time: %.4g s at dt=%.4g s is %.4g steps; the run stops at "
                        "solve.max_steps=%d before reaching it", scene.solve.time, dt, steps,
                        scene.solve.max_steps)
    _check_step_count(scene, joints, dt)
    _refuse_worst(comm, _check_static_overlap(scene, specs, rows, joints, group_names))
    if ctol is not None:
        _refuse_worst(comm, _check_start_speeds(scene, specs, rows, dt, ctol))
        _refuse_worst(comm, _check_impact_overlap(scene, specs, rows, joints, group_names))


def _refuse_worst(comm, found: tuple[float, str] | None) -> None:
    """Refuse the worst of the ranks' findings (``(how bad, message)``, None: nothing wrong
    among its rows): the first of the worst in rank order, so the first in gid order (the
    build shares are contiguous gid ranges in rank order), as a check over every block
    would name it. Every rank raises the same error (no rank left waiting)."""
    bad = [f for f in allgather(comm, found) if f is not None]
    if bad:
        raise ConfigError([max(bad, key=lambda f: f[0])[1]])


def _check_step_count(scene, joints, dt: float) -> None:
    """The steps the run's end implies (``solve.time`` / dt, or ``solve.steps``; at most
    ``solve.max_steps``) against ``limits.max_steps``: a joint far stiffer than it needs to be
    (or a tiny block) makes dt so small that the requested model time would take days."""
    sv = scene.solve
    if sv.time is not None:
        steps, key, what = sv.time / dt, "solve.time", f"{sv.time:.4g} s at dt={dt:.4g} s is"
    elif sv.steps is not None:
        steps, key, what = float(sv.steps), "solve.steps", "asks for"
    else:
        return
    if sv.max_steps is not None:
        steps = min(steps, float(sv.max_steps))
    limit = scene.limits.max_steps
    if steps > limit:
        stiff = max(scene.joints, key=lambda j: max(scene.joints[j].kn, scene.joints[j].ks))
        j = scene.joints[stiff]
        raise ConfigError([
            f"{key}: {what} {steps:.4g} steps, more than limits.max_steps = {limit:.4g} "
            f"(dt={dt:.4g} s is set by the stiffest joint, joints.{stiff}: kn={j.kn:.4g}, "
            f"ks={j.ks:.4g} Pa/m, and the lightest block; docs/limits.md)"])


def _check_start_speeds(scene, specs, rows, dt: float, ctol: float):
    """A moving block's start speed (|v| + |w| r) times dt against MAX_STEP_MOTION x CTOL:
    the fastest of ``rows`` beyond it, as ``(speed, message)``, else None."""
    moving = np.nonzero(rows.fixed == 0)[0]
    if len(moving) == 0:
        return None
    speed = np.linalg.norm(rows.v[moving], axis=1) \
        + np.linalg.norm(rows.w[moving], axis=1) * rows.radius[moving]
    k = int(np.argmax(speed))
    step = float(speed[k]) * dt
    if not step > MAX_STEP_MOTION * ctol:
        return None
    b = int(rows.gid[moving[k]])
    dt_max = MAX_STEP_MOTION * ctol / float(speed[k])
    return float(speed[k]), (
        f"blocks[{specs[b].entry}].velocity: block {specs[b].name!r} starts at "
        f"{float(speed[k]):.4g} m/s and moves {step:.4g} m in one step (dt={dt:.4g} s), "
        f"more than {MAX_STEP_MOTION:g} x CTOL = {MAX_STEP_MOTION * ctol:.4g} m: it could "
        f"pass through a thin block before contact detection sees it; give "
        f"solve.timestep.dt <= {dt_max:.3g} s (or stiffer joints) (docs/limits.md)")


def _column(specs, name: str, gids: np.ndarray) -> np.ndarray:
    """A geometric scalar of blocks ``gids``: the SpecTable's column, or from each spec."""
    if hasattr(specs, name):
        return getattr(specs, name)[gids]
    return np.array([getattr(specs[b], name) for b in gids], float)


def _check_static_overlap(scene, specs, rows, joints, group_names):
    """m g / (kn A) of each free block resting on its largest face, with the softest joint its
    group can touch, against MAX_STATIC_OVERLAP of its size (cube root of the volume): the
    worst of ``rows`` beyond it, as ``(fraction, message)``, else None."""
    free = np.nonzero(rows.fixed == 0)[0]
    if len(free) == 0:
        return None
    load = np.linalg.norm(rows.mass[free, None] * np.array(scene.gravity, float)
                          + rows.applied_force[free], axis=1)
    if not load.any():
        return None
    # softest joint per group: any pair this group is part of (joint_table's rows by group)
    soft = _softest_kn_per_group(scene, joints, group_names)
    # per block, vectorised (a Python loop over the blocks was seconds for 1e5 of them)
    gids = rows.gid[free]
    area, size = _column(specs, "max_face", gids), _column(specs, "volume", gids) ** (1.0 / 3.0)
    kn_all = np.array([kn for kn, _ in soft], float)[rows.group[free]]
    overlap = load / (kn_all * area)
    frac = overlap / size
    n = int(np.argmax(np.where(np.isnan(frac), -np.inf, frac)))  # the first largest
    worst = float(frac[n]) if frac[n] > 0.0 else 0.0
    if not worst > MAX_STATIC_OVERLAP:
        return None
    worst_b = int(gids[n])
    f, kn, area, overlap, size = load[n], kn_all[n], area[n], overlap[n], size[n]
    jname = soft[int(rows.group[free[n]])][1]
    return worst, (
        f"{jname}.kn: {kn:.4g} Pa/m is too soft for block {specs[worst_b].name!r} "
        f"(blocks[{specs[worst_b].entry}]): its static overlap m g / (kn A) = {f:.4g} N / "
        f"({kn:.4g} Pa/m x {area:.4g} m2) = {overlap:.4g} m is {worst:.3g} of its size "
        f"{size:.4g} m, more than {MAX_STATIC_OVERLAP:g} (docs/limits.md)")


def _check_impact_overlap(scene, specs, rows, joints, group_names):
    """A block started at speed v stops against a fixed support after sinking
    v sqrt(m / (kn A)) into it (the spring takes its kinetic energy, A its largest face, kn the
    softest joint its group can touch): more than MAX_STATIC_OVERLAP of its size and the
    contact's common plane can end up beyond the block's middle, which pushes it through.
    The worst of ``rows`` beyond it, as ``(fraction, message)``, else None."""
    moving = np.nonzero((rows.fixed == 0) & (np.linalg.norm(rows.v, axis=1) > 0.0))[0]
    if len(moving) == 0:
        return None
    soft = _softest_kn_per_group(scene, joints, group_names)
    worst, vals = 0.0, None
    for r in moving:
        b = int(rows.gid[r])
        kn, jname = soft[int(rows.group[r])]
        area = specs[b].max_face
        speed = float(np.linalg.norm(rows.v[r]))
        depth = speed * math.sqrt(float(rows.mass[r]) / (kn * area))
        size = specs[b].volume ** (1.0 / 3.0)
        if depth / size > worst:
            worst, vals = depth / size, (b, kn, jname, area, speed, depth, size)
    if not worst > MAX_STATIC_OVERLAP:
        return None
    b, kn, jname, area, speed, depth, size = vals
    return worst, (
        f"{jname}.kn: {kn:.4g} Pa/m is too soft for block {specs[b].name!r} "
        f"(blocks[{specs[b].entry}]) started at {speed:.4g} m/s: an impact sinks it "
        f"v sqrt(m / (kn A)) = {depth:.4g} m into what it hits, {worst:.3g} of its size "
        f"{size:.4g} m, more than {MAX_STATIC_OVERLAP:g}: it could pass through "
        f"(docs/limits.md)")


def _softest_kn_per_group(scene, joints, group_names) -> list[tuple[float, str]]:
    names = list(scene.joints)
    out = []
    for g in group_names:
        cands = [jp.joint for jp in scene.joint_pairs if g in jp.groups]
        if "default" in scene.joints:
            cands.append("default")
        cands = cands or names
        best = min(cands, key=lambda j: scene.joints[j].kn)
        out.append((float(scene.joints[best].kn), f"joints.{best}"))
    return out
