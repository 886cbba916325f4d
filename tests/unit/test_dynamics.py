"""pdem.dynamics: rotation helpers, central-difference motion, damping, timestep, energy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdem.dynamics import motion as M
from pdem.dynamics.damping import DAMPING
from pdem.dynamics.energy import angular_momentum, kinetic_energy, linear_momentum
from pdem.dynamics.rotation import (
    quat_conj,
    quat_from_rotvec,
    quat_mul,
    quat_normalize,
    quat_to_matrix,
    quat_to_rotvec,
    rotate,
    rotate_inv,
)
from pdem.dynamics.timestep import (
    auto_timestep,
    block_stiffness,
    mass_scale_factors,
)

RNG = np.random.default_rng(12345)


def rodrigues(theta):
    a = np.linalg.norm(theta)
    if a == 0.0:
        return np.eye(3)
    k = theta / a
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * kx + (1 - math.cos(a)) * kx @ kx


class Blocks:
    """Minimal per-block state for driving ``integrate``."""

    def __init__(self, n, mass=1.0, inertia=(1.0, 1.0, 1.0)):
        self.n = n
        self.x = np.zeros((n, 3))
        self.q = np.zeros((n, 4))
        self.q[:, 0] = 1.0
        self.v = np.zeros((n, 3))
        self.w = np.zeros((n, 3))
        self.L = np.zeros((n, 3))
        self.mass = np.full(n, float(mass))
        self.inertia = np.tile(np.asarray(inertia, dtype=float), (n, 1))
        self.fixed = np.zeros(n, np.uint8)
        self.vfix = np.zeros(n, np.uint8)
        self.force = np.zeros((n, 3))
        self.applied = np.zeros((n, 3))
        self.work = np.zeros((n, 8))
        self.moment = np.zeros((n, 3))
        self.mscale = np.ones(n)
        self.prev_force = np.zeros((n, 3))
        self.prev_moment = np.zeros((n, 3))
        self.dx = np.zeros((n, 3))
        self.dtheta = np.zeros((n, 3))
        self.stats = M.new_stats()
        self.gravity = np.zeros(3)
        self.scalar = False

    def set_omega(self, w):
        self.w[:] = w
        M.momentum_from_omega(self.q, self.w, self.inertia, self.mscale, self.scalar, self.L)

    def record(self):
        return M.Motion(self.x, self.q, self.v, self.w, self.L, self.mass, self.inertia,
                        self.fixed, self.vfix, self.force, self.applied, self.moment,
                        self.mscale, self.prev_force, self.prev_moment, self.dx, self.dtheta,
                        self.work, np.zeros((len(self.x), 3)), np.zeros((len(self.x), 3)))

    def stagger(self, dt):
        M.stagger_start(self.record(), self.gravity, dt, self.scalar)

    def step(self, dt, mode="none", alpha=0.0):
        M.integrate(self.record(), self.gravity, dt, DAMPING[mode].kernel_args(alpha),
                    self.scalar, self.stats)

    def energy(self):
        et, er = kinetic_energy(
            self.mass, self.inertia, self.q, self.v, self.L, self.mscale, self.scalar
        )
        return et + er


# --------------------------------------------------------------------------- quaternions


def test_rotvec_quat_matrix_matches_rodrigues():
    vecs = [RNG.normal(size=3) * s for s in (1e-12, 1e-7, 1e-4, 9.9e-4, 1e-3, 0.3, 2.0, 3.1)]
    vecs.append(np.array([math.pi, 0.0, 0.0]))
    vecs.append(np.zeros(3))
    for th in vecs:
        q = quat_from_rotvec(th)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-15
        r = quat_to_matrix(q)
        np.testing.assert_allclose(r, rodrigues(th), rtol=0, atol=2e-15)
        p = RNG.normal(size=3)
        np.testing.assert_allclose(rotate(q, p), r @ p, rtol=0, atol=1e-14)
        np.testing.assert_allclose(rotate_inv(q, p), r.T @ p, rtol=0, atol=1e-14)
        if np.linalg.norm(th) < math.pi:
            np.testing.assert_allclose(quat_to_rotvec(q), th, rtol=1e-14, atol=1e-28)
    # the small-angle branch is continuous with the trig branch at the switch
    for a in (1e-3 * (1 - 1e-12), 1e-3 * (1 + 1e-12)):
        q = quat_from_rotvec(np.array([a, 0.0, 0.0]))
        assert abs(q[0] - math.cos(a / 2)) < 1e-17 and abs(q[1] - math.sin(a / 2)) < 1e-18


def test_quat_mul_composes_rotations():
    a = quat_from_rotvec(RNG.normal(size=3))
    b = quat_from_rotvec(RNG.normal(size=3))
    np.testing.assert_allclose(
        quat_to_matrix(quat_mul(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-15
    )
    np.testing.assert_allclose(quat_mul(a, quat_conj(a)), [1, 0, 0, 0], atol=1e-15)
    q = quat_normalize(np.array([2.0, 0.0, 0.0, 2.0]))
    np.testing.assert_allclose(q, [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], atol=1e-16)


# --------------------------------------------------------------------------- translation


def test_free_fall_exact_with_staggered_start():
    b = Blocks(3, mass=2.5)
    b.gravity[:] = (0.3, -0.2, -9.81)
    x0 = RNG.normal(size=(3, 3))
    v0 = RNG.normal(size=(3, 3)) * 5
    b.x[:] = x0
    b.v[:] = v0
    dt = 1e-3
    b.stagger(dt)  # v(-dt/2) = v0 - g dt/2
    np.testing.assert_allclose(b.v, v0 - b.gravity * dt / 2, rtol=1e-15)
    nstep = 2000
    for _ in range(nstep):
        b.step(dt)
    t = nstep * dt
    exact = x0 + v0 * t + 0.5 * b.gravity * t * t
    assert np.abs(b.x - exact).max() <= 1e-12 * np.abs(exact).max()
    # v is the mid-step velocity v(t - dt/2)
    np.testing.assert_allclose(b.v, v0 + b.gravity * (t - dt / 2), rtol=1e-12)


def test_unstaggered_start_is_first_order():
    """Without stagger_start the trajectory is off by g t dt / 2 -- the convention matters."""
    b = Blocks(1)
    b.gravity[:] = (0.0, 0.0, -10.0)
    dt = 1e-2
    for _ in range(100):
        b.step(dt)
    t = 1.0
    assert abs(b.x[0, 2] - (-5.0 - 10.0 * t * dt / 2)) < 1e-12


def test_mass_scaling_keeps_true_weight():
    b = Blocks(2, mass=3.0)
    b.gravity[:] = (0.0, 0.0, -9.81)
    b.mscale[:] = (1.0, 4.0)
    b.force[:] = (6.0, 0.0, 0.0)
    dt = 0.01
    b.step(dt)
    np.testing.assert_allclose(b.v[0], (2.0 * dt, 0.0, -9.81 * dt), rtol=1e-15)
    np.testing.assert_allclose(b.v[1], (0.5 * dt, 0.0, -9.81 / 4 * dt), rtol=1e-15)


# --------------------------------------------------------------------------- rotation


def test_torque_free_asymmetric_block_conserves_L_and_energy():
    b = Blocks(2, mass=1.0, inertia=(1.0, 2.0, 3.0))
    b.q[1] = quat_from_rotvec(np.array([0.3, -1.2, 0.7]))
    # block 0: near the stable axis 3; block 1: near the unstable intermediate axis (flips)
    b.set_omega(np.array([[1.0, 0.01, 2.0], [0.02, 2.0, 0.03]]))
    b.w[1] = rotate(b.q[1], np.array([0.02, 2.0, 0.03]))
    M.momentum_from_omega(b.q, b.w, b.inertia, b.mscale, False, b.L)
    L0 = b.L.copy()

    def rot_energy(i):
        sl = slice(i, i + 1)
        return kinetic_energy(
            b.mass[sl], b.inertia[sl], b.q[sl], b.v[sl], b.L[sl], b.mscale[sl], False
        )[1]

    e_init = [rot_energy(0), rot_energy(1)]
    dt = 1e-3
    err = np.zeros(2)
    axis2 = []
    for _ in range(10_000):
        b.step(dt)
        for i in range(2):
            err[i] = max(err[i], abs(rot_energy(i) / e_init[i] - 1.0))
        axis2.append(rotate_inv(b.q[1], b.w[1])[1])
    assert np.abs(b.L - L0).max() <= 1e-12 * np.abs(L0).max()
    print("max relative energy error", err)
    assert err.max() < 1e-6, err  # measured ~4e-8 and ~2e-7
    assert min(axis2) < -1.5  # the intermediate-axis block really flipped
    assert b.stats[M.STAT_ROT_ITER] <= 6
    # stored w and L are consistent (w = I_world(q_mid)^-1 L, so 1/2 w.L is the energy)
    assert abs(0.5 * b.w[0] @ b.L[0] / e_init[0] - 1.0) < 1e-6


def _euler_rk4(wb, inertia, t, nsub):
    """Reference body-frame angular velocity of a free body (Euler eqs. 45, RK4)."""
    i1, i2, i3 = inertia

    def f(w):
        return np.array(
            [
                (i2 - i3) * w[1] * w[2] / i1,
                (i3 - i1) * w[2] * w[0] / i2,
                (i1 - i2) * w[0] * w[1] / i3,
            ]
        )

    h = t / nsub
    w = wb.copy()
    for _ in range(nsub):
        k1 = f(w)
        k2 = f(w + h / 2 * k1)
        k3 = f(w + h / 2 * k2)
        k4 = f(w + h * k3)
        w = w + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return w


def test_free_rotation_second_order_against_euler_equations():
    inertia = (1.0, 2.0, 3.0)
    wb0 = np.array([1.0, 0.5, 2.0])
    t_end = 1.0
    ref = _euler_rk4(wb0, inertia, t_end, 20_000)
    errs = []
    for dt in (4e-3, 2e-3):
        b = Blocks(1, inertia=inertia)
        b.set_omega(wb0)
        b.stagger(dt)
        for _ in range(round(t_end / dt)):
            b.step(dt)
        # body-frame omega at t_end from L and q(t_end)
        wb = rotate_inv(b.q[0], b.L[0]) / np.array(inertia)
        errs.append(np.linalg.norm(wb - ref))
    assert errs[0] < 1e-4
    assert 3.5 < errs[0] / errs[1] < 4.5  # second order


def test_constant_torque_about_principal_axis_grows_linearly():
    b = Blocks(1, inertia=(1.0, 2.0, 3.0))
    b.q[0] = quat_from_rotvec(np.array([0.4, 0.2, -0.9]))
    axis = rotate(b.q[0], np.array([0.0, 1.0, 0.0]))  # body axis 2 in the world frame
    b.moment[0] = 3.0 * axis
    dt = 1e-3
    b.stagger(dt)
    q0 = b.q[0].copy()
    nstep = 1000
    for k in range(nstep):
        b.step(dt)
        if k % 100 == 99:
            t_mid = (k + 0.5) * dt
            np.testing.assert_allclose(b.w[0], 3.0 / 2.0 * t_mid * axis, rtol=1e-12, atol=1e-14)
    # rotation angle about the fixed axis = 1/2 (M/I) t^2, exact for the staggered scheme
    t = nstep * dt
    dq = quat_mul(b.q[0], quat_conj(q0))
    np.testing.assert_allclose(quat_to_rotvec(dq), 0.75 * t * t * axis, rtol=1e-11)


def test_scalar_inertia_mode():
    b = Blocks(1, inertia=(1.0, 2.0, 4.0))  # mean 7/3
    b.scalar = True
    b.q[0] = quat_from_rotvec(np.array([1.0, 0.5, 0.2]))
    b.set_omega(np.array([0.3, -0.2, 0.5]))
    w_prev = b.w[0].copy()
    mom = np.array([1.0, -2.0, 0.5])
    b.moment[0] = mom
    dt = 1e-2
    for _ in range(50):
        b.step(dt)
        np.testing.assert_allclose((b.w[0] - w_prev) / dt * (7.0 / 3.0), mom, rtol=1e-9)
        w_prev = b.w[0].copy()
    assert b.stats[M.STAT_ROT_ITER] == 0


# --------------------------------------------------------------------------- boundary flags


def test_fixed_block_never_moves():
    b = Blocks(2)
    b.fixed[0] = 1
    b.gravity[:] = (0.0, 0.0, -9.81)
    b.force[:] = (100.0, 5.0, 3.0)
    b.moment[:] = (1.0, 2.0, 3.0)
    b.v[0] = (1.0, 1.0, 1.0)
    b.set_omega(np.array([0.5, 0.0, 0.0]))
    x0 = b.x[0].copy()
    q0 = b.q[0].copy()
    for _ in range(100):
        b.step(1e-3, "local", 0.8)
    assert np.array_equal(b.x[0], x0) and np.array_equal(b.q[0], q0)
    assert not b.v[0].any() and not b.w[0].any() and not b.L[0].any()
    assert not b.dx[0].any() and not b.dtheta[0].any()
    assert b.x[1, 0] > 0.0  # the free one did move
    assert b.stats[M.STAT_N_FREE] == 1


def test_prescribed_velocity_moves_exactly():
    b = Blocks(1, inertia=(1.0, 2.0, 3.0))
    b.vfix[0] = 1
    b.gravity[:] = (0.0, 0.0, -9.81)
    b.force[0] = (50.0, -20.0, 7.0)
    b.moment[0] = (3.0, 1.0, -2.0)
    vel = np.array([0.5, -0.25, 0.125])
    om = np.array([0.2, 0.1, -0.3])
    b.v[0] = vel
    b.w[0] = om
    dt = 1e-3
    n = 500
    for _ in range(n):
        b.step(dt, "viscous", 5.0)
    assert np.array_equal(b.v[0], vel) and np.array_equal(b.w[0], om)
    np.testing.assert_allclose(b.x[0], vel * n * dt, rtol=1e-13)
    np.testing.assert_allclose(quat_to_rotvec(b.q[0]), om * n * dt, rtol=1e-12)
    np.testing.assert_allclose(b.dx[0], vel * dt, rtol=1e-15)
    np.testing.assert_allclose(b.dtheta[0], om * dt, rtol=1e-15)
    assert b.stats[M.STAT_N_FREE] == 0 and b.stats[M.STAT_MAX_FORCE] == 0.0


# --------------------------------------------------------------------------- damping


def _spring_peaks(mode, alpha, drift=0.0, ncyc=8, dt=1e-3, stiffness=(2 * np.pi) ** 2):
    """Unit mass on a spring (period 1 s) whose anchor moves at ``drift``; peak |x| per cycle."""
    b = Blocks(1)
    b.v[0, 0] = drift + 1.0
    per = round(1.0 / dt)
    peaks = []
    cur = 0.0
    for s in range(ncyc * per):
        b.force[0, 0] = -stiffness * (b.x[0, 0] - drift * s * dt)
        b.step(dt, mode, alpha)
        cur = max(cur, abs(b.x[0, 0] - drift * (s + 1) * dt))
        if (s + 1) % per == 0:
            peaks.append(cur)
            cur = 0.0
    return np.array(peaks)


def test_undamped_spring_keeps_amplitude():
    p = _spring_peaks("none", 0.7)
    np.testing.assert_allclose(p / p[0], 1.0, atol=1e-5)
    p = _spring_peaks("local", 0.0)
    np.testing.assert_allclose(p / p[0], 1.0, atol=1e-5)


def test_local_damping_decay_ratio():
    alpha = 0.1
    p = _spring_peaks("local", alpha)
    ratio = p[1:] / p[:-1]
    assert np.all(ratio < 1.0)
    # energy argument: each half cycle the amplitude falls by sqrt((1 - a)/(1 + a))
    np.testing.assert_allclose(ratio, (1 - alpha) / (1 + alpha), rtol=1e-4)


def test_viscous_damping_matches_exponential_decay():
    alpha = 0.2
    p = _spring_peaks("viscous", alpha)
    np.testing.assert_allclose(p[1:] / p[:-1], math.exp(-alpha / 2), rtol=1e-2)
    p2 = _spring_peaks("adaptive", alpha)  # same kernel path with a caller-set alpha
    np.testing.assert_array_equal(p, p2)


def test_combined_damping_works_with_steady_drift():
    """Velocity never changes sign: local damping stalls, combined damping (eq. 83) decays."""
    loc = _spring_peaks("local", 0.1, drift=3.0)
    com = _spring_peaks("combined", 0.1, drift=3.0)
    assert loc[-1] / loc[1] > 0.99
    assert np.all(np.diff(com) < 0.0) and com[-1] / com[0] < 0.5


def test_damping_stats_and_adaptive_servo():
    b = Blocks(1)
    b.v[0, 0] = 1.0
    k = (2 * np.pi) ** 2
    dt = 1e-3
    alpha = 0.05
    p_sum = dek_sum = 0.0
    e_start = None
    for s in range(20_000):
        b.force[0, 0] = -k * b.x[0, 0]
        b.step(dt, "adaptive", alpha)
        assert b.stats[M.STAT_DAMP_POWER] >= 0.0
        p_sum += b.stats[M.STAT_DAMP_POWER]
        dek_sum += b.stats[M.STAT_DEK]
        if s % 10 == 9:
            alpha = M.adaptive_alpha_update(alpha, p_sum, dek_sum, 0.5, dt=dt)
            p_sum = dek_sum = 0.0
        if e_start is None:
            e_start = b.stats[M.STAT_KE]
    # servo settles around alpha ~ 2 R w0 / pi = 2 (rad/s), kinetic energy is drained
    assert 0.5 < alpha < 8.0
    e_end = 0.5 * b.v[0, 0] ** 2 + 0.5 * k * b.x[0, 0] ** 2
    assert e_end < 1e-6 * e_start


def test_adaptive_alpha_update_rules():
    a = M.adaptive_alpha_update(1.0, 1.0, 10.0, 0.5)  # R = 0.1 < 0.5: more damping
    assert 1.01 <= a <= 1.10
    a = M.adaptive_alpha_update(1.0, 100.0, 1.0, 0.5)  # R = 100: less
    assert 1 / 1.10 <= a <= 1 / 1.01
    assert M.adaptive_alpha_update(1.0, 0.5, 1.0, 0.5) == 1.0
    assert M.adaptive_alpha_update(1.0, 1.0, 0.0) == 1.0  # at rest: unchanged
    assert M.adaptive_alpha_update(0.0, 0.0, 1.0, alpha_min=1e-3) > 1e-3
    assert M.adaptive_alpha_update(999.0, 0.0, 1.0, dt=0.01) == 100.0
    assert set(DAMPING) == {"none", "local", "combined", "viscous", "adaptive", "rayleigh"}


def test_local_damping_on_rotation():
    b = Blocks(1, inertia=(2.0, 2.0, 2.0))
    b.set_omega(np.array([0.0, 0.0, 1.0]))
    kr = (2 * np.pi) ** 2 * 2.0  # torsional spring, period 1 s
    dt = 1e-3
    peaks = []
    cur = 0.0
    for s in range(4000):
        ang = quat_to_rotvec(b.q[0])[2]
        b.moment[0, 2] = -kr * ang
        b.step(dt, "local", 0.2)
        cur = max(cur, abs(ang))
        if (s + 1) % 1000 == 0:
            peaks.append(cur)
            cur = 0.0
    np.testing.assert_allclose(np.array(peaks[1:]) / peaks[:-1], 0.8 / 1.2, rtol=1e-3)


# --------------------------------------------------------------------------- energy


def test_energy_and_momentum_reporting():
    b = Blocks(2, mass=2.0, inertia=(1.0, 2.0, 3.0))
    b.x[:] = RNG.normal(size=(2, 3))
    b.v[:] = RNG.normal(size=(2, 3))
    b.q[1] = quat_from_rotvec(np.array([0.1, 0.2, 0.3]))
    b.set_omega(RNG.normal(size=(2, 3)))
    b.mscale[:] = (1.0, 3.0)
    M.momentum_from_omega(b.q, b.w, b.inertia, b.mscale, False, b.L)
    et, er = kinetic_energy(b.mass, b.inertia, b.q, b.v, b.L, b.mscale, False)
    assert et == pytest.approx(0.5 * 2.0 * (b.v**2).sum(), rel=1e-14)
    er_hand = 0.0
    for i in range(2):
        r = quat_to_matrix(b.q[i])
        er_hand += 0.5 * b.w[i] @ (r @ np.diag(b.inertia[i]) @ r.T @ b.w[i])
    assert er == pytest.approx(er_hand, rel=1e-13)
    h0 = angular_momentum(b.mass, b.x, b.v, b.L, b.mscale)
    p0 = linear_momentum(b.mass, b.v)
    for _ in range(300):
        b.step(1e-2)
    np.testing.assert_allclose(
        angular_momentum(b.mass, b.x, b.v, b.L, b.mscale), h0, rtol=1e-12, atol=1e-12
    )
    np.testing.assert_allclose(linear_momentum(b.mass, b.v), p0, rtol=1e-15)
    assert b.energy() == pytest.approx(et + er, rel=1e-4)


# --------------------------------------------------------------------------- timestep


def test_auto_timestep_hand_computation():
    masses = np.array([2.0, 8.0, 0.5])
    stiff = np.array([100.0, 400.0, 1e9])
    fixed = np.array([0, 0, 1])
    # eq. (87): M_min = 2, K_max = 400 over the free blocks
    assert auto_timestep(masses, stiff, 0.1, fixed=fixed) == pytest.approx(
        0.1 * 2 * math.sqrt(2.0 / 400.0), rel=1e-15
    )
    # rotational bound: block 1: I_min = 1, r = 1 -> 2 * 0.1 * sqrt(1 / 400) = 0.01 < 0.01414
    inertias = np.array([[1.0, 1.0, 1.0], [1.0, 5.0, 5.0], [1.0, 1.0, 1.0]])
    radii = np.array([0.1, 1.0, 1.0])
    assert auto_timestep(masses, stiff, 0.1, inertias, radii, fixed=fixed) == pytest.approx(
        0.01, rel=1e-15
    )
    assert auto_timestep(masses, np.zeros(3)) == math.inf
    assert auto_timestep(
        masses, stiff, 0.1, fixed=fixed, mass_scale=[4.0, 1.0, 1.0]
    ) == pytest.approx(0.2 * math.sqrt(8.0 / 400.0), rel=1e-15)


def test_block_stiffness_and_mass_scaling():
    k = block_stiffness(3, [0, 0, 1], [1, 2, -1], [10.0, 5.0, 1.0])
    np.testing.assert_allclose(k, [15.0, 11.0, 5.0])
    masses = np.array([1.0, 100.0, 0.01])
    dt = 0.1
    s = mass_scale_factors(masses, k, dt, 0.1)
    assert s[1] == 1.0 and s[0] > 1.0 and s[2] > 1.0
    dts = 0.1 * 2 * np.sqrt(s * masses / k)
    np.testing.assert_allclose(dts[[0, 2]], dt, rtol=1e-14)
    su = mass_scale_factors(masses, k, dt, 0.1, uniform=True)
    np.testing.assert_allclose(0.1 * 2 * np.sqrt(su * masses / k), dt, rtol=1e-14)
    assert auto_timestep(masses, k, 0.1, mass_scale=su) == pytest.approx(
        0.2 * math.sqrt((su * masses).min() / k.max()), rel=1e-15
    )
    inertias = np.array([[0.1, 0.2, 0.3]] * 3)
    radii = np.ones(3)
    sr = mass_scale_factors(masses, k, dt, 0.1, inertias, radii)
    assert np.all(sr >= s)
    np.testing.assert_allclose(sr[0], k[0] * dt**2 / (4 * 0.01 * 0.1))
