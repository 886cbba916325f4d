"""Damping modes by name (``solve.damping.mode``), each a kernel chosen at compile time.

A mode is a namedtuple type carrying its constants; :func:`damped_momentum` is resolved per
type when :func:`pdem.dynamics.motion.integrate` compiles, so an undamped scene carries no
damping code. Equations: local (78-79), combined (83), viscous (49) and adaptive (77); see
:mod:`pdem.dynamics.motion` for the time levels.
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass

from numba.extending import overload

from ..jit import inline_kernel
from ..registry import Registry

NoDamping = namedtuple("NoDamping", "alpha")
LocalDamping = namedtuple("LocalDamping", "alpha")
CombinedDamping = namedtuple("CombinedDamping", "alpha")
ViscousDamping = namedtuple("ViscousDamping", "alpha")


@dataclass(frozen=True)
class DampingMode:
    """``kernel_args(alpha)`` -> the kernel's constants; ``default_alpha`` when the scene gives
    none (``None``: the scene must give it); ``adaptive``: alpha is servo-controlled."""

    kernel_args: type
    default_alpha: float | None
    adaptive: bool = False


DAMPING: Registry[DampingMode] = Registry("damping mode")
DAMPING.register("none", DampingMode(NoDamping, 0.0))
DAMPING.register("local", DampingMode(LocalDamping, 0.8))
DAMPING.register("combined", DampingMode(CombinedDamping, 0.8))
DAMPING.register("viscous", DampingMode(ViscousDamping, None))
DAMPING.register("adaptive", DampingMode(ViscousDamping, 0.0, adaptive=True))
# dynamic analysis: its mass-proportional part is the viscous form with alpha = fraction
# omega (pdem.config.schema.Damping.rayleigh); the stiffness-proportional part acts in the
# zones (pdem.deformable.motion) and as dashpots on the joints (pdem.contact.forces.dashpot)
DAMPING.register("rayleigh", DampingMode(ViscousDamping, None))


@inline_kernel
def sign_of(a):
    """-1, 0 or 1 (the damping modes' sgn; the zoned grids' combined damping too)."""
    if a > 0.0:
        return 1.0
    if a < 0.0:
        return -1.0
    return 0.0


def damped_momentum(d, mi, dt, v0, l0, w0, ft, m, pf, pm):
    """New (v, L) at t + dt/2 and the damping force and moment applied; compiled per mode.

    ``v0, l0, w0``: velocity, angular momentum and angular velocity at t - dt/2; ``ft, m``:
    total force (with gravity) and moment at t; ``pf, pm``: last step's (combined damping);
    ``mi``: inertial mass. Returns ``(v, L, fd, md)`` as 3-tuples.
    """
    raise NotImplementedError("damped_momentum is only callable from numba kernels")


@inline_kernel
def _sgn3(a):
    return sign_of(a[0]), sign_of(a[1]), sign_of(a[2])


@inline_kernel
def _applied(mi, dt, v0, l0, ft, m, fd, md):
    """Momentum update with the damping force and moment subtracted (eq. 78)."""
    c = dt / mi
    v = (v0[0] + (ft[0] - fd[0]) * c, v0[1] + (ft[1] - fd[1]) * c, v0[2] + (ft[2] - fd[2]) * c)
    lm = (l0[0] + (m[0] - md[0]) * dt, l0[1] + (m[1] - md[1]) * dt, l0[2] + (m[2] - md[2]) * dt)
    return v, lm, fd, md


@inline_kernel
def _against(a, f, s):
    """alpha |f| s per component."""
    return a * abs(f[0]) * s[0], a * abs(f[1]) * s[1], a * abs(f[2]) * s[2]


@inline_kernel
def _free(d, mi, dt, v0, l0, w0, ft, m, pf, pm):
    c = dt / mi
    v = (v0[0] + ft[0] * c, v0[1] + ft[1] * c, v0[2] + ft[2] * c)
    lm = (l0[0] + m[0] * dt, l0[1] + m[1] * dt, l0[2] + m[2] * dt)
    zero = (0.0, 0.0, 0.0)
    return v, lm, zero, zero


@inline_kernel
def _local(d, mi, dt, v0, l0, w0, ft, m, pf, pm):
    # eqs. 78-79: F_d = alpha |F| sgn(v(t - dt/2)) per component; the moment with sgn(w)
    return _applied(mi, dt, v0, l0, ft, m, _against(d.alpha, ft, _sgn3(v0)),
                    _against(d.alpha, m, _sgn3(w0)))


@inline_kernel
def _combined(d, mi, dt, v0, l0, w0, ft, m, pf, pm):
    # eq. 83 in the sign of (78): F_d = alpha |F| (sgn(v) - sgn(dF/dt)) / 2
    sv = _sgn3(v0)
    sw = _sgn3(w0)
    sf = (0.5 * (sv[0] - sign_of(ft[0] - pf[0])), 0.5 * (sv[1] - sign_of(ft[1] - pf[1])),
          0.5 * (sv[2] - sign_of(ft[2] - pf[2])))
    sm = (0.5 * (sw[0] - sign_of(m[0] - pm[0])), 0.5 * (sw[1] - sign_of(m[1] - pm[1])),
          0.5 * (sw[2] - sign_of(m[2] - pm[2])))
    return _applied(mi, dt, v0, l0, ft, m, _against(d.alpha, ft, sf), _against(d.alpha, m, sm))


@inline_kernel
def _viscous(d, mi, dt, v0, l0, w0, ft, m, pf, pm):
    # eq. 49: v+ = (D1 v- + a dt) D2; the same on L
    alpha = d.alpha
    d1 = 1.0 - 0.5 * alpha * dt
    d2 = 1.0 / (1.0 + 0.5 * alpha * dt)
    c = dt / mi
    v = ((d1 * v0[0] + ft[0] * c) * d2, (d1 * v0[1] + ft[1] * c) * d2,
         (d1 * v0[2] + ft[2] * c) * d2)
    lm = ((d1 * l0[0] + m[0] * dt) * d2, (d1 * l0[1] + m[1] * dt) * d2,
          (d1 * l0[2] + m[2] * dt) * d2)
    # damping force/moment actually applied: alpha * m * v(t), v(t) from eq. 47
    fd = (alpha * mi * 0.5 * (v0[0] + v[0]), alpha * mi * 0.5 * (v0[1] + v[1]),
          alpha * mi * 0.5 * (v0[2] + v[2]))
    md = (alpha * 0.5 * (l0[0] + lm[0]), alpha * 0.5 * (l0[1] + lm[1]),
          alpha * 0.5 * (l0[2] + lm[2]))
    return v, lm, fd, md


_KERNELS = {NoDamping: _free, LocalDamping: _local, CombinedDamping: _combined,
            ViscousDamping: _viscous}


@overload(damped_momentum, inline="always")
def _damped_momentum(d, mi, dt, v0, l0, w0, ft, m, pf, pm):
    k = _KERNELS[d.instance_class]

    def impl(d, mi, dt, v0, l0, w0, ft, m, pf, pm):
        return k(d, mi, dt, v0, l0, w0, ft, m, pf, pm)
    return impl
