"""Re-run the physics verification cases of tests/verification and plot numerical against
closed-form results into docs/figures/*.png (the figures of docs/validation.md and
docs/dynamics.md's base-motion.png and waves.png).

This is a documentation tool only: it needs matplotlib, which is *not* a dependency of pdem
and is not installed by ``pip install -e .[test]``; nothing in pdem/ or tests/ imports it.

    .venv/bin/python -m pip install matplotlib
    .venv/bin/python docs/make_figures.py            # from the repository root, ~1-3 min
    python3 docs/make_figures.py dip-convention      # one figure, by its name in CASES

Any python with numpy and matplotlib will do (the system python3, say): pdem is imported from
this checkout, its compiled and MPI parts only when a case runs a simulation, and h5py only by
arch-energy. dip-convention (docs/rock-mass.md) is a drawing, no simulation.

The scenes, constants and closed forms come from the case library pdem.cases, which the tests
(tests/verification/test_*.py) use too, so the figures show exactly the set-ups the tests
assert on.
Single rank (MPI.COMM_SELF), no output files (arch-energy writes one into a temporary
directory and reads the energy history back). Each case also prints its key numbers, which
docs/validation.md quotes.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FIG = os.path.join(ROOT, "docs", "figures")
sys.path.insert(0, ROOT)  # the figures document this checkout's pdem

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import pdem.cases.collapse as tco  # noqa: E402
import pdem.cases.incline as tin  # noqa: E402
import pdem.cases.oscillator as tos  # noqa: E402
import pdem.cases.shaking as tsh  # noqa: E402
import pdem.cases.static as tst  # noqa: E402
import pdem.cases.tipping as tcp  # noqa: E402
import pdem.cases.tumbling as ttu  # noqa: E402
import pdem.cases.waves as twv  # noqa: E402
import pdem.cases.wedge as twe  # noqa: E402
from pdem.cases import (  # noqa: E402
    crossing_times,
    fit_acceleration,
    free_row,
    make_simulation,
    rotation_matrix,
)

G = 9.81


def save(fig, name: str):
    os.makedirs(FIG, exist_ok=True)
    path = os.path.join(FIG, name)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    print(f"  wrote {os.path.relpath(path, ROOT)}")


# --------------------------------------------------------------------------- incline
def incline_run(phi: float, algorithm: str = "fast", time_: float = 1.0):
    s = make_simulation(tin.incline_scene(phi, algorithm, f"time: {time_}"))
    b = s.blocks
    i = free_row(s)
    n = int(round(time_ / s.dt))
    t = np.empty(n)
    x = np.empty(n)
    for k in range(n):
        s.advance()
        t[k] = s.time
        x[k] = b.x[i, 0] - b.x0[i, 0]
    return t, x


def a_incline(phi: float) -> float:
    return max(0.0, tin.sliding_acceleration(phi))


def incline():
    print("incline (psi = 20 deg)")
    fig, (ax, ar, aw) = plt.subplots(1, 3, figsize=(18, 5))
    for phi, col in ((10.0, "C0"), (15.0, "C1")):
        t, x = incline_run(phi)
        late = t >= 0.1
        a_num = fit_acceleration(t[late], x[late])
        a_ex = a_incline(phi)
        # closed form 1/2 a t^2 plus the start-up offset x0 + v0 t, fitted with a fixed to a_exact
        c1, c0 = np.polyfit(t[late], x[late] - 0.5 * a_ex * t[late] ** 2, 1)
        closed = c0 + c1 * t + 0.5 * a_ex * t**2
        print(f"  phi={phi}: a_num={a_num:.6f} a_exact={a_ex:.6f} rel.err={a_num / a_ex - 1:+.2e}"
              f"  offset x0={c0:.2e} m v0={c1:.2e} m/s")
        ax.plot(t, x, col, lw=2.5, alpha=0.5, label=fr"pdem, $\phi$={phi:g}°")
        ax.plot(t, closed, "k--", lw=1)
        ar.loglog(t, np.maximum(np.abs(x - closed), 1e-12), col, lw=1,
                  label=fr"$\phi$={phi:g}°: a = {a_num:.4f} m/s² "
                        fr"(exact {a_ex:.4f}, rel. err. {a_num / a_ex - 1:+.1e})")
    ax.plot([], [], "k--", lw=1, label=r"$x_0 + v_0 t + \frac{1}{2} a t^2$, exact $a$")
    ax.set(xlabel="time t (s)", ylabel="displacement down the slope x (m)",
           title=r"20° incline: $a = g(\sin\psi - \cos\psi\tan\phi)$, $\psi$ = 20°")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ar.axvline(0.1, color="0.6", ls=":", lw=1)
    ar.text(0.11, 1e-7, "fit window\nt ≥ 0.1 s", color="0.4", fontsize=8)
    ar.set(xlabel="time t (s)", ylabel="|pdem − closed form| (m)", ylim=(1e-11, 1e-4),
           title="Residual: shear-spring start-up, then nm vibration")
    ar.legend(fontsize=8, loc="upper right")
    ar.grid(alpha=0.3, which="both")

    # friction sweep: 0.6 s runs, fit on t in [0.1, 0.6]
    phis = [0.0, 5.0, 10.0, 12.5, 15.0, 17.5, 19.0, 19.5, 20.5, 21.0, 25.0, 30.0]
    res = {}
    for alg in ("fast", "cundall"):
        sweep = phis if alg == "fast" else phis[::2]
        pts = []
        for phi in sweep:
            t, x = incline_run(phi, alg, 0.6)
            late = t >= 0.1
            pts.append(fit_acceleration(t[late], x[late]))
        res[alg] = (np.array(sweep), np.array(pts))
        errs = [f"{p:g}:{a:.4f}/{a_incline(p):.4f}" for p, a in zip(sweep, pts, strict=True)]
        print(f"  sweep {alg}: " + " ".join(errs))
    pl = np.linspace(0.0, 32.0, 321)
    aw.plot(pl, [a_incline(p) for p in pl], "k-", lw=1,
            label=r"$g(\sin\psi - \cos\psi\tan\phi)$, 0 for $\phi \geq \psi$")
    aw.plot(*res["fast"], "o", color="C0", mfc="none", ms=8, label="pdem, fast common plane")
    aw.plot(*res["cundall"], "x", color="C3", ms=7, label="pdem, Cundall common plane")
    aw.axvline(tin.PSI, color="0.6", ls=":", lw=1)
    aw.text(tin.PSI + 0.3, 2.8, r"$\phi = \psi$ = 20°", color="0.4", fontsize=8)
    aw.set(xlabel=r"friction angle $\phi$ (deg)", ylabel="sliding acceleration a (m/s²)",
           title="Friction sweep (fit of x(t) on 0.1 ≤ t ≤ 0.6 s)")
    aw.legend(fontsize=8)
    aw.grid(alpha=0.3)
    save(fig, "incline.png")


# --------------------------------------------------------------------------- oscillator
def oscillator_run(kn: float, periods: float = 30.0):
    m = tos.RHO
    delta = tos.static_overlap(m, kn)
    text = tos.cube_on_floor(-2.0 * delta).replace(f"kn: {tos.KN}, ks: {tos.KN}",
                                                     f"kn: {kn!r}, ks: {kn!r}")
    assert f"kn: {kn!r}" in text
    s = make_simulation(text)
    b = s.blocks
    i = free_row(s)
    period = tos.period(m, kn)
    n = int(periods * period / s.dt)
    t = np.empty(n)
    z = np.empty(n)
    vz = np.empty(n)
    for k in range(n):
        s.advance()
        t[k] = s.time
        z[k] = b.x[i, 2] - 0.5  # bottom face height = - overlap
        vz[k] = b.v[i, 2]
    tc = crossing_times(t - 0.5 * s.dt, vz)  # v is at the half step
    measured = (tc[-1] - tc[0]) / (len(tc) - 1)
    return t, z, measured, period, delta, s.dt


def oscillator():
    print("contact oscillator")
    fig, (ax, ap) = plt.subplots(1, 2, figsize=(13, 4.6))
    t, z, measured, period, delta, dt = oscillator_run(tos.KN, 30.0)
    omega = 2.0 * math.pi / period
    show = t <= 3.2 * period
    tt = np.linspace(0.0, t[show][-1], 600)
    ax.plot(t[show] * 1e3, -z[show] * 1e6, "o", ms=3, color="C0", label=f"pdem (dt = {dt:.2e} s)")
    ax.plot(tt * 1e3, delta * (1.0 + np.cos(omega * tt)) * 1e6, "k-", lw=1,
            label=r"$\delta\,(1 + \cos \omega t)$, $\omega = \sqrt{k_n A / m}$")
    for k in range(1, 4):
        ax.axvline(k * period * 1e3, color="0.6", ls=":", lw=1)
    ax.axhline(delta * 1e6, color="0.8", lw=1)
    ax.text(period * 1e3, 2.05 * delta * 1e6, " T", color="0.4")
    ax.set(xlabel="time t (ms)", ylabel=r"overlap $u_n$ = −(bottom face height) (µm)",
           ylim=(-0.1 * delta * 1e6, 2.2 * delta * 1e6),
           title=r"Cube on floor, $k_n$ = 1e9 Pa/m, started at 2δ: $T = 2\pi\sqrt{m/(k_n A)}$")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)

    kns = [1e8, 3e8, 1e9, 3e9, 1e10]
    meas, exact = [], []
    for kn in kns:
        *_, mp, pe, _, dtk = oscillator_run(kn, 30.0)
        meas.append(mp)
        exact.append(pe)
        print(f"  kn={kn:.0e}: T={mp:.6e} exact={pe:.6e} rel.err={mp / pe - 1:+.2e} dt={dtk:.2e}")
    kk = np.logspace(7.8, 10.2, 50)
    ap.loglog(kk, 2 * np.pi * np.sqrt(tos.RHO / kk) * 1e3, "k-", lw=1,
              label=r"$2\pi\sqrt{m/(k_n A)}$")
    ap.loglog(kns, np.array(meas) * 1e3, "o", color="C0", mfc="none", ms=9,
              label="pdem (mean of ~30 periods); labels: relative error\n"
                    r"(leapfrog theory: $-(\omega\,\Delta t)^2/24$ = "
                    f"{-100 * (2 * math.pi * dt / period) ** 2 / 24:+.3f} % at the automatic step)")
    for kn, mp, pe in zip(kns, meas, exact, strict=True):
        ap.annotate(f"{100 * (mp / pe - 1):+.3f} %", (kn, mp * 1e3), textcoords="offset points",
                    xytext=(6, 6), fontsize=8)
    ap.set(xlabel=r"joint normal stiffness $k_n$ (Pa/m), A = 1 m²", ylabel="period T (ms)",
           title="Measured vs analytical period (m = 2000 kg)")
    ap.legend(fontsize=8, loc="lower left")
    ap.grid(alpha=0.3, which="both")
    save(fig, "oscillator.png")


# --------------------------------------------------------------------------- elastic bounce
def bounce():
    print("elastic bounce (h = 1 cm)")
    h = 0.01
    m = tos.RHO
    s = make_simulation(tos.cube_on_floor(h, end="time: 1.0"))
    b = s.blocks
    i = free_row(s)

    def elastic() -> float:
        c = s.contacts
        kn = s.state.joints.kn[np.repeat(c.joint, np.diff(c.sc_start))]
        un = np.maximum(c.sc_un, 0.0)
        return 0.5 * float(np.sum(kn * c.sc_area * un * un))

    n = int((2.0 * math.sqrt(2.0 * h / G) + 0.02) / s.dt)
    t = np.empty(n)
    kin = np.empty(n)
    pot = np.empty(n)
    ela = np.empty(n)
    bottom = np.empty(n)
    for k in range(n):
        v_minus = b.v[i].copy()
        zb = b.x[i, 2] - 0.5
        t[k] = s.time
        pot[k] = m * G * zb  # zero at first touch (bottom face at z = 0)
        ela[k] = elastic()
        s.advance()
        kin[k] = 0.5 * m * float(v_minus @ b.v[i])  # leapfrog time-centred K at t[k]
        bottom[k] = zb
    e_drop = m * G * h
    tot = kin + pot + ela
    drift = (tot.max() - tot.min()) / e_drop
    lowest = int(np.argmin(bottom))
    rebound = bottom[lowest:].max() / h
    print(f"  energy variation {drift:.2e} of m g h, rebound/drop {rebound:.6f}, "
          f"max overlap {-bottom.min():.2e} m, dt {s.dt:.2e}")
    fig, (ax, az) = plt.subplots(1, 2, figsize=(13, 4.6))
    for a in (ax, az):
        a.plot(t * 1e3, kin / e_drop, label="kinetic $K$ (time-centred)")
        a.plot(t * 1e3, pot / e_drop, label="potential $m g z_{bottom}$")
        a.plot(t * 1e3, ela / e_drop, label=r"contact elastic $\sum \frac{1}{2} k_n A_s u_n^2$")
        a.plot(t * 1e3, tot / e_drop, "k", lw=2, label="total")
        a.set(xlabel="time t (ms)", ylabel="energy / (m g h)")
        a.grid(alpha=0.3)
    fig.suptitle(f"Unit cube (m = 2000 kg) dropped face-on from h = 1 cm onto a fixed floor, "
                 f"kn = 1e9 Pa/m, no damping: total energy varies by {drift:.1e} m g h, "
                 f"rebound height {rebound:.4f} h", fontsize=10)
    ax.set_title("Whole drop and rebound", fontsize=10)
    ax.legend(fontsize=8, loc="center right")
    t_touch = math.sqrt(2.0 * h / G)
    half = tos.contact_duration(m, tos.KN)
    az.set_xlim((t_touch - 0.3 * half) * 1e3, (t_touch + 1.3 * half) * 1e3)
    az.axvspan(t_touch * 1e3, (t_touch + half) * 1e3, color="0.9", zorder=0)
    az.set_title(r"Zoom on the contact: analytical duration $\pi\sqrt{m/(k_n A)}$"
                 f" = {half * 1e3:.2f} ms (shaded)", fontsize=10)
    save(fig, "bounce.png")


# --------------------------------------------------------------------------- tumbling
def tumbling():
    print("free tumbling")
    fig, (ah, ak) = plt.subplots(1, 2, figsize=(13, 4.6))
    for shape, col in (("box123", "C0"), ("random", "C1")):
        s = make_simulation(ttu.tumbling_scene(shape))
        b = s.blocks
        m = float(b.mass[0])

        def momentum(b=b, m=m):
            return b.L[0] + m * np.cross(b.x[0], b.v[0])

        def energy(b=b, m=m):
            return 0.5 * m * float(b.v[0] @ b.v[0]) + 0.5 * float(b.w[0] @ b.L[0])

        h0, k0 = momentum(), energy()
        n = 5000
        dh = np.empty(n)
        dlm = np.empty(n)
        dk = np.empty(n)
        turned = 0.0
        for k in range(n):
            s.advance()
            hh = momentum()
            dh[k] = np.linalg.norm(hh - h0) / np.linalg.norm(h0)
            dlm[k] = abs(np.linalg.norm(hh) / np.linalg.norm(h0) - 1.0)
            dk[k] = abs(energy() - k0) / k0
            turned += float(np.linalg.norm(b.w[0])) * s.dt
        steps = np.arange(1, n + 1)
        floor = 1e-18
        print(f"  {shape}: max |dH|/|H| {dh.max():.2e}, max ||H|/|H0|-1| {dlm.max():.2e}, "
              f"max |dK|/K {dk.max():.2e}, turned {turned:.2f} rad in {n} steps, dt {s.dt:.2e}")
        lab = {"box123": "box 1×2×3 m", "random": "random 14-vertex polyhedron"}[shape]
        ah.semilogy(steps, np.maximum(dh, floor), color=col, lw=1,
                    label=fr"{lab}: $|H - H_0|/|H_0|$")
        ah.semilogy(steps, np.maximum(dlm, floor), color=col, lw=1, ls="--", alpha=0.7,
                    label=fr"{lab}: $||H|/|H_0| - 1|$")
        ak.semilogy(steps, np.maximum(dk, floor), color=col, lw=1,
                    label=f"{lab} (turns {turned:.1f} rad)")
    eps = np.finfo(float).eps
    ah.axhline(1e-10, color="C3", ls=":", lw=1, label="test tolerance 1e-10")
    ah.axhline(eps, color="0.5", ls="-.", lw=1, label="machine epsilon")
    ah.set(xlabel="step", ylabel="relative drift", ylim=(1e-18, 1e-8),
           title=r"Angular momentum $H = L + m\,x \times v$ (exactly conserved)")
    ah.legend(fontsize=7, loc="upper left")
    ah.grid(alpha=0.3, which="both")
    ak.axhline(1e-5, color="C3", ls=":", lw=1, label="test tolerance 1e-5")
    ak.set(xlabel="step", ylabel=r"$|K - K_0| / K_0$", ylim=(1e-10, 1e-4),
           title=r"Kinetic energy $K = \frac{1}{2} m |v|^2 + \frac{1}{2}\,\omega \cdot L$"
                 " (bounded error)")
    ak.legend(fontsize=8, loc="lower right")
    ak.grid(alpha=0.3, which="both")
    fig.suptitle("Torque-free tumbling, no gravity, no contacts, 5000 steps", fontsize=11)
    save(fig, "tumbling.png")


# --------------------------------------------------------------------------- wedge
def wedge():
    print("DDA wedge")
    phi_c = twe.critical_friction()

    def a_exact(phi):
        return max(0.0, twe.sliding_acceleration(phi))

    t, u = twe.displacement_history(twe.wedge_simulation(15.0, "fast"), 0.5)
    late = t >= 0.1
    a_num = fit_acceleration(t[late], u[late])
    print(f"  phi_c = {phi_c:.4f} deg; phi=15: a_num={a_num:.6f} exact={a_exact(15.0):.6f} "
          f"rel.err={a_num / a_exact(15.0) - 1:+.2e}")
    cache = {}

    def u_end_of(phi):
        if phi not in cache:
            _, uu = twe.displacement_history(twe.wedge_simulation(phi, "fast"), 0.5)
            cache[phi] = float(uu[-1])
            print(f"  phi={phi:7.4f}: u(0.5 s) = {uu[-1]:.3e} m (rigid, from rest: "
                  f"{0.5 * a_exact(phi) * 0.25:.3e} m)")
        return cache[phi]

    phis = [10.0, 15.0, 17.0, 18.0, 19.0, 19.4, 19.6, 19.8, 20.0, 20.5, 22.0, 25.0]
    u_end = np.array([u_end_of(p) for p in phis])
    # the bisection of test_wedge.test_wedge_critical_friction: slides = u > 1 mm
    lo, hi = 18.0, 22.0
    assert u_end_of(lo) > 1e-3 and u_end_of(hi) <= 1e-3
    for _ in range(6):
        mid = 0.5 * (lo + hi)
        if u_end_of(mid) > 1e-3:
            lo = mid
        else:
            hi = mid
    phi_num = 0.5 * (lo + hi)
    print(f"  bisection: phi_c numerical {phi_num:.4f} deg (bracket {lo:.4f}..{hi:.4f}), "
          f"limit equilibrium {phi_c:.4f}, difference {phi_num - phi_c:+.4f} deg")
    bis = sorted(p for p in cache if p not in phis)
    fig, ax = plt.subplots(figsize=(8.5, 5))
    pl = np.linspace(9.0, 26.0, 800)
    ua = np.array([0.5 * a_exact(p) * 0.25 for p in pl])
    ax.semilogy(pl[ua > 0], ua[ua > 0], "k-", lw=1,
                label=r"rigid wedge from rest: $\frac{1}{2} a t^2$, "
                      r"$a = (W\cdot d - (N_A + N_B)\tan\phi)/m$")
    ax.semilogy(phis, np.maximum(np.abs(u_end), 1e-7), "o", color="C0", mfc="none", ms=8,
                label="pdem (fast common plane), |u| along the line of intersection")
    ax.semilogy(bis, [max(abs(cache[p]), 1e-7) for p in bis], "+", color="C0", ms=8,
                label="pdem, bisection runs")
    ax.axvspan(lo, hi, color="C0", alpha=0.25,
               label=fr"pdem $\phi_c$ bracket {lo:.3f}–{hi:.3f}° (midpoint {phi_num:.3f}°)")
    ax.axvline(phi_c, color="C3", lw=1.2, label=fr"limit equilibrium $\phi_c$ = {phi_c:.2f}°")
    ax.axvline(19.6, color="C2", lw=1.2, ls="--", label=r"explicit 3D-DDA paper: $\phi_c$ = 19.6°")
    ax.axhline(1e-3, color="0.5", ls=":", lw=1, label="'slides' threshold of the test (1 mm)")
    ax.set(xlabel=r"joint friction angle $\phi$ (deg), both planes",
           ylabel="displacement after t = 0.5 s (m)", ylim=(1e-6, 2.0),
           title=r"Wedge (A 45/005, B 55/135): $\tan\phi_c = W \sin\psi_i / (N_A + N_B)$")
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(alpha=0.3, which="both")
    save(fig, "wedge.png")


# --------------------------------------------------------------------------- tipping cube
def tipping():
    print("tipping cube")
    s = make_simulation(tcp.tipping_scene("fast"))
    b = s.blocks
    i = free_row(s)
    m = float(b.mass[i])
    theta, omega, tt = [], [], []
    for _ in range(20000):
        s.advance()
        up = rotation_matrix(b.q[i]) @ np.array([0.0, 0.0, 1.0])
        theta.append(math.atan2(up[0], up[2]))
        omega.append(b.w[i, 1])
        tt.append(s.time)
        if theta[-1] > math.radians(40.0):
            break
    theta, omega = np.array(theta), np.array(omega)
    w_ex = tcp.angular_velocity(theta, m)
    late = theta > math.radians(10.0)
    err = float(np.abs(omega[late] / w_ex[late] - 1.0).max())
    print(f"  {len(theta)} steps to 40 deg (t = {tt[-1]:.3f} s); max |omega/exact - 1| "
          f"(theta > 10 deg) {err:.3f}")
    fig, ax = plt.subplots(figsize=(8.5, 5))
    th = np.linspace(0.0, math.radians(40.0), 400)
    ax.plot(np.degrees(th), tcp.angular_velocity(th, m), "k-", lw=1,
            label=r"rigid pivot: $\omega = \sqrt{2 m g (z_c(0) - z_c(\theta)) / I_p}$")
    ax.plot(np.degrees(theta), omega, color="C0", lw=2, alpha=0.6, label="pdem (fast common plane)")
    ax.axvline(10.0, color="0.6", ls=":", lw=1)
    ax.text(10.3, 0.2, f"θ > 10°: max error {100 * err:.1f} % (test: 3 %)", fontsize=8, color="0.3")
    ax.set(xlabel=r"tilt angle $\theta$ (deg)", ylabel=r"angular velocity $\omega$ (rad/s)",
           title="Unit cube tipping over a floor edge (overhang e = 0.1 m)\n"
                 r"$z_c = \frac{a}{2}\cos\theta - e \sin\theta$, "
                 r"$I_p = m a^2/6 + m (e^2 + a^2/4)$")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    save(fig, "tipping.png")


# --------------------------------------------------------------------------- static relaxation
def static():
    print("static relaxation of a two-cube stack")
    d1, d2 = tst.overlaps()
    fig, ax = plt.subplots(figsize=(8.5, 5))
    for damping, scaling in (("local", False), ("local", True), ("combined", False),
                             ("adaptive", False)):
        s = make_simulation(tst.stack_scene(damping, scaling))
        ratio = []
        while s.step < 200000:
            s.advance()
            ratio.append(s.state.ratio)
            if s.state.ratio <= 1e-5:
                break
        z = {s.specs[g].name: s.blocks.x[i, 2] for i, g in enumerate(s.blocks.gid)}
        e1 = (0.5 - z["low"]) / d1 - 1.0
        e2 = ((1.5 - z["top"]) - (0.5 - z["low"])) / d2 - 1.0
        lab = f"{damping}{' + mass scaling' if scaling else ''}"
        print(f"  {lab}: {s.step} steps (dt {s.dt:.2e} s), ratio {s.state.ratio:.2e}, overlap errors "
              f"lower {e1:+.2e} upper {e2:+.2e}, max |v| {np.abs(s.blocks.v).max():.1e} m/s")
        ax.semilogy(np.arange(1, len(ratio) + 1), ratio, lw=1, ls="--" if scaling else "-",
                    label=f"{lab}: {s.step} steps, overlap errors {e1:+.1e} / {e2:+.1e}")
    ax.axhline(1e-5, color="C3", ls=":", lw=1, label="target ratio 1e-5")
    ax.set(xlabel="step", ylabel="unbalanced-force ratio",
           title="Two unit cubes on a floor relaxing to equilibrium:\n"
                 r"overlaps $\delta_1 = 2 m g/(k_n A)$ (lower joint), "
                 r"$\delta_2 = m g/(k_n A)$ (upper joint)")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1)
    ax.grid(alpha=0.3, which="both")
    save(fig, "static.png")


# --------------------------------------------------------------------------- arch collapse energy
def arch_energy(tr: float = 0.100, time_: float = 3.0):
    """Energy budget of an undamped arch collapse, read back from ``histories/energy`` of the
    run's output file (written by pdem.plugins.energy)."""
    import h5py
    from mpi4py import MPI

    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    print(f"arch collapse energy budget (t/R = {tr}, undamped, {time_} s)")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "arch.h5")
        # energy sampled every 50 steps (~1 ms); the picture needs no more than a few snapshots
        text = tco.arch_scene(tr, time=time_, extra=f"output: {{file: {path}, every: 0.1, "
                                                     "energy_every: 50}\n")
        s = Simulation(parse_scene(text), MPI.COMM_SELF)
        s.run()
        s.close()
        with h5py.File(path, "r") as f:
            g = f["histories/energy"]
            cols = g.attrs["columns"]
            cols = (cols.decode() if isinstance(cols, bytes) else str(cols)).split(",")
            t = g["time"][:]
            e = {c: g["value"][:, k] for k, c in enumerate(cols)}
    wg = e["gravity_work"]
    err = e["balance_error"]
    rel = np.divide(err, wg, out=np.zeros_like(err), where=wg > 1e3)
    late = wg > 0.05 * wg[-1]
    print(f"  {len(t)} samples; at t = {t[-1]:.2f} s: work of gravity {wg[-1]:.4g} J, kinetic "
          f"{e['kinetic'][-1]:.4g} J, joints: stored {e['strain'][-1]:.4g} J, dissipated "
          f"{e['joint_dissipation'][-1]:.4g} J; balance error {err[-1]:+.4g} J "
          f"({100 * err[-1] / wg[-1]:+.3f} %), largest |error| {np.abs(err).max():.4g} J, "
          f"largest |error|/W_g once W_g > 5 % of final {100 * np.abs(rel[late]).max():.3f} %")
    fig, (ax, ab) = plt.subplots(2, 1, figsize=(9, 7.5), sharex=True,
                                 gridspec_kw={"height_ratios": [2.2, 1]})
    kj = 1e-3
    ax.plot(t, wg * kj, "k", lw=2, label="work of gravity $W_g$ (potential energy released)")
    ax.plot(t, e["kinetic"] * kj, color="C0", label="kinetic $K$")
    ax.plot(t, e["strain"] * kj, color="C2", label="spring energy stored in the joints $U$")
    ax.plot(t, e["joint_dissipation"] * kj, color="C3", label="dissipated in the joints (friction slip) $D$")
    ax.plot(t, (e["kinetic"] + e["strain"] + e["joint_dissipation"]) * kj, color="C1", ls="--",
            lw=1.2, label="$K + U + D$")
    ax.set(ylabel="energy (kJ)",
           title=f"Semicircular arch R = 5 m, 24 voussoirs, t/R = {tr:.3f} (limit analysis "
                 f"{tco.ARCH_CRITICAL_TR}), no damping:\nenergy budget of the collapse "
                 "(histories/energy of the output file)")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    ab.plot(t, err, color="C4", lw=1)
    ab.axhline(0.0, color="0.5", lw=0.8)
    ab.set(xlabel="time t (s)", ylabel="balance error (J)")
    ab.grid(alpha=0.3)
    ar = ab.twinx()
    ar.plot(t[late], 100 * rel[late], color="C5", lw=1, ls=":")
    ar.set_ylabel("error / $W_g$ (%), dotted", color="C5")
    ab.set_title(f"balance error $K + U + D - K_0 - U_0 - W_g$: {err[-1]:+.3g} J at the end "
                 f"= {100 * err[-1] / wg[-1]:+.3f} % of $W_g$", fontsize=9)
    save(fig, "arch-energy.png")


# --------------------------------------------------------------------------- dip convention
def dip_convention(dip: float = 40.0, dd: float = 120.0):
    """Sketch of the orientation convention of joint sets (docs/rock-mass.md): x = east,
    y = north, z = up; dip below horizontal, dip direction clockwise from north, upward normal
    ``n = (sin(dip) sin(dd), sin(dip) cos(dd), cos(dip))`` (pdem.geometry.cutting.dip_normal).
    A drawing only: no simulation."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from pdem.geometry.cutting import dip_normal

    print(f"dip convention (dip {dip:g}, dip direction {dd:g})")
    d, a = math.radians(dip), math.radians(dd)
    n = dip_normal(dip, dd)
    h = np.array([math.sin(a), math.cos(a), 0.0])  # dip direction, horizontal
    s = math.cos(d) * h - math.sin(d) * np.array([0.0, 0.0, 1.0])  # down-dip (steepest descent)
    t = np.cross(s, n)  # strike, horizontal
    assert abs(t[2]) < 1e-12 and abs(n @ s) < 1e-12
    print(f"  n = ({n[0]:.3f}, {n[1]:.3f}, {n[2]:.3f})")

    fig = plt.figure(figsize=(15, 7.2))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax.set_proj_type("ortho")
    ax.view_init(elev=32, azim=-62)
    ax.computed_zorder = False  # draw in the order added: lines and labels over the planes
    box = {"facecolor": "white", "alpha": 0.75, "edgecolor": "none", "pad": 1.5}
    # horizontal reference plane z = 0 and the dipping plane through the origin
    r = 2.0
    ax.add_collection3d(Poly3DCollection([[(-r, -r, 0), (r, -r, 0), (r, r, 0), (-r, r, 0)]],
                                         facecolor="0.85", edgecolor="0.6", alpha=0.35))
    a_, b_ = 1.5, 1.15
    corners = [a_ * t + b_ * s, -a_ * t + b_ * s, -a_ * t - b_ * s, a_ * t - b_ * s]
    ax.add_collection3d(Poly3DCollection([corners], facecolor="#c98b4b", edgecolor="#7a4a1c",
                                         alpha=0.35, lw=1.5))
    # strike line (horizontal line of the plane) and the down-dip line
    ax.plot(*np.array([-a_ * t, a_ * t]).T, color="#7a4a1c", ls="--", lw=1.2)
    ax.text(*(a_ * t * 1.08 + [0, 0, 0.08]), "strike\n(horizontal)", color="#7a4a1c", fontsize=9,
            bbox=box)
    ax.quiver(0, 0, 0, *(b_ * s), color="C3", lw=2.2, arrow_length_ratio=0.15)
    ax.text(*(b_ * s * 1.1 + [0, 0, -0.15]), "down-dip line", color="C3", fontsize=10, bbox=box)
    # horizontal projection of the down-dip line = dip direction, and north
    ax.plot(*np.array([0 * h, 1.9 * h]).T, color="C0", lw=1.6)
    ax.quiver(0, 0, 0, 0, 1.9, 0, color="C2", lw=1.6, arrow_length_ratio=0.08)
    ax.text(0.0, 2.0, -0.05, "north (+y)", color="C2", fontsize=10, va="top", bbox=box)
    # dip angle: arc from the dip direction (horizontal) down to the down-dip line
    th = np.linspace(0.0, d, 30)
    arc = 0.75 * (np.cos(th)[:, None] * h - np.sin(th)[:, None] * np.array([0, 0, 1.0]))
    ax.plot(*arc.T, color="C3", lw=2)
    m = 0.85 * (math.cos(d / 2) * h - math.sin(d / 2) * np.array([0, 0, 1.0]))
    ax.text(*(m + [0.05, 0.0, -0.12]), f"dip = {dip:g}°\n(below horizontal)", color="C3",
            fontsize=10, bbox=box)
    # dip direction: horizontal arc from north clockwise (seen from above) to the dip direction
    th = np.linspace(0.0, a, 60)
    arc = 1.2 * np.column_stack([np.sin(th), np.cos(th), np.zeros_like(th)])
    ax.plot(*arc.T, color="C0", lw=2)
    ax.quiver(*arc[-4], *(arc[-1] - arc[-4]), color="C0", lw=2, arrow_length_ratio=1.0)
    mid = 1.3 * np.array([math.sin(a / 2), math.cos(a / 2), 0.0])
    ax.text(*(mid + [0.1, 0.0, 0.0]), f"dip direction = {dd:g}°\n(clockwise from north)",
            color="C0", fontsize=10, bbox=box)
    # upward normal
    ax.quiver(0, 0, 0, *(1.4 * n), color="k", lw=2.2, arrow_length_ratio=0.12)
    ax.text(*(1.45 * n + [0, 0, 0.08]), "upward normal n", color="k", fontsize=10, ha="right",
            bbox=box)
    # coordinate triad in a corner
    o = np.array([-2.0, -2.0, 0.0])
    for v, lab, col in (((1, 0, 0), "x = east", "C1"), ((0, 1, 0), "y = north", "C2"),
                        ((0, 0, 1), "z = up", "C4")):
        v = np.array(v, dtype=float)
        ax.quiver(*o, *(0.9 * v), color=col, lw=2, arrow_length_ratio=0.18)
        ax.text(*(o + 1.02 * v), lab, color=col, fontsize=10, fontweight="bold")
    ax.set(xlim=(-2, 2), ylim=(-2, 2), zlim=(-1.6, 1.6), xlabel="x (east)", ylabel="y (north)",
           zlabel="z (up)")
    ax.set_box_aspect((1, 1, 0.8))
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.pane.fill = False
        axis.set_ticklabels([])  # a sketch: the scale means nothing
    ax.set_title(f"A joint plane: dip {dip:g}°, dip direction {dd:g}°", fontsize=12)

    # plan view (map): dip direction as a compass bearing, the strike/dip map symbol
    ap = fig.add_subplot(1, 2, 2)
    ap.set_aspect("equal")
    ap.add_patch(plt.Circle((0, 0), 1.0, fill=False, color="0.6", lw=1))
    for k, lab in enumerate(("N\n0°", "E 90°", "S\n180°", "270° W")):
        az = math.radians(90.0 * k)
        x, y = 1.17 * math.sin(az), 1.17 * math.cos(az)
        ap.text(x, y, lab, ha="center", va="center", fontsize=11, color="C2" if k == 0 else "0.3")
    ap.annotate("", xy=(0, 1.0), xytext=(0, 0), arrowprops={"arrowstyle": "-|>", "color": "C2", "lw": 1.6})
    ap.annotate("", xy=(0.95 * h[0], 0.95 * h[1]), xytext=(0, 0),
                arrowprops={"arrowstyle": "-|>", "color": "C0", "lw": 2.2})
    th = np.linspace(0.0, a, 60)
    ap.plot(0.45 * np.sin(th), 0.45 * np.cos(th), color="C0", lw=2)
    ap.annotate("", xy=(0.45 * math.sin(a), 0.45 * math.cos(a)),
                xytext=(0.45 * math.sin(a - 0.08), 0.45 * math.cos(a - 0.08)),
                arrowprops={"arrowstyle": "-|>", "color": "C0", "lw": 2})
    ap.text(0.55 * math.sin(a / 2), 0.55 * math.cos(a / 2), f"{dd:g}°", color="C0", fontsize=12)
    # strike line: where the plane cuts a horizontal plane, at right angles to the dip direction
    ap.plot([-0.9 * t[0], 0.9 * t[0]], [-0.9 * t[1], 0.9 * t[1]], color="#7a4a1c", lw=3)
    ap.text(0.97 * h[0] + 0.03, 0.97 * h[1] - 0.1, f"dip direction\n(dip {dip:g}°)", color="C0", fontsize=10)
    ap.text(-0.9 * t[0] - 0.02, -0.9 * t[1] + 0.05, "strike", color="#7a4a1c", fontsize=10, ha="right")
    ap.text(0.0, -1.5, "map view, looking down (x east, y north): the dip direction is the compass\n"
            "bearing of the down-dip line, measured clockwise from north",
            ha="center", fontsize=10)
    ap.text(0.0, -1.9, "upward normal  n = (sin dip · sin dd,  sin dip · cos dd,  cos dip)\n"
            f"here n = ({n[0]:.3f}, {n[1]:.3f}, {n[2]:.3f});  "
            "the plane is n · x = n · origin  (pdem.geometry.cutting.dip_normal)",
            ha="center", fontsize=10, family="monospace")
    ap.set(xlim=(-1.45, 1.45), ylim=(-2.1, 1.4))
    ap.axis("off")
    ap.set_title("The same plane on a map", fontsize=12)
    save(fig, "dip-convention.png")


# --------------------------------------------------------------------------- base motion
def base_motion():
    print("rigid blocks under base motion (docs/dynamics.md)")
    fig, (ax, ar) = plt.subplots(1, 2, figsize=(14, 5.5))
    a_y = tsh.yield_acceleration()
    for ratio, col in ((1.5, "C0"), (3.0, "C1")):
        a = ratio * a_y
        end = tsh.slip_time(a, 0.1, a_y) + 0.05
        s = make_simulation(tsh.sliding_scene(a, 0.1, end))
        b = s.blocks
        x0 = b.x[:, 0].copy()
        n = int(round(end / s.dt))
        t, d = np.empty(n), np.empty(n)
        for k in range(n):
            s.advance()
            t[k] = s.time
            d[k] = (b.x[0, 0] - x0[0]) - (b.x[1, 0] - x0[1])
        d_n = tsh.newmark_displacement(a, 0.1, a_y)
        d_e = tsh.newmark_elastic_displacement(a, 0.1, a_y)
        fin = float(d[t >= end - 0.03].mean())
        print(f"  A = {ratio} a_y: slip {fin:.6f} m, Newmark {d_n:.6f} ({fin / d_n - 1:+.2e}), "
              f"with elastic start {d_e:.6f} ({fin / d_e - 1:+.2e})")
        ax.plot(t, 100 * d, color=col, lw=2.5, alpha=0.5,
                label=f"pdem, A = {ratio} $a_y$: {100 * fin:.3f} cm")
        ax.plot(t, 100 * tsh.newmark_slip(t, a, 0.1, a_y), "k--", lw=1,
                label=f"Newmark rigid-plastic: {100 * d_n:.3f} cm ({100 * (fin / d_n - 1):+.1f} %)")
    ax.axvline(0.1, color="0.6", ls=":", lw=1)
    ax.set(xlabel="time (s)", ylabel="slip of the slab relative to the base (cm)",
           title="Newmark's sliding block: pulse A for T = 0.1 s, $a_y = g\\tan 30°$\n"
                 r"$d = \frac{(AT)^2}{2a_y}\left(1 - \frac{a_y}{A}\right)$"
                 "; pdem's excess: the shear spring's elastic start")
    ax.title.set_fontsize(10)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)

    alpha, _, p = tsh.rocking_constants()
    theta0 = 0.5 * alpha
    s = make_simulation(tsh.tilted_scene(theta0, 0.7))
    b = s.blocks
    r0 = rotation_matrix(b.q[1])
    n = int(round(0.7 / s.dt))
    t, beta = np.empty(n), np.empty(n)
    for k in range(n):
        s.advance()
        t[k] = s.time
        beta[k] = theta0 + tsh.tilt_about_y(b.q[1], r0)
    # the rigid pivot, theta'' = -p^2 sin(alpha - theta), to theta = 0 (RK4)
    h, th, om, tr, thr = 1e-4, theta0, 0.0, [0.0], [theta0]
    f = lambda x: -p * p * math.sin(alpha - x)  # noqa: E731
    while th > 0.0:
        k1t, k1o = om, f(th)
        k2t, k2o = om + h / 2 * k1o, f(th + h / 2 * k1t)
        k3t, k3o = om + h / 2 * k2o, f(th + h / 2 * k2t)
        k4t, k4o = om + h * k3o, f(th + h * k3t)
        th += h / 6 * (k1t + 2 * k2t + 2 * k3t + k4t)
        om += h / 6 * (k1o + 2 * k2o + 2 * k3o + k4o)
        tr.append(tr[-1] + h)
        thr.append(th)
    t_p, _ = tsh.pivot_impact_time(theta0)
    t_h = tsh.housner_impact_time(theta0)
    k = int(np.nonzero(beta <= 0.0)[0][0])
    tc = t[k - 1] + (t[k] - t[k - 1]) * beta[k - 1] / (beta[k - 1] - beta[k])
    print(f"  free rocking from alpha/2: impact {tc:.5f} s, rigid pivot {t_p:.5f} "
          f"({tc / t_p - 1:+.2e}), Housner {t_h:.5f} ({tc / t_h - 1:+.2e})")
    ar.plot(t, np.degrees(beta), color="C0", lw=2.5, alpha=0.5, label="pdem")
    ar.plot(tr, np.degrees(thr), "k--", lw=1, label="rigid pivot (exact equation)")
    ar.axvline(t_h, color="C3", ls=":", lw=1,
               label=f"Housner $t = p^{{-1}}\\,\\mathrm{{arccosh}}(1/(1-\\theta_0/\\alpha))$ = {t_h:.4f} s")
    ar.axhline(0.0, color="0.6", lw=0.8)
    ar.set(xlabel="time (s)", ylabel=r"tilt $\theta$ (deg)",
           title=f"Housner's rocking block (b/h = 0.2, α = {math.degrees(alpha):.1f}°) "
                 f"released at θ₀ = α/2\nfirst impact {tc:.4f} s, rigid pivot {t_p:.4f} s "
                 f"({100 * (tc / t_p - 1):+.2f} %); the elastic impact rocks on")
    ar.title.set_fontsize(10)
    ar.legend(fontsize=8, loc="lower left")
    ar.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, "base-motion.png")


# --------------------------------------------------------------------------- waves
def _column_energy(base: str, duration: float = 0.04):
    """The S pulse in the 20 m column (test_dynamics_waves): times and the column's
    energy over the pulse's ``rho C A int v^2 dt``."""
    from pdem.plugins.energy import energy_totals

    sim = make_simulation(twv.column_scene("S", 20.0, 0.5, base=base, duration=duration))
    s = sim.state
    pulse = twv.pulse_energy(0.1, duration, twv.RHO * twv.CS)
    ts, es = [], []
    while s.time < duration + 2.0 * 20.0 / twv.CS + 0.02:
        sim.stepper.advance()
        if s.step % 5 == 0:
            t = energy_totals(s)
            ts.append(s.time)
            es.append((t["kinetic"] + t["zone_strain"]) / pulse)
    return np.array(ts), np.array(es)


def _transmitted(wave: str, frequency: float, ratio: float) -> float:
    c = twv.WAVES[wave][2]
    k = "xyz".index(twv.WAVES[wave][0])
    omega, z = 2.0 * math.pi * frequency, twv.RHO * c
    sim = make_simulation(twv.joint_bars_scene(wave, frequency, omega * z / (2.0 * ratio)))
    s = sim.state
    d = s.grids.names.index("upper")
    body = s.grids.bodies[d]
    zs = body.nodes0[:, 2]
    probe = np.nonzero(np.abs(zs - zs[np.argmin(np.abs(zs - 15.0))]) < 1e-9)[0]
    end = 15.0 / c + 5.0 / frequency
    ts, vs = [], []
    while s.time < end:
        sim.stepper.advance()
        ts.append(s.time)
        vs.append(float(body.vel[probe, k].mean()))
    v = np.array(vs)[np.array(ts) > end - 2.0 / frequency]
    return 0.5 * (v.max() - v.min()) / 0.01


def _decay(centre_over_f1: float):
    height, fraction = 10.0, 0.05
    f1 = twv.CS / (4.0 * height)
    text = twv.decay_scene(height, fraction, centre_over_f1 * f1)
    sim = make_simulation(text)
    s = sim.state
    body = s.grids.bodies[0]
    shape = np.sin(math.pi * body.nodes0[:, 2] / (2.0 * height))
    m = body.gravity_mass
    ts, qs = [], []
    while s.time < 4.0 / f1:
        sim.stepper.advance()
        ts.append(s.time)
        qs.append(float(np.sum(m * shape * (body.nodes[:, 0] - body.nodes0[:, 0]))
                        / np.sum(m * shape * shape)))
    omega = 2.0 * math.pi * f1
    return np.array(ts), np.array(qs), twv.rayleigh_fraction(omega, fraction,
                                                             centre_over_f1 * f1), omega


def waves():
    """docs/dynamics.md, Verification: waves in zoned blocks."""
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.4))
    fig.subplots_adjust(wspace=0.3)
    for base, style in (("quiet", "-"), ("held", "--")):
        t, e = _column_energy(base)
        ax[0].plot(t, e, style, label=f"{base} base")
        print(f"  column, {base} base: held {e.max():.5f}, left {e[-1]:.3g} of the pulse")
    ax[0].set(xlabel="t (s)", ylabel="energy in the column / ρ C A ∫v² dt",
              title="S pulse: in through a quiet base, up, back, out")
    ax[0].legend()
    r = np.linspace(0.0, 4.0, 200)
    ax[1].plot(r, 1.0 / np.sqrt(1.0 + r * r), "k-", label="Pyrak-Nolte 1/√(1+(ωZ/2κ)²)")
    for wave, frequency, ratio, mark in (("P", 20.0, 0.5, "o"), ("P", 20.0, 1.0, "o"),
                                         ("P", 40.0, 2.0, "o"), ("P", 40.0, 4.0, "o"),
                                         ("S", 20.0, 1.0, "s"), ("S", 40.0, 2.0, "s")):
        got = _transmitted(wave, frequency, ratio)
        print(f"  {wave} {frequency:g} Hz, ωZ/2κ = {ratio:g}: |T| {got:.4f} "
              f"(closed form {1 / math.sqrt(1 + ratio * ratio):.4f})")
        ax[1].plot(ratio, got, mark, color="C0" if wave == "P" else "C1",
                   label=f"{wave} wave" if ratio in (0.5, 1.0) and
                   (wave == "P") == (ratio == 0.5) else None)
    ax[1].set(xlabel="ωZ / 2κ", ylabel="|T|", title="a joint in the path: transmission")
    ax[1].legend()
    for centre, color in ((1.0, "C0"), (3.0, "C2")):
        t, q, xi, omega = _decay(centre)
        ax[2].plot(t, q / np.abs(q).max(), color=color, lw=0.8,
                   label=f"centre {centre:g} f₁: ξ(f₁) = {xi:.4f}")
        k = int(np.argmax(np.abs(q)))  # the first peak: the envelope through it
        ax[2].plot(t, np.exp(-xi * omega * (t - t[k])), ":", color=color)
    ax[2].set(xlabel="t (s)", ylabel="fundamental mode (normalised)",
              title="Rayleigh damping: free decay, envelope exp(−ξωt)")
    ax[2].legend()
    save(fig, "waves.png")


def seismic_slope(path: str = "seismic-slope.h5"):
    """docs/dynamics.md: the stations of configs/seismic-slope.yaml's output (run it first,
    from the repository root: it writes seismic-slope.h5 there; or set PDEM_SEISMIC_SLOPE to
    its path)."""
    import h5py

    path = os.environ.get("PDEM_SEISMIC_SLOPE", path)
    with h5py.File(path, "r") as f:
        h = f["histories"]
        t0 = float(h["point-0.displacement/time"][0])
        ts = {k: h[f"{k}/time"][()] - t0 for k in ("point-0.displacement",
                                                    "point-1.acceleration",
                                                    "point-2.velocity")}
        d = h["point-0.displacement/value"][()]
        a = h["point-1.acceleration/value"][()]
        v = h["point-2.velocity/value"][()]
    dip = math.radians(35.0)
    along = d[:, 0] * math.cos(dip) - d[:, 2] * math.sin(dip)  # down the joint, east and down
    fig, ax = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True)
    ax[0].plot(ts["point-2.velocity"], v[:, 0], lw=0.8)
    ax[0].set(ylabel="m/s", title="foundation base, x velocity (point-2)")
    ax[1].plot(ts["point-1.acceleration"], a[:, 0] / G, lw=0.6)
    ax[1].set(ylabel="g", title="sliding block, x acceleration (point-1)")
    ax[2].plot(ts["point-0.displacement"], 1e3 * along)
    ax[2].set(xlabel="t since the earthquake stage began (s)", ylabel="mm",
              title="sliding block, displacement down the joint (point-0)")
    print(f"  sliding block: {1e3 * along[-1]:.1f} mm down the joint at the end")
    save(fig, "seismic-slope.png")


CASES = {"incline": incline, "oscillator": oscillator, "bounce": bounce, "tumbling": tumbling,
         "wedge": wedge, "tipping": tipping, "static": static, "arch-energy": arch_energy,
         "dip-convention": dip_convention, "base-motion": base_motion, "waves": waves,
         "seismic-slope": seismic_slope}


def main(argv):
    names = argv or list(CASES)
    t_all = time.perf_counter()
    for name in names:
        t0 = time.perf_counter()
        CASES[name]()
        print(f"  ({time.perf_counter() - t0:.1f} s)")
    print(f"total {time.perf_counter() - t_all:.1f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
