"""Every ``auto`` value of a scene resolved once, from the scene and its built blocks.

The resolved numbers (CTOL, cell size, timestep, damping constant, ghost margin, rank grid,
...) are computed here and nowhere else, stored in every output and checkpoint, and read by
the stepper; a restart takes them from the checkpoint rather than re-deriving them.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass

import numpy as np

from ..dynamics.damping import DAMPING
from ..dynamics.kinematics import refresh_pose
from ..dynamics.timestep import auto_timestep, mass_scale_factors
from ..errors import UserError
from ..parallel.decomposition import choose_dims

# vertices within this fraction of CTOL of the common plane count as touching it
TOUCH_FRACTION = 0.5


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


def block_sizes(specs) -> np.ndarray:
    """Equivalent size (cube root of the volume) of every block, gid order."""
    return np.array([s.volume for s in specs]) ** (1.0 / 3.0)


def _estimated_stiffness(specs, joints) -> np.ndarray:
    """Per block, the stiffness of contacts on a third of its surface (top and bottom of a
    cube): the timestep must be stable before the first contact forms, and must not depend
    on which contacts a rank holds."""
    kmax = float(np.maximum(joints.kn, joints.ks).max())
    surf = np.array([s.face_areas.sum() for s in specs])
    # an absurd stiffness overflows to inf (dt = 0), refused by preflight.check_derived with
    # the joint named; numpy's warning would only add noise before that message
    with np.errstate(over="ignore"):
        return kmax * surf / 3.0


def _timestep(scene, glob, k) -> float:
    """The step (eq. 87 + rotational bound); with mass scaling, sets ``glob.mscale`` (eq. 89)."""
    ts = scene.solve.timestep
    if scene.solve.mass_scaling:
        # static solve: every block gets the critical step of the mean block (eq. 89)
        free = glob.fixed == 0
        dt = ts.dt or ts.frac * 2.0 * math.sqrt(
            float(np.mean(glob.mass[free])) / float(np.mean(k[free])))
        glob.mscale[:] = mass_scale_factors(glob.mass, k, dt, ts.frac, glob.inertia, glob.radius)
    elif ts.dt is not None:
        dt = ts.dt
    else:
        dt = auto_timestep(glob.mass, k, ts.frac, glob.inertia, glob.radius, glob.fixed,
                           glob.mscale)
    if not math.isfinite(dt):
        raise UserError("solve.timestep: no free block, cannot choose a timestep; give dt")
    return float(dt)


def _alpha(scene) -> float:
    d = scene.solve.damping
    if d.alpha is not None:
        return d.alpha
    default = DAMPING[d.mode].default_alpha
    if default is None:
        raise UserError(f"solve.damping.alpha: {d.mode} damping needs alpha (1/s)")
    return default


def resolve(scene, comm_size: int, specs, glob, joints) -> Resolved:
    """Resolve the scene's ``auto`` values for the built global store ``glob`` (whose world
    vertices, envelopes and, with mass scaling, ``mscale`` are set here)."""
    cs = scene.contact
    sizes = block_sizes(specs)
    ctol = 0.02 * sizes.min() if cs.ctol == "auto" else float(cs.ctol)
    glob.point_area[:] = cs.point_area * sizes**2
    refresh_pose(glob, 0.5 * ctol)
    lo, hi = glob.lo, glob.hi
    free = glob.fixed == 0
    ext = (hi - lo)[free] if free.any() else hi - lo
    cell_size = float(np.mean(ext.max(axis=1))) if cs.cell_size == "auto" else float(cs.cell_size)
    dt = _timestep(scene, glob, _estimated_stiffness(specs, joints))
    # Runaway threshold: no block can honestly move faster than its start speed plus a fall
    # across the whole model (or what gravity and applied loads add over time); ten times
    # that is a blow-up, typically a timestep too large for the stiffness.
    gravity = np.array(scene.gravity, float)
    acc = float(np.linalg.norm(gravity))
    if free.any():
        acc += float((np.linalg.norm(glob.applied_force[free], axis=1) / glob.mass[free]).max())
    size = float(np.linalg.norm(hi.max(0) - lo.min(0)))
    v0 = float((np.linalg.norm(glob.v, axis=1) + np.linalg.norm(glob.w, axis=1) * glob.radius)
               .max(initial=0.0))
    if free.any():
        ref = np.linalg.norm(glob.mass[free, None] * gravity + glob.applied_force[free], axis=1)
        ref_force = float(ref.mean()) or 1.0
    else:
        ref_force = 1.0
    par = scene.parallel
    dims = choose_dims(comm_size, hi.max(0) - lo.min(0), gravity) if par.dims == "auto" \
        else list(par.dims)
    return Resolved(
        ctol=float(ctol),
        cell_size=cell_size,
        overlap_tolerance=0.1 * ctol if cs.overlap_tolerance == "auto"
        else float(cs.overlap_tolerance),
        snap_tol=1e-9 * max(1.0, float(np.abs(glob.verts_world).max(initial=1.0))),
        refresh_tolerance=cs.refresh_tolerance * ctol,
        dt=dt,
        alpha=float(_alpha(scene)),
        margin=cell_size if par.margin == "auto" else float(par.margin),
        dims=tuple(int(d) for d in dims),
        domain_lo=tuple(float(v) for v in lo.min(0)),
        domain_hi=tuple(float(v) for v in hi.max(0)),
        ref_force=ref_force,
        speed_limit=10.0 * (v0 + math.sqrt(2.0 * acc * size)) + 1.0,
        speed_growth=2.0 * acc,
    )
