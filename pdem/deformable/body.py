"""``DeformableBody``: one block's zoning and state arrays, stepped without contacts.

Plain-Python orchestration over the kernels of :mod:`.zones`, :mod:`.nmd`, :mod:`.motion` and
:mod:`.constitutive`; the arrays are public so the later integration (contacts, MPI, output)
can read and write them directly.
"""

from __future__ import annotations

import math

import numpy as np

from .constitutive import material
from .mesh import TetMesh, tetrahedralise
from .motion import (
    GRID_DAMPING,
    N_GW,
    N_SC,
    SC_ACTIVE,
    SC_BETA,
    SC_DAMPING,
    SC_LOADED,
    SC_MODE,
    SC_NMD,
    SC_QUIET,
    critical_timestep,
    cycle,
    nodal_stiffness,
    scaled_masses,
    stability_alpha,
)
from .zones import gravity_forces, lumped_mass, surface_load, zone_geometry


class DeformableBody:
    """A deformable block: gridpoints (``nodes, vel, mass, fixed``), zones (``tets, grad, vol,
    stress, plastic``) and the material's kernel table.

    Parameters
    ----------
    mesh : TetMesh, or a ConvexPolyhedron zoned with ``size``.
    spec : scene material, e.g. ``{density: 2650, young: 40e9, poisson: 0.25}`` or with
        ``model: mohr_coulomb, cohesion, friction, tension, dilation``.
    gravity : (3,) acceleration.
    nmd : nodal mixed discretization (on by default, as in 3DEC).
    damping : damping coefficient alpha (0 for dynamics; 0.8 is pdem's static default).
    damping_mode : its form, a ``solve.damping.mode`` (pdem.deformable.motion's module doc;
        ``adaptive`` is viscous with the alpha given: its servo is the scene's).
    mass_scaling : static solution: inertial masses scaled so that ``dt = 1`` is stable
        (gravity keeps the true masses).
    """

    def __init__(self, mesh, spec: dict, size: float | None = None, gravity=(0.0, 0.0, 0.0),
                 nmd: bool = True, damping: float = 0.0, mass_scaling: bool = False,
                 damping_mode: str = "local"):
        if not isinstance(mesh, TetMesh):
            if size is None:
                raise ValueError("a polyhedron needs a zone size")
            mesh = tetrahedralise(mesh, size)
        self.mesh = mesh
        self.params, self.model = material(dict(spec))
        self.nodes = mesh.nodes.copy()
        self.nodes0 = mesh.nodes.copy()
        self.tets = mesh.tets
        n, m = len(self.nodes), len(self.tets)
        self.vel = np.zeros((n, 3))
        self.grad = np.empty((m, 4, 3))
        self.vol = np.empty(m)
        if zone_geometry(self.nodes, self.tets, self.grad, self.vol) <= 0.0:
            raise ValueError("mesh has a zone of non-positive volume")
        self.stress = np.zeros((m, 6))
        self.plastic = np.zeros(m, np.int32)
        self.gravity_mass = lumped_mass(n, self.tets, self.vol, self.params.density)
        self.gravity = np.asarray(gravity, float)
        self.fixed = np.zeros((n, 3), bool)
        self.fixed_vel = np.zeros((n, 3))
        # a prescribed velocity's history (pdem.deformable.conditions): its index, -1 none
        self.vhist = np.full((n, 3), -1, np.int32)
        self.applied = np.zeros((n, 3))
        # the scalars the grid steps with, in one row (pdem.deformable.motion.SC_*: in a
        # scene a view of the GridStore's rows, which its one kernel reads), by the
        # properties below
        self.scalars = np.zeros(N_SC)
        self.loaded = False  # applied holds a load (GridStore.step adds it)
        self.active = True  # stepped (False: its block was taken out of the model)
        self.nmd = bool(nmd)
        self.damping = float(damping)
        self.damping_mode = GRID_DAMPING[damping_mode][0]
        # every gridpoint's total force of the last step (combined damping's dF/dt): it
        # travels with the body and into checkpoints
        self.prev_force = np.zeros((n, 3))
        self.servo = np.zeros(2)  # the last step's damping power and sum |dEk/dt| (eq. 77)
        self.mass_scaling = bool(mass_scaling)
        self.unbalanced = np.zeros(1)  # the last step's largest unbalanced gridpoint force
        # the energy accumulators since the start (pdem.deformable.motion.GW_*): they travel
        # with the body between ranks and into checkpoints
        self.work = np.zeros(N_GW)
        self.update_mass()
        self.zone_stiffness = None  # of the built geometry (GridStore._zone_stiffness)
        self.time = 0.0

    @property
    def active(self) -> bool:
        return bool(self.scalars[SC_ACTIVE])

    @active.setter
    def active(self, on: bool) -> None:
        self.scalars[SC_ACTIVE] = bool(on)

    @property
    def loaded(self) -> bool:
        return bool(self.scalars[SC_LOADED])

    @loaded.setter
    def loaded(self, on: bool) -> None:
        self.scalars[SC_LOADED] = bool(on)

    @property
    def nmd(self) -> bool:
        return bool(self.scalars[SC_NMD])

    @nmd.setter
    def nmd(self, on: bool) -> None:
        self.scalars[SC_NMD] = bool(on)

    @property
    def damping_mode(self) -> int:
        return int(self.scalars[SC_MODE])

    @damping_mode.setter
    def damping_mode(self, mode: int) -> None:
        self.scalars[SC_MODE] = int(mode)

    @property
    def damping(self) -> float:
        return float(self.scalars[SC_DAMPING])

    @damping.setter
    def damping(self, alpha: float) -> None:
        self.scalars[SC_DAMPING] = float(alpha)

    @property
    def rayleigh_beta(self) -> float:
        """Rayleigh damping's stiffness-proportional constant (s; 0: none)."""
        return float(self.scalars[SC_BETA])

    @rayleigh_beta.setter
    def rayleigh_beta(self, beta: float) -> None:
        self.scalars[SC_BETA] = float(beta)

    @property
    def quieted(self) -> bool:
        """Some gridpoint has a quiet boundary's dashpots (GridStore.quiet)."""
        return bool(self.scalars[SC_QUIET])

    @quieted.setter
    def quieted(self, on: bool) -> None:
        self.scalars[SC_QUIET] = bool(on)

    # --- setup -----------------------------------------------------------------------------
    def stiffness(self) -> np.ndarray:
        return nodal_stiffness(self.tets, self.grad, self.vol, self.params.bulk,
                               self.params.shear, len(self.nodes))

    def update_mass(self) -> None:
        """Inertial masses: true lumped masses, or scaled for ``dt = 1`` (static mode)."""
        self.mass = (scaled_masses(self.stiffness(), alpha=self.stability_alpha())
                     if self.mass_scaling else self.gravity_mass)
        self.emass = self.mass  # the masses of the last grid step (GridStore.step)

    def timestep(self) -> float:
        """The zone term of eq. 88 for the current geometry and inertial masses."""
        if self.mass_scaling:
            return 1.0
        return critical_timestep(self.stiffness(), self.mass, self.stability_alpha(),
                                 self.rayleigh_beta)

    def stability_alpha(self) -> float:
        """The damping's factor on the critical step (pdem.deformable.motion.stability_alpha)."""
        return stability_alpha(self.damping_mode, self.damping)

    def fix(self, mask, dofs=(0, 1, 2), velocity: float = 0.0) -> None:
        """Prescribe ``velocity`` on the ``dofs`` of the gridpoints in ``mask``."""
        for i in dofs:
            self.fixed[mask, i] = True
            self.fixed_vel[mask, i] = velocity

    def traction(self, faces, t) -> np.ndarray:
        """Gridpoint forces of a uniform traction ``t (3,)`` on the block faces ``faces``."""
        sel = np.isin(self.mesh.surface_face, np.atleast_1d(faces))
        return surface_load(self.nodes, self.mesh.surface[sel], np.asarray(t, float))

    # --- stepping --------------------------------------------------------------------------
    def step(self, n_steps: int, dt: float | None = None) -> int:
        """Advance ``n_steps`` steps of ``dt`` (default: :meth:`timestep` at the start)."""
        dt = self.timestep() if dt is None else dt
        gforce = gravity_forces(self.gravity_mass, self.gravity)
        applied = self.applied + gforce
        done = cycle(n_steps, dt, self.nodes, self.vel, self.mass, applied, self.fixed,
                     self.fixed_vel, self.tets, self.grad, self.vol, self.stress, self.plastic,
                     self.model, self.nmd, self.damping_mode, self.damping, self.prev_force,
                     self.unbalanced, self.servo, gforce,
                     np.zeros_like(applied), self.applied, self.params.bulk, self.params.shear,
                     self.work)
        self.time += done * dt
        if done < n_steps:
            raise FloatingPointError(f"a zone inverted after {done} of {n_steps} steps")
        return done

    # --- measures --------------------------------------------------------------------------
    @property
    def displacement(self) -> np.ndarray:
        return self.nodes - self.nodes0

    def kinetic_energy(self) -> float:
        return float(0.5 * np.sum(self.mass[:, None] * self.vel ** 2))

    def kinetic_as_integrated(self) -> float:
        """Kinetic energy at the last half step with the inertial masses, prescribed degrees
        of freedom holding none (the energy budget's); correctly rounded, so the same bits
        on any rank."""
        e = np.where(self.fixed, 0.0, self.emass[:, None] * self.vel ** 2)
        return 0.5 * math.fsum(e.ravel().tolist())

    def strain_energy(self) -> float:
        """Elastic energy ``sum V (p^2 / 2K + s:s / 4G)`` of the zone stresses."""
        s = self.stress
        p = s[:, :3].mean(axis=1)
        dev = s[:, :3] - p[:, None]
        ss = np.sum(dev ** 2, axis=1) + 2.0 * np.sum(s[:, 3:] ** 2, axis=1)
        k, g = self.params.bulk, self.params.shear
        return float(np.sum(self.vol * (p ** 2 / (2.0 * k) + ss / (4.0 * g))))

    def max_speed(self) -> float:
        """Largest gridpoint velocity component: with mass scaling (dt = 1) the displacement per
        step, the convergence measure of static solves."""
        return float(np.abs(self.vel).max())
