"""Gridpoint motion: the explicit cycle of a deformable block and its critical timestep.

One step (the FLAC/3DEC sequence, reference eqs. 53-59 and 68-76):

1. gridpoint forces at t: applied + gravity (eq. 56) + zone stresses (eq. 55);
2. velocities at t + dt/2 by central differences (eq. 57) with the grid's damping (below), or
   the prescribed velocity on fixed degrees of freedom; positions to t + dt;
3. strain rates and spins (eq. 58) on the geometry at t + dt/2, NMD on strain (eqs. 68-71);
   the zone geometry at t + dt for the next forces;
4. stresses: Jaumann rotation by the spin, then the constitutive model (eq. 59 / plasticity),
   then NMD on the plastic volumetric stress correction (eqs. 73-76).

Damping (``solve.damping.mode``, as pdem's rigid modes, pdem.dynamics.damping), per
gridpoint component with ``F`` the total unbalanced force at t (before damping):

``LOCAL``     eqs. 78-79: ``F_d = alpha |F| sgn(v(t - dt/2))`` subtracted (``none``: alpha 0).
``COMBINED``  eq. 83 in the sign of (78): ``F_d = alpha |F| (sgn(v) - sgn(dF/dt)) / 2``,
              ``dF/dt`` from ``F - F_prev`` (the gridpoint's total force of the step before,
              kept in ``prev``, which travels with the grid and into checkpoints): no damping
              of a steady motion (``F`` constant or growing along ``v``), local damping's
              force on an oscillation.
``VISCOUS``   eq. 49: ``v+ = (D1 v- + F dt/m) D2``, ``D1 = 1 - alpha dt/2``,
              ``D2 = 1/(1 + alpha dt/2)``: the force ``alpha m v(t)`` with ``m`` the inertial
              mass, so that every gridpoint's velocity decays alike, ``exp(-alpha t)`` for a
              free block's rigid motion (with the true mass under mass scaling the lighter-
              scaled gridpoints would be damped less, and damping a rigid motion would strain
              the block); the rigid blocks' viscous mode uses the inertial mass too.
              ``adaptive``: this form with the servo's alpha (eq. 77), the rigid blocks' one.

Energy (the run's budget, pdem.plugins.energy): each step books on the grid's ``work``
(columns ``GW_*``) the work of the gridpoint forces over the step with the mean velocity
``(v(t - dt/2) + v(t + dt/2)) / 2`` of every free degree of freedom, which makes the kinetic
energy's change exact for the leap-frog (the rigid blocks' rule, pdem.dynamics.motion): of
gravity, of the applied loads (a block's or a stage's ``force``, boundary stresses), of the
contacts, what damping took out (its force, as applied, times the mean velocity: exact for
each mode), and the work done on the zones (minus the zone forces' work: the energy the
zones hold and dissipated, booked rather than taken from the stresses, whose quadratic form
is off by O(strain) at large strain). A prescribed degree of freedom
holds no kinetic energy: its motion does the work of the zone and contact forces on it
(``GW_BOUNDARY``, with the prescribed velocity). ``GW_PLASTIC``: the zones' plastic work
``V sigma_mean : (de - C^-1 dsigma)``, booked in the steps a zone's model yields.

Timestep (the zone term of eq. 88): eq. 84, ``dt_n = 2 min_i sqrt(m_i / k_i)``, with ``k_i``
the largest Gershgorin row sum of the assembled elastic zone stiffness at gridpoint ``i``
(sum over its zones and over the 3 x 4 columns of ``|K_e|``). Gershgorin bounds the largest
eigenvalue of ``M^-1 K``, so ``dt_n`` is a guaranteed-stable central-difference step for the
elastic grid (``omega_max dt <= 2``), yet usually within 1.2-1.6x of the true limit (the tests
measure it). Eq. 86's ``k_z = 8/3 (K + 4G/3) b_max^2 / h_min`` is an estimate of the same
quantity without that guarantee; :func:`nodal_stiffness_3dec` gives it for comparison.
"""

from __future__ import annotations

import numpy as np

from ..dynamics.damping import sign_of
from ..jit import inline_kernel, kernel
from .constitutive import SHEAR_NOW, SHEAR_PAST, TENSION_NOW, TENSION_PAST, update_stress
from .nmd import nmd_strain_in, nmd_stress_in
from .zones import (
    add_viscous_forces_in,
    add_zone_forces_in,
    rotate_stress_in,
    strain_rates_in,
    zone_geometry_in,
)

# columns of a grid's energy accumulators (DeformableBody.work), booked by :func:`cycle`
GW_GRAVITY = 0  # work of gravity
GW_APPLIED = 1  # work of applied loads (block and stage forces, boundary stresses)
GW_BOUNDARY = 2  # put in by prescribed gridpoint velocities
GW_DAMPING = 3  # dissipated by damping
GW_CONTACT = 4  # work of the contact forces (diagnostic: the joints book their side)
GW_ZONE = 5  # work done on the zones (held and dissipated in them)
GW_PLASTIC = 6  # of which dissipated by the zones' plastic flow
GW_QUIET = 7  # absorbed by quiet (viscous) boundaries
N_GW = 8

# columns of a grid's scalar row (DeformableBody.scalars; the store's rows, read by
# :func:`step_grids`): stepped (0: taken out of the model), a load in ``applied``, NMD, the
# damping form and its coefficient, Rayleigh damping's stiffness-proportional constant (s),
# whether some gridpoint has a quiet boundary's dashpots
SC_ACTIVE = 0
SC_LOADED = 1
SC_NMD = 2
SC_MODE = 3
SC_DAMPING = 4
SC_BETA = 5
SC_QUIET = 6
N_SC = 7

# gridpoint damping forms (:func:`cycle`'s ``mode``; module doc)
LOCAL = 0
COMBINED = 1
VISCOUS = 2
# solve.damping.mode -> (form, whether alpha is kept: none is the local form with alpha 0)
GRID_DAMPING = {"none": (LOCAL, False), "local": (LOCAL, True), "combined": (COMBINED, True),
                "viscous": (VISCOUS, True), "adaptive": (VISCOUS, True),
                "rayleigh": (VISCOUS, True)}


def stability_alpha(mode: int, alpha: float) -> float:
    """The alpha of the ``(1 + alpha)`` stiffness factor of :func:`critical_timestep` for a
    damping form: local and combined damping may add ``alpha |F|`` to the force (combined's
    force is local's or less); viscous damping (eq. 49, centred in time) leaves the
    central-difference limit ``omega dt <= 2`` as it is for any alpha >= 0 (the roots of
    ``(1 + c) z^2 - (2 - w^2 dt^2) z + 1 - c``, ``c = alpha dt / 2``, stay in the unit circle
    exactly while ``w dt <= 2``)."""
    return 0.0 if mode == VISCOUS else alpha


@kernel
def nodal_stiffness(tets, grad, vol, bulk, shear, n_nodes):
    """Gershgorin stiffness ``k_i`` of every gridpoint (see module doc)."""
    lam = bulk - 2.0 * shear / 3.0
    rows = np.zeros((n_nodes, 3))
    for z in range(tets.shape[0]):
        v = vol[z]
        for a in range(4):
            ga = grad[z, a]
            for b in range(4):
                gb = grad[z, b]
                dot = ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2]
                for i in range(3):
                    acc = 0.0
                    for j in range(3):
                        kij = lam * ga[i] * gb[j] + shear * ga[j] * gb[i]
                        if i == j:
                            kij += shear * dot
                        acc += abs(kij)
                    rows[tets[z, a], i] += v * acc
    out = np.empty(n_nodes)
    for n in range(n_nodes):
        out[n] = max(rows[n, 0], rows[n, 1], rows[n, 2])
    return out


_FACES = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))


@kernel
def nodal_stiffness_3dec(nodes, tets, vol, bulk, shear):
    """Eq. 86 summed over the zones of each gridpoint (eq. 85 without joints)."""
    out = np.zeros(nodes.shape[0])
    m = bulk + 4.0 * shear / 3.0
    for z in range(tets.shape[0]):
        b2 = 0.0
        for a in range(4):
            for b in range(a + 1, 4):
                d = nodes[tets[z, a]] - nodes[tets[z, b]]
                b2 = max(b2, d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        h_min = np.inf
        for f in range(4):  # height over each face = 3 V / area
            p, q, r = tets[z, _FACES[f][0]], tets[z, _FACES[f][1]], tets[z, _FACES[f][2]]
            u = nodes[q] - nodes[p]
            w = nodes[r] - nodes[p]
            cx = u[1] * w[2] - u[2] * w[1]
            cy = u[2] * w[0] - u[0] * w[2]
            cz = u[0] * w[1] - u[1] * w[0]
            area = 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)
            h_min = min(h_min, 3.0 * vol[z] / area)
        kz = 8.0 / 3.0 * m * b2 / h_min
        for a in range(4):
            out[tets[z, a]] += kz
    return out


def critical_timestep(stiffness: np.ndarray, mass: np.ndarray, alpha: float = 0.0,
                      beta: float = 0.0) -> float:
    """Eq. 84: ``2 min sqrt(m_i / k_i)``, reduced by ``sqrt(1 + alpha)`` under local damping
    (and combined; ``alpha``: :func:`stability_alpha`), and for Rayleigh damping's
    stiffness-proportional constant ``beta`` (s) by ``sqrt(1 + xi^2) - xi``, ``xi = beta
    omega_max / 2`` the damping fraction it gives the highest frequency (the central-difference
    limit with a viscous stiffness term, Belytschko's ``omega dt <= 2 (sqrt(1 + xi^2) - xi)``).

    Local damping subtracts ``alpha |F| sgn(v)``: when the force opposes the velocity (every
    half cycle of an oscillation) it *adds* ``alpha |F|`` to it, so the effective stiffness is
    up to ``(1 + alpha) k``; without this factor a damped grid at the undamped limit diverges
    (found: alpha = 0.8 with mass scaling at 0.9 of the undamped limit blew up in 30 steps).
    """
    dt0 = float(2.0 * np.sqrt(np.min(mass / ((1.0 + alpha) * stiffness))))
    return rayleigh_limit(dt0, beta)


def rayleigh_limit(dt0: float, beta: float) -> float:
    """The stable step of a grid whose undamped limit is ``dt0`` under Rayleigh damping's
    stiffness term ``beta`` (:func:`critical_timestep`; ``omega_max = 2 / dt0``)."""
    if beta <= 0.0 or not np.isfinite(dt0):
        return dt0
    xi = beta / dt0
    return float(dt0 * (np.sqrt(1.0 + xi * xi) - xi))


def undamped_limit(dt: float, beta: float) -> float:
    """The undamped limit ``dt0`` whose :func:`rayleigh_limit` is ``dt``:
    ``sqrt(dt^2 + 2 dt beta)`` (mass scaling for a step under Rayleigh damping)."""
    if beta <= 0.0:
        return dt
    return float(np.sqrt(dt * dt + 2.0 * dt * beta))


def scaled_masses(stiffness: np.ndarray, dt: float = 1.0, frac: float = 0.9,
                  alpha: float = 0.0, beta: float = 0.0) -> np.ndarray:
    """Inertial masses making ``dt`` a ``frac`` of the critical step (with local damping
    ``alpha``, Rayleigh damping's ``beta``) at every gridpoint: 3DEC's density scaling for
    static solutions (gravity keeps the true masses)."""
    return (1.0 + alpha) * stiffness * (undamped_limit(dt / frac, beta) / 2.0) ** 2


@kernel
def cycle(n_steps, dt, nodes, vel, mass, applied, fixed, fixed_vel, tets, grad, vol, stress,
          plastic, model, nmd, mode, alpha, prev, unbalanced, servo, gforce, contact, load, bulk,
          shear, work):
    """Advance ``n_steps`` steps in place (see module doc); return the steps done.
    ``unbalanced (1,)``: set to the largest unbalanced gridpoint force (the norm over its
    free degrees of freedom, before damping) of the last step, for ``solve.ratio``.

    ``mass (n,)`` inertial gridpoint masses; ``applied (n, 3)`` applied + gravity forces;
    ``fixed (n, 3) bool`` prescribed-velocity degrees of freedom with ``fixed_vel (n, 3)``;
    ``plastic (m,) int32`` state bits; ``model`` a constitutive table; ``nmd`` bool;
    ``mode`` the damping form (LOCAL, COMBINED, VISCOUS) and ``alpha`` its coefficient (LOCAL
    with 0: undamped); ``prev (n, 3)`` every gridpoint's total force of the last step, read by
    COMBINED and rewritten every step whatever the form (a stage may change it);
    ``servo (2,)``: set to the last step's damping power and sum over the gridpoints of
    ``|dEk/dt|`` (inertial masses), the adaptive servo's sums (eq. 77). Stops early
    (returning fewer steps) if a zone inverts.

    Energy (module doc): ``applied`` is the sum of ``gforce`` (gravity), ``contact`` and
    ``load`` (each (n, 3); ``load`` may have no rows: no load), which are read only to book
    their work; ``bulk``, ``shear`` the elastic moduli of the plastic work; ``work (N_GW,)``
    accumulates.
    """
    n_nodes = nodes.shape[0]
    n_zones = tets.shape[0]
    force = np.empty((n_nodes, 3))
    mid = np.empty((n_nodes, 3))
    rate = np.empty((n_zones, 6))
    spin = np.empty((n_zones, 3))
    sigma_p = np.zeros(n_zones)
    no_quiet = np.zeros((0, 6))
    # the grid's rows as :func:`advance` takes them (row 0 of step_grids' flat ones), copied
    # back after the steps
    servo_rows = np.empty((1, 2))
    work_rows = np.empty((1, N_GW))
    for k in range(2):
        servo_rows[0, k] = servo[k]
    for k in range(N_GW):
        work_rows[0, k] = work[k]
    where = (0, 0, n_nodes, 0, n_zones, load.shape[0] > 0)
    done = n_steps
    for step in range(n_steps):
        if not advance(dt, where, nodes, vel, mass, applied, fixed, fixed_vel, tets, grad, vol,
                       stress, plastic, model, nmd, (mode, alpha, 0.0, False), prev, unbalanced,
                       servo_rows, gforce, contact, load, (bulk, shear), work_rows, no_quiet,
                       (force, mid, rate, spin, sigma_p)):
            done = step
            break
    for k in range(2):
        servo[k] = servo_rows[0, k]
    for k in range(N_GW):
        work[k] = work_rows[0, k]
    return done


@inline_kernel
def advance(dt, where, nodes, vel, mass, applied, fixed, fixed_vel, tets, grad, vol, stress,
            plastic, model, nmd, damp, prev, unbalanced, servo, gforce, contact, load, moduli,
            work, quiet, scratch):
    """One step of one grid of :func:`cycle` or :func:`step_grids` on the flat arrays of
    :func:`step_grids` (a single grid's are those of one grid), without slicing them:
    ``where = (d, a, e, za, ze, loaded)``: the grid's row ``d`` of ``unbalanced (k,)``,
    ``servo (k, 2)``, ``work (k, N_GW)``, its gridpoints ``a <= n < e`` (its ``tets`` number
    them from ``a``), its zones ``za <= z < ze``, and whether ``load`` has its rows (else it
    is not read). ``moduli``: its ``(bulk, shear)``; ``damp = (mode, alpha, beta, quieted)``:
    the damping form and coefficient, Rayleigh damping's stiffness-proportional constant
    (0: none) and whether some gridpoint has dashpots (``quiet (n, 6)``: each gridpoint's
    symmetric dashpot matrix ``C``, xx yy zz xy yz zx, N s/m; read only then). Scratch
    ``(force, mid, rate, spin, sigma_p)``: ``(n, 3)`` twice, ``(m, 6)``, ``(m, 3)``, ``(m,)``
    (fewer than 31 arguments, or Python 3.11 passes them as ``*args``, which numba cannot
    inline). False if a zone inverted.

    Rayleigh's stiffness term adds the viscous stresses ``beta D : eps_dot`` of the velocities
    at ``t - dt/2`` to the zones' forces (:func:`~pdem.deformable.zones.add_viscous_forces_in`;
    not kept in the stresses) and books their work as damping. A gridpoint with dashpots
    moves by the centred balance ``m (v+ - v-) / dt = F - C (v+ + v-) / 2`` (with the
    damping form's), solved for ``v+`` in its free components (a prescribed component keeps
    its velocity): stable for any dashpot, and what ``C`` absorbs, ``C vb . vb dt`` at the
    mean velocity ``vb``, is the kinetic energy's loss to the step's round-off
    (``GW_QUIET``).

    Inlined into :func:`cycle` and :func:`step_grids`: the same arithmetic, so the same
    bits, on either path. Its loops index with unsigned integers (pdem.deformable.zones:
    numba would wrap a signed index that may be negative around at every access)."""
    d, a, e, za, ze, loaded = where
    bulk, shear = moduli
    mode, alpha, beta, quieted = damp
    force, mid, rate, spin, sigma_p = scratch
    d1 = 1.0 - 0.5 * alpha * dt  # eq. 49's factors (VISCOUS)
    d2 = 1.0 / (1.0 + 0.5 * alpha * dt)
    h = 0.5 * alpha * dt if mode == VISCOUS else 0.0
    # (unsigned indices: a signed one is wrapped around at every access, pdem.deformable.zones)
    for n in range(np.uint64(a), np.uint64(e)):
        for i in range(3):
            force[n, i] = applied[n, i]
    add_zone_forces_in(tets, grad, vol, stress, force, za, ze, a)
    viscous = beta > 0.0
    if viscous:  # Rayleigh's stiffness term, in ``mid`` (read below before it is rewritten)
        for n in range(np.uint64(a), np.uint64(e)):
            for i in range(3):
                mid[n, i] = 0.0
        add_viscous_forces_in(vel, tets, grad, vol, beta, bulk - 2.0 * shear / 3.0, shear, mid,
                              za, ze, a)
    # per gridpoint: velocity at t - dt/2 and t + dt/2, force after the damping form's
    # (rows 0-2), and a dashpot gridpoint's system (rows 3-5: matrix; 6: right-hand side)
    tmp = np.empty((7, 3))
    big = 0.0
    wg = wa = wb = wd = wc = wz = wq = 0.0
    dek = 0.0
    for n in range(np.uint64(a), np.uint64(e)):
        c = dt / mass[n]
        f2 = 0.0
        e2 = 0.0
        for i in range(3):
            fv = mid[n, i] if viscous else 0.0
            ft = force[n, i] + fv if viscous else force[n, i]
            dfdt = ft - prev[n, i]
            prev[n, i] = ft
            v = vel[n, i]
            tmp[0, i] = v
            if fixed[n, i]:
                tmp[1, i] = fixed_vel[n, i]
                continue
            f = ft
            f2 += f * f
            if mode == VISCOUS:
                v1 = (d1 * v + f * c) * d2
            else:
                if mode == COMBINED:  # (sgn(v) - sgn(dF/dt)) / 2
                    sg = 0.5 * (sign_of(v) - sign_of(dfdt))
                    f -= alpha * abs(f) * sg
                elif v > 0.0:
                    f -= alpha * abs(f)
                elif v < 0.0:
                    f += alpha * abs(f)
                v1 = v + f * c
            tmp[1, i] = v1
            tmp[2, i] = f
        dash = quieted and quiet[n, 0] + quiet[n, 1] + quiet[n, 2] > 0.0
        if dash:
            _dashpot_velocity(quiet, n, mass[n] / dt, h, fixed, fixed_vel, tmp)
        for i in range(3):
            fv = mid[n, i] if viscous else 0.0
            fz = force[n, i] - applied[n, i]  # the zone forces' part (elastic)
            if fixed[n, i]:
                vp = tmp[1, i]
                vel[n, i] = vp
                # the prescribed motion strains the zones and the joints: it puts in the
                # work of their forces on the gridpoint (their reactions), and of the
                # viscous stresses, which dissipate it
                wz -= fz * vp
                wb -= (fz + contact[n, i] + fv) * vp
                wd -= fv * vp
                continue
            v = tmp[0, i]
            v1 = tmp[1, i]
            vb = 0.5 * (v + v1)
            if mode == VISCOUS:
                fd = alpha * mass[n] * vb  # eq. 49 solved for its force
            else:
                fd = (force[n, i] + fv if viscous else force[n, i]) - tmp[2, i]
            if viscous:
                fd -= fv
            if dash:
                wq += _dashpot_force(quiet, n, i, tmp) * vb
            vel[n, i] = v1
            e2 += v1 * v1 - v * v
            wg += gforce[n, i] * vb
            if loaded:
                wa += load[n, i] * vb
            wc += contact[n, i] * vb
            wz -= fz * vb
            wd += fd * vb
        big = max(big, f2)
        dek += abs(0.5 * mass[n] * e2)
        for i in range(3):
            mid[n, i] = nodes[n, i] + 0.5 * vel[n, i] * dt
            nodes[n, i] += vel[n, i] * dt
    unbalanced[d] = np.sqrt(big)
    work[d, GW_GRAVITY] += wg * dt
    work[d, GW_APPLIED] += wa * dt
    work[d, GW_BOUNDARY] += wb * dt
    work[d, GW_DAMPING] += wd * dt
    servo[d, 0] = wd
    servo[d, 1] = dek / dt
    work[d, GW_CONTACT] += wc * dt
    work[d, GW_ZONE] += wz * dt
    if quieted:
        work[d, GW_QUIET] += wq * dt
    # strain rates on the mid-step geometry: for a rigid rotation over the step the
    # velocity gradient is then exactly skew (a Cayley transform), so it strains nothing
    if zone_geometry_in(mid, tets, grad, vol, za, ze, a) <= 0.0:
        return False
    strain_rates_in(vel, tets, grad, rate, spin, za, ze, a)
    if nmd:  # (scratch: ``mid``, read above)
        nmd_strain_in(tets, vol, rate, mid, za, ze, a, e)
    if zone_geometry_in(nodes, tets, grad, vol, za, ze, a) <= 0.0:  # forces at t + dt
        return False
    rotate_stress_in(stress, spin, dt, za, ze)
    wp = 0.0
    for z in range(np.uint64(za), np.uint64(ze)):
        de = (rate[z, 0] * dt, rate[z, 1] * dt, rate[z, 2] * dt, rate[z, 3] * dt,
              rate[z, 4] * dt, rate[z, 5] * dt)
        s0 = (stress[z, 0], stress[z, 1], stress[z, 2], stress[z, 3], stress[z, 4],
              stress[z, 5])
        bits, sigma_p[z] = update_stress(model, stress[z], de)
        if bits & (SHEAR_NOW | TENSION_NOW):
            wp += vol[z] * plastic_increment(s0, stress[z], de, bulk, shear)
        past = plastic[z] & (SHEAR_PAST | TENSION_PAST)
        if plastic[z] & SHEAR_NOW:
            past |= SHEAR_PAST
        if plastic[z] & TENSION_NOW:
            past |= TENSION_PAST
        plastic[z] = past | bits
    work[d, GW_PLASTIC] += wp
    if nmd:  # (scratch: ``mid``, read above)
        nmd_stress_in(tets, vol, sigma_p, stress, mid, za, ze, a, e)
    return True


@inline_kernel
def _quiet_entry(quiet, n, i, j):
    """``C_ij`` of gridpoint ``n``'s dashpot matrix (``quiet`` rows: xx yy zz xy yz zx)."""
    if i == j:
        return quiet[n, i]
    k = i + j  # (0, 1): xy, (1, 2): yz, (0, 2): zx
    if k == 1:
        return quiet[n, 3]
    if k == 3:
        return quiet[n, 4]
    return quiet[n, 5]


@inline_kernel
def _dashpot_force(quiet, n, i, tmp):
    """Component ``i`` of the dashpots' force ``C vb`` at the step's mean velocity (``tmp``
    rows 0 and 1: the velocities at t - dt/2 and t + dt/2, :func:`advance`)."""
    out = 0.0
    for j in range(3):
        out += _quiet_entry(quiet, n, i, j) * 0.5 * (tmp[0, j] + tmp[1, j])
    return out


@inline_kernel
def _dashpot_velocity(quiet, n, mdt, h, fixed, fixed_vel, tmp):
    """The velocity at t + dt/2 (into ``tmp`` row 1) of gridpoint ``n`` with dashpots
    (:func:`advance`): ``(mdt (1 + h) I + C / 2) v+ = mdt (1 - h) v- - C v- / 2 + f`` on its
    free components (``mdt = m / dt``; ``h``: half the viscous form's ``alpha dt``, else 0;
    ``v-`` in row 0, ``f`` the force after the damping form's in row 2), ``v+`` the
    prescribed velocity on the others; by Cramer's rule (the matrix is diagonally dominant)."""
    for i in range(3):
        if fixed[n, i]:
            for j in range(3):
                tmp[3 + i, j] = 1.0 if i == j else 0.0
            tmp[6, i] = fixed_vel[n, i]
            continue
        r = mdt * (1.0 - h) * tmp[0, i] + tmp[2, i]
        for j in range(3):
            cij = 0.5 * _quiet_entry(quiet, n, i, j)
            tmp[3 + i, j] = cij + mdt * (1.0 + h) if i == j else cij
            r -= cij * tmp[0, j]
        tmp[6, i] = r
    a00, a01, a02 = tmp[3, 0], tmp[3, 1], tmp[3, 2]
    a10, a11, a12 = tmp[4, 0], tmp[4, 1], tmp[4, 2]
    a20, a21, a22 = tmp[5, 0], tmp[5, 1], tmp[5, 2]
    b0, b1, b2 = tmp[6, 0], tmp[6, 1], tmp[6, 2]
    c00 = a11 * a22 - a12 * a21
    c01 = a12 * a20 - a10 * a22
    c02 = a10 * a21 - a11 * a20
    det = a00 * c00 + a01 * c01 + a02 * c02
    tmp[1, 0] = (b0 * c00 + a01 * (a12 * b2 - b1 * a22) + a02 * (b1 * a21 - a11 * b2)) / det
    tmp[1, 1] = (a00 * (b1 * a22 - a12 * b2) + b0 * c01 + a02 * (a10 * b2 - b1 * a20)) / det
    tmp[1, 2] = (a00 * (a11 * b2 - b1 * a21) + a01 * (b1 * a20 - a10 * b2) + b0 * c02) / det


@kernel
def step_grids(d0, d1, model, dt, q, g, adaptive, alpha, bloaded, node_start, zone_start,
               scalars, moduli, work, servo, unbalanced, nodes, vel, contact, kc, gmass, mass,
               emass, zstiff, applied, fixed, fixed_vel, prev, bload, quiet, tets, grad, vol,
               stress, plastic, ap, gf, load, force, mid, rate, spin, sigma_p):
    """One step of the grids ``d0 <= d < d1`` of a :class:`~pdem.deformable.store.GridStore`
    (all of the constitutive table ``model``), each as :func:`cycle`'s step on its ranges of
    the flat arrays (CSR by ``node_start``, ``zone_start``; ``tets`` hold each grid's own
    gridpoint numbers, offset by its ``node_start``; no array is sliced), in order; a grid
    whose row of ``scalars`` (``SC_*``) says inactive is skipped. Per grid, before its step:
    with ``adaptive`` its damping becomes ``alpha``; its inertial masses ``emass`` are
    ``mass`` raised where the contact stiffness ``kc`` with the zones' ``zstiff`` needs it
    (``q = (dt / (2 GRID_FRAC))^2``: the store's ``inertial_masses``); its applied forces
    ``contact + m_g g (+ applied) (+ bload)`` and loads ``(bload) (+ applied)`` into the
    scratch ``ap``, ``load`` (gravity's ``gf``), each sum in the order the per-grid numpy
    made it. ``moduli (k, 2)``: bulk and shear moduli; ``work``, ``servo``, ``unbalanced``:
    the grids' rows; ``quiet (n, 6)``: the gridpoints' dashpots (:func:`advance`; read in the
    grids whose ``SC_QUIET`` is set). Under Rayleigh damping (``SC_BETA``) the masses are
    raised for the step its stiffness term allows (:func:`undamped_limit`). Returns the
    first grid that folded (-1: none; the grids after it are not stepped) and the largest
    unbalanced gridpoint force of the grids stepped."""
    big = 0.0
    for d in range(d0, d1):
        if scalars[d, SC_ACTIVE] == 0.0:  # taken out of the model
            continue
        if adaptive:
            scalars[d, SC_DAMPING] = alpha
        mode = int(scalars[d, SC_MODE])
        damping = scalars[d, SC_DAMPING]
        sa = 0.0 if mode == VISCOUS else damping  # stability_alpha
        beta = scalars[d, SC_BETA]
        qd = q
        if beta > 0.0:  # undamped_limit's square over 4, of dt / GRID_FRAC = 2 sqrt(q)
            r = 2.0 * np.sqrt(q)
            qd = 0.25 * (r * r + 2.0 * r * beta)
        loaded = scalars[d, SC_LOADED] != 0.0
        a, e = node_start[d], node_start[d + 1]
        za, ze = zone_start[d], zone_start[d + 1]
        for n in range(np.uint64(a), np.uint64(e)):  # (unsigned: advance)
            need = (1.0 + sa) * (zstiff[n] + kc[n]) * qd
            emass[n] = need if need > mass[n] else mass[n]
            for i in range(3):
                gi = gmass[n] * g[i]
                gf[n, i] = gi
                f = contact[n, i] + gi
                if loaded:
                    f += applied[n, i]
                if bloaded:
                    f += bload[n, i]
                    load[n, i] = bload[n, i] + applied[n, i] if loaded else bload[n, i]
                elif loaded:
                    load[n, i] = applied[n, i]
                ap[n, i] = f
        nmd = scalars[d, SC_NMD] != 0.0
        if not advance(dt, (d, a, e, za, ze, loaded or bloaded), nodes, vel, emass, ap, fixed,
                       fixed_vel, tets, grad, vol, stress, plastic, model, nmd,
                       (mode, damping, beta, scalars[d, SC_QUIET] != 0.0), prev, unbalanced,
                       servo, gf, contact, load, (moduli[d, 0], moduli[d, 1]), work, quiet,
                       (force, mid, rate, spin, sigma_p)):
            return d, big
        if unbalanced[d] > big:
            big = unbalanced[d]
    return -1, big


@kernel
def servo_total(servo, scalars, n):
    """The sum over the first ``n`` grids that step (``scalars``' SC_ACTIVE) of their rows of
    ``servo`` (the adaptive servo's sums, :func:`cycle`), in row order."""
    out = np.zeros(2)
    for d in range(n):
        if scalars[d, SC_ACTIVE] != 0.0:
            out[0] += servo[d, 0]
            out[1] += servo[d, 1]
    return out


@inline_kernel
def plastic_increment(s0, s1, de, bulk, shear):
    """Plastic work per volume of a zone's stress update from ``s0`` to ``s1`` under the
    strain increment ``de`` (tensor shear components): the mean stress times the strain less
    its elastic part, ``(s0 + s1)/2 : (de - C^-1 (s1 - s0))``."""
    dp = (s1[0] - s0[0] + s1[1] - s0[1] + s1[2] - s0[2]) / 3.0
    out = 0.0
    for k in range(6):
        ds = s1[k] - s0[k]
        if k < 3:
            el = (ds - dp) / (2.0 * shear) + dp / (3.0 * bulk)
            out += 0.5 * (s0[k] + s1[k]) * (de[k] - el)
        else:
            out += (s0[k] + s1[k]) * (de[k] - ds / (2.0 * shear))
    return out
