"""The continuously yielding joint (Cundall & Hart 1984; Lemos 1987), as 3DEC and UDEC use it
for progressive damage of a joint under shear.

Sources: P. A. Cundall and R. D. Hart, "Analysis of block test No. 1 inelastic rock mass
behavior: phase 2 - a characterization of joint behavior (final report)", Itasca report to
Rockwell Hanford Operations (1984); J. V. Lemos, "A distinct element model for dynamic
analysis of jointed rock with application to dam foundations and fault motion", PhD thesis,
University of Minnesota (1987); the model as documented in the UDEC and 3DEC manuals ("joint
constitutive models: continuously yielding"). The equations below are those of the project's
formulation notes (shared/reference/continuously-yielding-joint.md), written in the incremental
form of an explicit code; where the published model leaves a choice open, the choice made here
is marked *(pdem)*. Sign convention: ``σn > 0`` in compression.

Normal (Cundall & Hart; 3DEC ``jkn``, ``jen``)::

    dσn = kn(σn) dun,   kn(σn) = a_n σn^e_n                                              (1)

With ``0 <= e_n < 1`` this is a nonlinear *elastic* spring, so it is integrated exactly from
``σn = 0`` at zero closure *(pdem: total form, path independent, conserves energy)*::

    σn = ((1 - e_n) a_n u)^(1 / (1 - e_n)),   u = un + dil > 0,   σn = 0 otherwise      (1a)
    stored energy per area  W = ∫ σn du = σn u (1 - e_n) / (2 - e_n)                      (1b)

(``e_n = 0``: ``σn = a_n u``, ``W = σn u / 2``). No tension: the joint opens at ``u <= 0``.

Shear (Cundall & Hart; 3DEC ``jks``, ``jes``)::

    Δτ = F ks |Δus|  along -Δus (the force on B resists its motion),  ks = a_s σn^e_s       (2)
    F  = (1 - τ/τm) / (1 - r),   0 <= F <= 1                                              (3)
    τm = σn tan φm   (the bounding strength)                                              (4)

``τ/τm`` is signed: the component of the current shear stress along the increment over the
bounding strength (so it is negative while the joint unloads). ``r`` starts at 0 and is reset
to ``τ/τm`` at every reversal of the shear direction, so that unloading and reloading start at
the full stiffness ``ks`` (``F = 1``); *(pdem)* a reversal is an increment whose direction
makes an obtuse angle with the previous increment's, and ``r`` is capped at
:data:`R_CAP` = 0.75 (UDEC also caps ``r``) so that reloading can never be rigid. The shear
stress is clipped to the bounding strength of the step's start (explicit); what the clip
removes counts as plastic displacement (eq. 5). So once the stress has met the bound it rides
it as the bound falls, the spring unloading elastically: ``dup/dus = 1 / (1 + τm'(up)/ks)``,
a little above 1 (``τm' < 0``), in the limit of small steps.

Damage: the bounding friction ``φm`` degrades with plastic shear displacement ``up``::

    Δup = (1 - F) |Δus|  (+ whatever the clip at τm removed, over ks)                      (5)
    dφm = -(1/R) (φm - φ) dup   =>   φm(up) = φ + (φm0 - φ) exp(-up / R)                   (6)

``φm0`` (initial friction, 3DEC ``jif``) >= ``φ`` (basic / residual friction, ``jfriction``),
``R`` the joint roughness, a length (``jr``). *(pdem)* Eq. 6 is used in its integrated form,
so the history keeps ``up`` and ``φm`` follows exactly for any step size.

Dilation: the apparent dilation angle is the mobilized friction less the basic friction::

    i = atan(|τ| / σn) - φ,        Δdil = ± tan(i) |Δus|                                   (7)

*(pdem)* ``i`` is clipped at 0 (no contraction while the mobilized friction is below ``φ``);
the sign is + while the joint loads (stress component along the increment >= 0) and - when it
unloads, and ``dil >= 0`` (as the Coulomb joint does on reversal). The dilation adds to the
closure in eq. 1a, as in eq. 43 of the Coulomb joint.

The Coulomb limit *(pdem)*: ``continuous: false`` replaces eq. 3 by the sharp elastic-plastic
rule (``F = 1`` below the bound, plastic flow at it, ``Δup`` = the slip). With
``initial_friction == friction`` there is then no damage (eq. 6 keeps ``φm = φ``) and no
dilation (``i = 0`` at the bound), and with ``normal_exponent = shear_exponent = 0`` the law is
the ``coulomb`` joint with that friction and no cohesion, tension or dilation, to round-off.
(``roughness -> ∞`` alone switches the damage off but keeps the continuous approach of eq. 3.)

Scene parameters and 3DEC's names: ``kn``, ``ks`` are the stiffnesses at ``reference_stress``
``σr`` so that ``a_n = kn / σr^e_n`` (``jkn``), ``a_s = ks / σr^e_s`` (``jks``); with zero
exponents (the default) they are the constant stiffnesses and ``σr`` plays no part.
``normal_exponent`` = ``e_n`` (``jen``), ``shear_exponent`` = ``e_s`` (``jes``), ``friction`` =
``φ`` (``jfriction``), ``initial_friction`` = ``φm0`` (``jif``, default ``friction``),
``roughness`` = ``R`` (``jr``, m; null: no damage). The timestep is estimated with ``kn``,
``ks``: with positive exponents, pick ``reference_stress`` at (or above) the largest normal
stress expected.

History columns (``sc_hist``): ``up`` (plastic shear displacement), ``r``, and the previous
increment's direction ``(ex, ey, ez)``.
"""

from __future__ import annotations

import math
from collections import namedtuple
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, PositiveFloat, model_validator

from ...jit import inline_kernel
from .base import OPEN, SLIPPING, JointLaw, JointParams, Strength

R_CAP = 0.75  # cap on the reversal factor r of eq. 3 (pdem's choice)


class Params(JointParams):
    """``joints.X`` with ``model: continuously_yielding``: stiffness in Pa/m at
    ``reference_stress`` (Pa), angles in degrees, ``roughness`` in m (see module doc)."""

    model: Literal["continuously_yielding"] = "continuously_yielding"
    normal_exponent: Annotated[float, Field(ge=0.0, lt=1.0)] = 0.0
    shear_exponent: Annotated[float, Field(ge=0.0, le=2.0)] = 0.0
    reference_stress: PositiveFloat = 1.0e6
    friction: Annotated[float, Field(ge=0.0, lt=90.0)] = 30.0
    initial_friction: Annotated[float, Field(ge=0.0, lt=90.0)] | None = None
    roughness: PositiveFloat | None = None
    continuous: bool = True

    @model_validator(mode="after")
    def _friction_order(self):
        if self.initial_friction is not None and self.initial_friction < self.friction:
            raise ValueError(
                f"initial_friction ({self.initial_friction} deg) is below friction "
                f"({self.friction} deg): the bounding friction degrades from "
                "initial_friction towards the residual friction, so it must be >= friction")
        return self


Table = namedtuple("Table", "an en as_ es tan_phi phi phim0 inv_r ks_ref continuous")


def table(joints: list[Params]) -> Table:
    """Per-joint arrays (angles in radians here; ``a_n``, ``a_s`` from ``kn``, ``ks``)."""
    return Table(
        np.array([x.kn / x.reference_stress ** x.normal_exponent for x in joints], float),
        np.array([x.normal_exponent for x in joints], float),
        np.array([x.ks / x.reference_stress ** x.shear_exponent for x in joints], float),
        np.array([x.shear_exponent for x in joints], float),
        np.array([math.tan(math.radians(x.friction)) for x in joints], float),
        np.array([math.radians(x.friction) for x in joints], float),
        np.array([math.radians(x.friction if x.initial_friction is None
                               else x.initial_friction) for x in joints], float),
        np.array([0.0 if x.roughness is None else 1.0 / x.roughness for x in joints], float),
        np.array([x.ks for x in joints], float),
        np.array([1.0 if x.continuous else 0.0 for x in joints], float),
    )


@inline_kernel
def normal_stress(an, en, u):
    """Eq. 1a: ``σn`` at closure ``u`` (0 when open). Without branches (inlined into the
    energy kernel): for ``e_n = 0`` the power is 1 and ``σn = a_n u`` exactly."""
    return ((1.0 - en) * an * max(u, 0.0)) ** (1.0 / (1.0 - en))


@inline_kernel
def shear_stiffness(as_, es, sn):
    """``ks = a_s σn^e_s`` (eq. 2); ``e_s = 0``: ``a_s`` exactly (``x ** 0 = 1``)."""
    return as_ * max(sn, 0.0) ** es


@inline_kernel
def update(p, j, s, hist, un, dil, fx, fy, fz, dx, dy, dz, area, ux, uy, uz, state):
    """Update one sub-contact (eqs. 1-7 of the module doc).

    ``hist[s]``: ``up, r, ex, ey, ez``. Returns ``(fn, dil, state, fx, fy, fz)``.
    """
    state = state & 0  # no lasting bits: no tension or cohesion to lose
    up = hist[s, 0]
    r = hist[s, 1]
    sn = normal_stress(p.an[j], p.en[j], un + dil)
    if sn <= 0.0 or area <= 0.0:
        hist[s, 1] = 0.0
        return 0.0, dil, state | OPEN, 0.0, 0.0, 0.0
    phi = p.phi[j]
    phim = phi + (p.phim0[j] - phi) * math.exp(-up * p.inv_r[j])  # eq. 6
    tan_phim = math.tan(phim)
    fmax = sn * tan_phim * area  # eq. 4, as a force
    kss = shear_stiffness(p.as_[j], p.es[j], sn) * area
    dus = math.sqrt(dx * dx + dy * dy + dz * dz)
    fmag0 = math.sqrt(fx * fx + fy * fy + fz * fz)
    if dus == 0.0:
        if fmag0 > fmax:  # normal stress fell: the bound clips the stress
            sc = fmax / fmag0 if fmag0 > 0.0 else 0.0
            return sn * area, dil, state | SLIPPING, fx * sc, fy * sc, fz * sc
        return sn * area, dil, state, fx, fy, fz
    ex, ey, ez = dx / dus, dy / dus, dz / dus
    # reversal: the increment turns back on the previous one -> r = τ/τm (eq. 3)
    # signed τ/τm along the increment (a frictionless joint is always at its bound)
    rho = -(fx * ex + fy * ey + fz * ez) / fmax if fmax > 0.0 else 1.0
    if ex * hist[s, 2] + ey * hist[s, 3] + ez * hist[s, 4] < 0.0:
        r = min(rho, R_CAP)
    hist[s, 2], hist[s, 3], hist[s, 4] = ex, ey, ez
    if p.continuous[j] != 0.0:
        f = min(max((1.0 - rho) / (1.0 - r), 0.0), 1.0)  # eq. 3
    else:
        f = 1.0
    dup = (1.0 - f) * dus  # eq. 5
    step = f * kss  # eq. 2
    fx = fx - step * dx
    fy = fy - step * dy
    fz = fz - step * dz
    fmag = math.sqrt(fx * fx + fy * fy + fz * fz)
    if fmag > fmax:  # clip at the bounding strength; the excess is plastic too
        dup += min((fmag - fmax) / kss, dus)
        sc = fmax / fmag if fmag > 0.0 else 0.0
        fx *= sc
        fy *= sc
        fz *= sc
        fmag = fmax
    if dup > 0.0:
        state |= SLIPPING
        hist[s, 0] = up + dup
    hist[s, 1] = r
    # eq. 7: dilation from the mobilized friction above the basic friction
    # (the mobilized friction never exceeds φm: no round-off dilation when φm = φ)
    tan_mob = min(fmag / (sn * area), tan_phim)
    tan_phi = p.tan_phi[j]
    tan_i = (tan_mob - tan_phi) / (1.0 + tan_mob * tan_phi)
    if tan_i > 0.0:
        loading = -(fx * ex + fy * ey + fz * ez) >= 0.0
        dil0 = dil
        dil = max(dil + (tan_i * dus if loading else -tan_i * dus), 0.0)
        if dil != dil0:
            sn = normal_stress(p.an[j], p.en[j], un + dil)
    return sn * area, dil, state, fx, fy, fz


@inline_kernel
def stays_open(p, j, s, hist, un, dil, area, state):
    """Whether :func:`update` takes its open branch with nothing to change: the state is
    OPEN already and the reversal ratio it would zero is +0 (not -0: the same bits)."""
    if state != OPEN or hist[s, 1] != 0.0 or math.copysign(1.0, hist[s, 1]) < 0.0:
        return False
    return normal_stress(p.an[j], p.en[j], un + dil) <= 0.0 or area <= 0.0


@inline_kernel
def energy(p, j, s, hist, un, dil, fx, fy, fz, area, state):
    """Normal force and stored spring energy: eq. 1b for the normal spring, ``|fs|^2 / (2 ks
    A)`` for the shear spring with ``ks`` at the current normal stress (exact for
    ``shear_exponent = 0``; with a stress-dependent ``ks`` the shear spring has no potential
    and this is the usual estimate)."""
    has_area = area > 0.0
    a = max(area, 1e-300)
    u = un + dil
    en = p.en[j]
    sn = normal_stress(p.an[j], en, u)
    kss = max(shear_stiffness(p.as_[j], p.es[j], sn), 1e-300 * p.ks_ref[j]) * a
    fn = sn * a * has_area
    w = fn * max(u, 0.0) * (1.0 - en) / (2.0 - en)
    return fn, w + 0.5 * (fx * fx + fy * fy + fz * fz) * has_area / kss


# Strength reduction (a factor-of-safety stage): the joint's strength is its bounding friction
# φm (eq. 4, τm = σn tan φm; no cohesion or tension), which goes from initial_friction (φm0,
# the peak) to friction (φ, the residual) with damage (eq. 6): both angles are reduced through
# their tangents, tan(φ)/F and tan(φm0)/F, so the whole bound, peak to residual, is weakened.
# initial_friction unset stays unset (the table then takes the reduced friction for it); set,
# it stays >= the reduced friction (the tangent's reduction keeps the order, as the validator
# wants). The dilation (eq. 7) follows from the two angles and has no parameter of its own.
# Not strengths: the stiffnesses and their exponents and reference_stress (the normal and
# shear springs), roughness (a length: how fast the peak degrades, not how high it is) and
# continuous.
STRENGTH = Strength(angles=("friction", "initial_friction"))

LAW = JointLaw("continuously_yielding", Params, ("up", "r", "ex", "ey", "ez"), table, update,
               energy, stays_open=stays_open, strength=STRENGTH)
