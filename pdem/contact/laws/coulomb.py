"""The Coulomb-slip joint of 3DEC (eqs. 34-43): elastic, tension and cohesion until the
first failure, frictional slip with dilation."""

from __future__ import annotations

import math
from collections import namedtuple
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, NonNegativeFloat, PositiveFloat

from ...jit import inline_kernel
from .base import FAILED, OPEN, SLIPPING, JointLaw, JointParams, Strength


class Params(JointParams):
    """Joint (contact) properties in 3DEC units: stiffness in Pa/m, strengths in Pa, angles in
    degrees. ``dilation_limit`` is the shear displacement beyond which dilation stops (eq. 43
    text); null means no limit."""

    model: Literal["coulomb"] = "coulomb"
    friction: Annotated[float, Field(ge=0.0, lt=90.0)] = 30.0
    dilation: Annotated[float, Field(ge=0.0, lt=90.0)] = 0.0
    cohesion: NonNegativeFloat = 0.0
    tension: NonNegativeFloat = 0.0
    dilation_limit: PositiveFloat | None = None


Table = namedtuple("Table", "kn ks tan_phi tan_psi cohesion tension us_lim")


def table(joints: list[Params]) -> Table:
    """Per-joint arrays; angles become tangents here, once, so kernels never see degrees."""
    return Table(
        np.array([x.kn for x in joints], float),
        np.array([x.ks for x in joints], float),
        np.array([math.tan(math.radians(x.friction)) for x in joints], float),
        np.array([math.tan(math.radians(x.dilation)) for x in joints], float),
        np.array([x.cohesion for x in joints], float),
        np.array([x.tension for x in joints], float),
        np.array([x.dilation_limit or np.inf for x in joints], float),
    )


@inline_kernel
def below_limit(fx, fy, fz, fs_max):
    """Whether ``sqrt(fx² + fy² + fz²) > fs_max`` is surely false, decided on the squares: a
    sticking sub-contact (most of them, at rest) skips the square root. Where the squares are
    within 4e-15 of each other, or outside the normal range, this says no and the caller
    compares the rounded root as before: the decision, and so every bit, is the root's (the
    square's rounding is 2^-53 relative, the root's half that)."""
    m2 = fx * fx + fy * fy + fz * fz
    tt = fs_max * fs_max
    return tt > 1e-290 and m2 < tt * (1.0 - 4e-15)


@inline_kernel
def update(p, j, s, hist, un, dil, fx, fy, fz, dx, dy, dz, area, ux, uy, uz, state):
    """Update one sub-contact's normal and shear force (eqs. 24-27, 34-43).

    Scalars only, so the force loop keeps everything in registers.

    Parameters
    ----------
    p, j : the law's table (:data:`Table`) and this contact's joint row.
    s, hist : sub-contact index and the history columns (unused: Coulomb keeps none).
    un : overlap of the surfaces (+ closing); normal force is ``kn * area * (un + dil)``, the
        total form of eqs. 24, 26, 43.
    dil : accumulated dilation (eq. 42).
    fx, fy, fz : shear force on block B carried from the last step, turned into the plane.
    dx, dy, dz : this step's shear displacement increment (eq. 22), for dilation (eq. 41).
    ux, uy, uz : total shear displacement after this step, for the dilation limit.
    state : state bits (SLIPPING, FAILED, OPEN).

    Returns
    -------
    (fn, dil, state, fx, fy, fz)
    """
    kn = p.kn[j]
    tan_phi = p.tan_phi[j]
    tan_psi = p.tan_psi[j]
    tension = p.tension[j]
    cohesion = p.cohesion[j]
    us_lim = p.us_lim[j]
    kss = p.ks[j] * area
    fx = fx - kss * dx  # eqs. 25, 27: elastic trial
    fy = fy - kss * dy
    fz = fz - kss * dz
    state = state & FAILED
    fn = kn * area * (un + dil)
    t_max = 0.0 if state & FAILED else tension * area  # eq. 34, 36
    c_area = 0.0 if state & FAILED else cohesion * area
    if fn < -t_max:  # eq. 38: tensile failure
        if t_max > 0.0 or c_area > 0.0:
            state |= FAILED
        return 0.0, dil, state | OPEN, 0.0, 0.0, 0.0
    fs_max = c_area + max(fn, 0.0) * tan_phi  # eq. 35, 37
    fs_mag = fs_max if below_limit(fx, fy, fz, fs_max) else math.sqrt(fx * fx + fy * fy + fz * fz)
    if fs_mag > fs_max:  # eq. 39
        scale = fs_max / fs_mag
        fx *= scale
        fy *= scale
        fz *= scale
        state |= SLIPPING
        if t_max > 0.0 or c_area > 0.0:
            state |= FAILED
        if tan_psi > 0.0:
            # Dilation only while slipping (eq. 41-42), growing when the increment follows the
            # accumulated shear and shrinking when it reverses; none past the limit.
            dus_mag = math.sqrt(dx * dx + dy * dy + dz * dz)
            us_mag = math.sqrt(ux * ux + uy * uy + uz * uz)
            if us_mag < us_lim:
                sign = 1.0 if dx * ux + dy * uy + dz * uz >= 0.0 else -1.0
                dil = max(dil + sign * dus_mag * tan_psi, 0.0)
                fn = kn * area * (un + dil)  # eq. 43
    if fn <= 0.0:
        state |= OPEN
        fn = min(fn, 0.0)
    return fn, dil, state, fx, fy, fz


@inline_kernel
def stays_open(p, j, s, hist, un, dil, area, state):
    """Whether :func:`update` takes its tensile branch (eq. 38) and returns ``state`` as it
    was: the same tests on the same numbers, without the shear force (that branch drops it)."""
    kept = state & FAILED
    t_max = 0.0 if kept & FAILED else p.tension[j] * area
    c_area = 0.0 if kept & FAILED else p.cohesion[j] * area
    if not p.kn[j] * area * (un + dil) < -t_max:
        return False
    if t_max > 0.0 or c_area > 0.0:
        kept |= FAILED
    return kept | OPEN == state


@inline_kernel
def energy(p, j, s, hist, un, dil, fx, fy, fz, area, state):
    """Normal force and stored spring energy of a sub-contact in the given state: the normal
    spring ``kn A (un + dil)`` in compression, or in tension while the bond holds, and the
    shear spring ``|fs|^2 / (2 ks A)``."""
    # tension only while bonded
    bonded = ((state & FAILED) == 0) & (p.tension[j] > 0.0)
    return _springs(p.kn[j], p.ks[j], un, dil, fx, fy, fz, area, -1e308 * bonded)


@inline_kernel
def _springs(kn, ks, un, dil, fx, fy, fz, area, fn_min):
    """(normal force, stored energy) of the joint's two springs, the normal force at least
    ``fn_min`` (a bond's tension, or -0 without one). A sub-contact without positive area (a
    corner share can round to -1e-18 m2) stores nothing; written without branches (this kernel
    is inlined): the weights are 0 or 1."""
    has_area = area > 0.0
    a = max(area, 1e-300)
    kna = kn * a
    fn = max(kna * (un + dil), fn_min) * has_area
    return fn, (0.5 * fn * fn / kna + 0.5 * (fx * fx + fy * fy + fz * fz) * has_area
                / (ks * a))


@inline_kernel
def _linear_dissipation(kn, ks, dun, dsx, dsy, dsz, area, fn0, fn1, fn, gx, gy, gz, fx, fy,
                        fz):
    """What a step of the joint's two linear springs dissipated: the work over the step
    (trapezoid, the law's normal force going from ``fn0`` to ``fn``, the shear force from
    ``g`` to ``f``) less the change of the stored energy ``fn²/(2 kn A) + |f|²/(2 ks A)``
    (:func:`_springs`, whose normal forces are ``fn0`` and ``fn1``). Written as
    ``-(fn0 + fn1)/2 (dun + (fn1 - fn0)/(kn A))``, its shear match and ``-(fn - fn1) dun/2``
    (zero unless the step broke a bond in tension): the same sum regrouped (``fn1² - fn0² =
    (fn1 + fn0)(fn1 - fn0)``), with two divisions instead of four and without the
    cancellation of two large terms, so an elastic step books its springs' rounding and a slip
    the part of the increment that slipped. A sub-contact without positive area stores
    nothing."""
    if not area > 0.0:  # nothing stored: the springs' normal force is 0 before
        return -0.5 * (fn * dun + (gx + fx) * dsx + (gy + fy) * dsy + (gz + fz) * dsz)
    kna = kn * area
    ksa = ks * area
    if fn != fn1:
        work_n = -0.5 * ((fn0 + fn1) * (dun + (fn1 - fn0) / kna) + (fn - fn1) * dun)
    else:
        work_n = -0.5 * (fn0 + fn) * (dun + (fn - fn0) / kna)
    return work_n - 0.5 * ((gx + fx) * (dsx + (fx - gx) / ksa)
                           + (gy + fy) * (dsy + (fy - gy) / ksa)
                           + (gz + fz) * (dsz + (fz - gz) / ksa))


@inline_kernel
def dissipation(p, j, s, hist, dun, dsx, dsy, dsz, area, un0, dil0, gx, gy, gz, st0, un, dil,
                fn, fx, fy, fz, st):
    """The energy one step of the joint dissipated (pdem.contact.laws.joint_dissipation), the
    springs' normal forces before and after as :func:`energy` has them (tension only while
    bonded)."""
    kna = p.kn[j] * area
    bonded0 = ((st0 & FAILED) == 0) & (p.tension[j] > 0.0)
    bonded1 = ((st & FAILED) == 0) & (p.tension[j] > 0.0)
    fn0 = max(kna * (un0 + dil0), -1e308 * bonded0)
    fn1 = max(kna * (un + dil), -1e308 * bonded1)
    return _linear_dissipation(p.kn[j], p.ks[j], dun, dsx, dsy, dsz, area, fn0, fn1, fn, gx, gy,
                               gz, fx, fy, fz)


# Frictional joints (no cohesion, tension or dilation: the common case) compile a law without
# those branches. Bitwise the same as ``update``/``energy`` with zero strengths and dilation:
# every term they drop is an exact zero there (0 + x, x * 0 with x finite).
FrictionTable = namedtuple("FrictionTable", "kn ks tan_phi")


def friction_table(joints: list[Params]) -> FrictionTable:
    t = table(joints)
    return FrictionTable(t.kn, t.ks, t.tan_phi)


def is_frictional(p: Params) -> bool:
    return p.cohesion == 0.0 and p.tension == 0.0 and p.dilation == 0.0


@inline_kernel
def friction_update(p, j, s, hist, un, dil, fx, fy, fz, dx, dy, dz, area, ux, uy, uz, state):
    """:func:`update` for a joint without cohesion, tension or dilation (``dil`` stays 0)."""
    kss = p.ks[j] * area
    fx = fx - kss * dx
    fy = fy - kss * dy
    fz = fz - kss * dz
    state = state & FAILED
    fn = p.kn[j] * area * (un + dil)
    if fn < -0.0:
        return 0.0, dil, state | OPEN, 0.0, 0.0, 0.0
    fs_max = 0.0 + max(fn, 0.0) * p.tan_phi[j]  # as update's c_area + ..., to the zero's sign
    fs_mag = fs_max if below_limit(fx, fy, fz, fs_max) else math.sqrt(fx * fx + fy * fy + fz * fz)
    if fs_mag > fs_max:
        scale = fs_max / fs_mag
        fx *= scale
        fy *= scale
        fz *= scale
        state |= SLIPPING
    if fn <= 0.0:
        state |= OPEN
        fn = min(fn, 0.0)
    return fn, dil, state, fx, fy, fz


@inline_kernel
def friction_stays_open(p, j, s, hist, un, dil, area, state):
    """:func:`stays_open` for :func:`friction_update`."""
    return p.kn[j] * area * (un + dil) < -0.0 and (state & FAILED) | OPEN == state


@inline_kernel
def friction_energy(p, j, s, hist, un, dil, fx, fy, fz, area, state):
    """:func:`energy` for a joint without tension (never bonded)."""
    return _springs(p.kn[j], p.ks[j], un, dil, fx, fy, fz, area, -0.0)


@inline_kernel
def friction_dissipation(p, j, s, hist, dun, dsx, dsy, dsz, area, un0, dil0, gx, gy, gz, st0,
                         un, dil, fn, fx, fy, fz, st):
    """:func:`dissipation` for a joint without tension (never bonded)."""
    kna = p.kn[j] * area
    fn0 = max(kna * (un0 + dil0), -0.0)
    fn1 = max(kna * (un + dil), -0.0)
    return _linear_dissipation(p.kn[j], p.ks[j], dun, dsx, dsy, dsz, area, fn0, fn1, fn, gx, gy,
                               gz, fx, fy, fz)


# Strength reduction (a factor-of-safety stage) as 3DEC's: tan(friction)/F, cohesion/F,
# tension/F. Dilation is left as it is (3DEC leaves it too): at large F the reduced friction can
# fall below it, which this law allows (no validator relates the two, and the update uses
# tan(dilation) only while slipping); stiffnesses and dilation_limit are not strengths.
STRENGTH = Strength(angles=("friction",), strengths=("cohesion", "tension"))

FRICTION_LAW = JointLaw("coulomb", Params, (), friction_table, friction_update, friction_energy,
                        dissipation=friction_dissipation, stays_open=friction_stays_open,
                        strength=STRENGTH)
LAW = JointLaw("coulomb", Params, (), table, update, energy,
               variants=((is_frictional, FRICTION_LAW),), dissipation=dissipation,
               stays_open=stays_open, strength=STRENGTH)
