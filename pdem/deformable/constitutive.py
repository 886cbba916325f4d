"""Zone constitutive models by name (``materials.<name>.model``), each a numba kernel.

A model is a :class:`ZoneModel` registered in :data:`ZONE_MODELS`: its scene parameters
(a :class:`~pdem.strict.Strict` model), ``table(params)`` -> the kernel's constants (a
namedtuple of floats: one material per deformable block) and ``update``, a kernel

    update(table, stress_row, de) -> (plastic_bits, sigma_p)

that takes a zone's stress row (``xx yy zz xy yz zx``, tension positive, updated in place) and
this step's strain increment ``de`` (a 6-tuple in the same order, shear components as tensor,
not engineering, strains) and returns the zone's "now" plastic bits and ``sigma_p = K de_v^p``,
the plastic volumetric stress correction the nodal mixed discretization on stress averages
(eq. 73). :func:`update_stress` resolves the kernel per table type at compile time, as
:func:`pdem.dynamics.damping.damped_momentum` does per damping mode: no runtime dispatch, and
a model registered from outside this file is found the same way.
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from numba.extending import overload
from pydantic import Field, NonNegativeFloat, PositiveFloat, model_validator

from ..jit import inline_kernel
from ..registry import Registry
from ..strict import Strict

# per-zone plastic state bits (FLAC3D's convention: "now" is this step, "past" ever before)
SHEAR_NOW = 1
TENSION_NOW = 2
SHEAR_PAST = 4
TENSION_PAST = 8


class ElasticParams(Strict):
    """Isotropic linear elasticity: ``young`` (Pa), ``poisson``, ``density`` (kg/m^3)."""

    model: Literal["elastic"] = "elastic"
    density: PositiveFloat
    young: PositiveFloat
    poisson: Annotated[float, Field(gt=-1.0, lt=0.5)]

    @property
    def bulk(self) -> float:
        return self.young / (3.0 * (1.0 - 2.0 * self.poisson))

    @property
    def shear(self) -> float:
        return self.young / (2.0 * (1.0 + self.poisson))


class MohrCoulombParams(ElasticParams):
    """Elastic-perfectly plastic Mohr-Coulomb with a tension cut-off and non-associated flow:
    ``cohesion``, ``tension`` (Pa), ``friction`` and ``dilation`` angles (degrees)."""

    model: Literal["mohr_coulomb"] = "mohr_coulomb"  # type: ignore[assignment]
    cohesion: NonNegativeFloat
    friction: Annotated[float, Field(ge=0.0, lt=90.0)]
    tension: NonNegativeFloat = 0.0
    dilation: Annotated[float, Field(ge=0.0, lt=90.0)] = 0.0

    @model_validator(mode="after")
    def _dilation_below_friction(self):
        if self.dilation > self.friction:
            raise ValueError(f"dilation {self.dilation} exceeds friction {self.friction}: "
                             "the flow rule would generate energy")
        return self


ElasticTable = namedtuple("ElasticTable", "bulk shear")
MohrCoulombTable = namedtuple(
    "MohrCoulombTable", "bulk shear n_phi two_c_sqrt_n_phi tension n_psi alpha_p sigma_p")


def elastic_table(p: ElasticParams) -> ElasticTable:
    return ElasticTable(p.bulk, p.shear)


def mohr_coulomb_table(p: MohrCoulombParams) -> MohrCoulombTable:
    """Angles become N_phi, N_psi once here; the tension cut-off is capped at the apex of the
    shear cone, ``c / tan(phi)`` (FLAC3D does the same), so the two surfaces always meet."""
    s_phi = math.sin(math.radians(p.friction))
    s_psi = math.sin(math.radians(p.dilation))
    n_phi = (1.0 + s_phi) / (1.0 - s_phi)
    n_psi = (1.0 + s_psi) / (1.0 - s_psi)
    tension = p.tension
    if p.friction > 0.0:
        tension = min(tension, p.cohesion / math.tan(math.radians(p.friction)))
    two_c = 2.0 * p.cohesion * math.sqrt(n_phi)
    alpha_p = math.sqrt(1.0 + n_phi * n_phi) + n_phi
    return MohrCoulombTable(p.bulk, p.shear, n_phi, two_c, tension, n_psi, alpha_p,
                            tension * n_phi - two_c)


def mohr_coulomb_reduced(p: MohrCoulombParams, factor: float) -> MohrCoulombParams:
    """Strength reduction (FLAC3D/3DEC ``factor-of-safety``): ``cohesion / F``,
    ``tan(friction) / F``, ``tension / F``; the dilation angle kept, but not above the
    reduced friction angle (the flow rule must not generate energy)."""
    phi = math.degrees(math.atan(math.tan(math.radians(p.friction)) / factor))
    return p.model_copy(update={"cohesion": p.cohesion / factor, "friction": phi,
                                "tension": p.tension / factor,
                                "dilation": min(p.dilation, phi)})


@dataclass(frozen=True)
class ZoneModel:
    """``params``: the scene model; ``table(params)`` -> an instance of ``table_type`` (a
    namedtuple owned by this model alone: it selects ``update`` at compile time);
    ``reduced(params, F)`` -> the params with their strength divided by F (a factor of
    safety's trial), None: a model without strength (elastic), unchanged."""

    name: str
    params: type[ElasticParams]
    table_type: type
    table: Callable
    update: Callable
    reduced: Callable | None = None


def update_stress(table, stress_row, de):
    """Apply the model of ``table``'s type to one zone (see the module doc); numba only."""
    raise NotImplementedError("update_stress is only callable from numba kernels")


@inline_kernel
def _elastic_increment(k, g, s, de):
    """``s += K tr(de) I + 2 G dev(de)`` (eq. 59 with lambda = K - 2G/3)."""
    ev = de[0] + de[1] + de[2]
    lam = (k - 2.0 * g / 3.0) * ev
    s[0] += lam + 2.0 * g * de[0]
    s[1] += lam + 2.0 * g * de[1]
    s[2] += lam + 2.0 * g * de[2]
    s[3] += 2.0 * g * de[3]
    s[4] += 2.0 * g * de[4]
    s[5] += 2.0 * g * de[5]


@inline_kernel
def elastic_update(p, s, de):
    _elastic_increment(p.bulk, p.shear, s, de)
    return 0, 0.0


@inline_kernel
def symmetric_eigen(s, vec):
    """Eigenvalues (ascending) of the symmetric tensor row ``s``; eigenvectors into the columns
    of ``vec (3, 3)``. Cyclic Jacobi: no LAPACK (numba's needs scipy), exact to round-off."""
    a = np.empty((3, 3))
    a[0, 0], a[1, 1], a[2, 2] = s[0], s[1], s[2]
    a[0, 1] = a[1, 0] = s[3]
    a[1, 2] = a[2, 1] = s[4]
    a[0, 2] = a[2, 0] = s[5]
    for i in range(3):
        for j in range(3):
            vec[i, j] = 1.0 if i == j else 0.0
    scale = abs(a[0, 0]) + abs(a[1, 1]) + abs(a[2, 2]) + abs(s[3]) + abs(s[4]) + abs(s[5])
    for _ in range(50):
        off = abs(a[0, 1]) + abs(a[1, 2]) + abs(a[0, 2])
        if off <= 1e-300 or off <= 1e-17 * scale:
            break
        for p, q in ((0, 1), (1, 2), (0, 2)):
            apq = a[p, q]
            if apq == 0.0:
                continue
            theta = (a[q, q] - a[p, p]) / (2.0 * apq)
            t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
            c = 1.0 / math.sqrt(t * t + 1.0)
            sn = t * c
            for k in range(3):  # a <- J^T a J
                akp, akq = a[k, p], a[k, q]
                a[k, p] = c * akp - sn * akq
                a[k, q] = sn * akp + c * akq
            for k in range(3):
                apk, aqk = a[p, k], a[q, k]
                a[p, k] = c * apk - sn * aqk
                a[q, k] = sn * apk + c * aqk
            for k in range(3):
                vkp, vkq = vec[k, p], vec[k, q]
                vec[k, p] = c * vkp - sn * vkq
                vec[k, q] = sn * vkp + c * vkq
    lam = np.array([a[0, 0], a[1, 1], a[2, 2]])
    order = np.argsort(lam)
    out = np.empty(3)
    v2 = vec.copy()
    for j in range(3):
        out[j] = lam[order[j]]
        for k in range(3):
            vec[k, j] = v2[k, order[j]]
    return out


@inline_kernel
def _assemble(lam, vec, s):
    """``s = sum_i lam_i v_i v_i^T`` (principal stresses back with their directions)."""
    for r, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0))):
        s[r] = lam[0] * vec[i, 0] * vec[j, 0] + lam[1] * vec[i, 1] * vec[j, 1] \
            + lam[2] * vec[i, 2] * vec[j, 2]


@inline_kernel
def _extreme_principal(s):
    """Smallest and largest principal value of the row ``s`` by the trigonometric closed form
    (no eigenvectors); used only to screen out elastic zones."""
    q = (s[0] + s[1] + s[2]) / 3.0
    p1 = s[3] * s[3] + s[4] * s[4] + s[5] * s[5]
    dx, dy, dz = s[0] - q, s[1] - q, s[2] - q
    p2 = dx * dx + dy * dy + dz * dz + 2.0 * p1
    if p2 <= 1e-30 * (q * q + 1e-300):
        return q, q
    pp = math.sqrt(p2 / 6.0)
    bx, by, bz = dx / pp, dy / pp, dz / pp
    bxy, byz, bzx = s[3] / pp, s[4] / pp, s[5] / pp
    det = bx * (by * bz - byz * byz) - bxy * (bxy * bz - byz * bzx) + bzx * (bxy * byz - by * bzx)
    r = min(1.0, max(-1.0, 0.5 * det))
    phi = math.acos(r) / 3.0
    return q + 2.0 * pp * math.cos(phi + 2.0 * math.pi / 3.0), q + 2.0 * pp * math.cos(phi)


@inline_kernel
def _tension_return(a1, a2, k, t, lam):
    """Bring the principal stresses above ``t`` to ``t`` (lam ascending, in place); return the
    plastic volumetric strain. The exact return of the Rankine corners: plastic extension
    along s3 only; if s2 is then still above ``t``, along s2 and s3 together; if s1 too, to
    the apex (all three ``t``). FLAC3D's one-surface return stops after the first, which
    leaves s1, s2 > t in a hydrostatic pull."""
    s1, s2, s3 = lam[0], lam[1], lam[2]
    d3 = (s3 - t) / a1
    if s2 - a2 * d3 <= t:
        lam[0] = s1 - a2 * d3
        lam[1] = s2 - a2 * d3
        lam[2] = t
        return d3
    # [a1 a2; a2 a1] (d2, d3) = (s2 - t, s3 - t)
    det = a1 * a1 - a2 * a2
    d2 = (a1 * (s2 - t) - a2 * (s3 - t)) / det
    d3 = (a1 * (s3 - t) - a2 * (s2 - t)) / det
    if s1 - a2 * (d2 + d3) <= t:
        lam[0] = s1 - a2 * (d2 + d3)
        lam[1] = t
        lam[2] = t
        return d2 + d3
    ev_p = (s1 + s2 + s3 - 3.0 * t) / (3.0 * k)
    lam[0] = t
    lam[1] = t
    lam[2] = t
    return ev_p


@inline_kernel
def mohr_coulomb_update(p, s, de):
    """FLAC3D's Mohr-Coulomb return in principal stresses (s1 <= s2 <= s3, tension positive).

    Elastic trial, then on ``f_s = s1 - s3 N_phi + 2 c sqrt(N_phi) < 0`` (shear) or
    ``f_t = t - s3 < 0`` (tension), split by ``h = s3 - t + alpha_P (s1 - sigma_P)`` (the
    bisector of the corner): the shear return with plastic potential ``s1 - s3 N_psi``
    (plastic strains ``(l, 0, -l N_psi)``: non-associated, volume change ``l (1 - N_psi)``),
    or the tension return bringing ``s3`` (and ``s2``, ``s1`` if still above) to ``t``.
    Principal directions are kept.
    """
    k, g = p.bulk, p.shear
    _elastic_increment(k, g, s, de)
    # cheap screen first: most zones stay elastic, and the closed-form principal values
    # need no eigenvectors (the return below recomputes everything with Jacobi)
    lo, hi = _extreme_principal(s)
    if lo - hi * p.n_phi + p.two_c_sqrt_n_phi > 1e-12 * (abs(lo) + abs(hi)) \
            and p.tension - hi > 1e-12 * abs(hi):
        return 0, 0.0
    vec = np.empty((3, 3))
    lam = symmetric_eigen(s, vec)
    s1, s2, s3 = lam[0], lam[1], lam[2]
    fs = s1 - s3 * p.n_phi + p.two_c_sqrt_n_phi
    ft = p.tension - s3
    if fs >= 0.0 and ft >= 0.0:
        return 0, 0.0
    a1 = k + 4.0 * g / 3.0
    a2 = k - 2.0 * g / 3.0
    h = s3 - p.tension + p.alpha_p * (s1 - p.sigma_p)
    if fs < 0.0 and (h <= 0.0 or ft >= 0.0):
        ls = fs / ((a1 - a2 * p.n_psi) - (a2 - a1 * p.n_psi) * p.n_phi)
        lam[0] = s1 - ls * (a1 - a2 * p.n_psi)
        lam[1] = s2 - ls * a2 * (1.0 - p.n_psi)
        lam[2] = s3 - ls * (a2 - a1 * p.n_psi)
        bits = 1
        ev_p = ls * (1.0 - p.n_psi)
    else:
        ev_p = _tension_return(a1, a2, k, p.tension, lam)
        bits = 2
    _assemble(lam, vec, s)
    return bits, k * ev_p


@overload(update_stress, inline="always")
def _update_stress(table, stress_row, de):
    owners = [m for m in ZONE_MODELS.values() if m.table_type is table.instance_class]
    if not owners:
        raise KeyError(f"no registered zone model has the table type {table}")
    k = owners[0].update

    def impl(table, stress_row, de):
        return k(table, stress_row, de)
    return impl


ZONE_MODELS: Registry[ZoneModel] = Registry("zone constitutive model")
ZONE_MODELS.register("elastic", ZoneModel("elastic", ElasticParams, ElasticTable, elastic_table,
                                          elastic_update))
ZONE_MODELS.register("mohr_coulomb", ZoneModel("mohr_coulomb", MohrCoulombParams, MohrCoulombTable,
                                               mohr_coulomb_table, mohr_coulomb_update,
                                               mohr_coulomb_reduced))


def material(spec: dict):
    """A scene material (``{density, young, poisson, model?, ...}``) -> (params, kernel table)."""
    model = ZONE_MODELS[spec.get("model", "elastic")]
    params = model.params(**spec)
    return params, model.table(params)


def reduced_table(params: ElasticParams, factor: float):
    """The kernel table of ``params`` with its strength divided by ``factor``
    (:attr:`ZoneModel.reduced`; the model's own table at F = 1 and for a model without
    strength)."""
    model = ZONE_MODELS[params.model]
    if model.reduced is None or factor == 1.0:
        return model.table(params)
    return model.table(model.reduced(params, factor))
