"""Mohr-Coulomb zones (pdem.deformable.constitutive) against closed forms: the return mapping
on its own, then a cube in uniaxial and triaxial compression and in tension driven through the
full cycle (strength, tension cut-off, dilatancy of the non-associated flow rule)."""

from __future__ import annotations

import math
from collections import namedtuple
from typing import Literal

import numba
import numpy as np
import pytest

from pdem.deformable.body import DeformableBody
from pdem.deformable.constitutive import (
    SHEAR_NOW,
    SHEAR_PAST,
    TENSION_NOW,
    ZONE_MODELS,
    ElasticParams,
    ZoneModel,
    _extreme_principal,
    elastic_update,
    material,
    mohr_coulomb_update,
    symmetric_eigen,
)
from pdem.deformable.motion import GW_BOUNDARY, GW_PLASTIC, GW_ZONE, cycle
from pdem.geometry import box

WEAK = dict(density=2400, young=5.0e9, poisson=0.3, model="mohr_coulomb", cohesion=2.0e6,
            friction=35.0, tension=0.5e6, dilation=5.0)


def n_of(deg):
    s = math.sin(math.radians(deg))
    return (1 + s) / (1 - s)


def test_registry_and_validation():
    assert {"elastic", "mohr_coulomb"} <= set(ZONE_MODELS.names())
    params, table = material(WEAK)
    assert table.n_phi == pytest.approx(n_of(35.0))
    with pytest.raises(KeyError, match="did you mean 'mohr_coulomb'"):
        material({**WEAK, "model": "mohr_colomb"})
    with pytest.raises(ValueError, match="dilation"):
        material({**WEAK, "dilation": 40.0})
    # the tension cut-off is capped at the apex c / tan(phi)
    _, capped = material({**WEAK, "tension": 1e9})
    assert capped.tension == pytest.approx(2.0e6 / math.tan(math.radians(35.0)))


# --- a zone model added from outside the package: parameters, table, kernel, one registration
class MarkedParams(ElasticParams):
    model: Literal["marked_elastic"] = "marked_elastic"  # type: ignore[assignment]


MarkedTable = namedtuple("MarkedTable", "bulk shear")


@numba.njit  # not cached, see _uncached_cycle
def marked_update(p, s, de):
    elastic_update(p, s, de)
    return 16, 0.0  # a bit no built-in model sets: proves this kernel ran


ZONE_MODELS.register("marked_elastic", ZoneModel(
    "marked_elastic", MarkedParams, MarkedTable, lambda q: MarkedTable(q.bulk, q.shear),
    marked_update))


# The cycle's own code, compiled without numba's disk cache: a cached specialisation on this
# module's table type would put the type's module in the cache index, and every later process
# loading ``cycle`` (without this test module importable) would fail to read the index.
_uncached_cycle = numba.njit(cycle.py_func)


def test_model_registered_outside_runs_in_the_cycle():
    b = DeformableBody(box([0, 0, 0], [1, 1, 1]),
                       dict(model="marked_elastic", density=1000.0, young=1e9, poisson=0.2),
                       size=1.0)
    b.vel[:, 0] = 1e-3 * b.nodes[:, 0]
    _uncached_cycle(3, b.timestep(), b.nodes, b.vel, b.mass, b.applied, b.fixed, b.fixed_vel,
                    b.tets, b.grad, b.vol, b.stress, b.plastic, b.model, b.nmd, b.damping_mode,
                    b.damping, b.prev_force, np.zeros(1), b.servo, b.applied, b.applied,
                    b.applied, 1.0, 1.0, b.work)
    assert np.all(b.plastic == 16)
    assert np.all(b.stress[:, 0] > 0.0)  # and it is elastic: stretched along x


def test_symmetric_eigen_matches_numpy():
    rng = np.random.default_rng(0)
    for _ in range(50):
        s = rng.normal(size=6) * 10.0 ** rng.uniform(-3, 6)
        t = np.array([[s[0], s[3], s[5]], [s[3], s[1], s[4]], [s[5], s[4], s[2]]])
        vec = np.empty((3, 3))
        lam = symmetric_eigen(s, vec)
        assert np.allclose(lam, np.linalg.eigvalsh(t), rtol=0, atol=1e-13 * np.abs(t).max())
        assert np.allclose(vec @ np.diag(lam) @ vec.T, t, rtol=0, atol=1e-13 * np.abs(t).max())
        lo, hi = _extreme_principal(s)  # the elastic screen's closed form
        assert np.allclose([lo, hi], lam[[0, 2]], rtol=0, atol=1e-12 * np.abs(t).max())


@pytest.mark.parametrize("dilation", [0.0, 5.0, 20.0])
def test_return_mapping_flow_rule(dilation):
    """From a state on the shear surface, a further strain increment is split so that the
    stress stays on the surface and the plastic strain (increment minus elastic part) obeys
    the non-associated rule: -de_v^p / (de_1^p - de_3^p) = sin(psi), de_2^p = 0."""
    params, p = material({**WEAK, "dilation": dilation})
    k, g = params.bulk, params.shear
    n_phi = n_of(35.0)
    s3, s2 = -1.0e6, -1.5e6
    s1 = s3 * n_phi - 2 * 2.0e6 * math.sqrt(n_phi)  # exactly on f_s = 0 (s1 most compressive)
    stress = np.array([s1, s2, s3, 0.0, 0.0, 0.0])
    de = np.array([-2e-4, 0.3e-4, 0.5e-4, 0.0, 0.0, 0.0])  # loads further into yield
    before = stress.copy()
    bits, sigma_p = mohr_coulomb_update(p, stress, tuple(de))
    assert bits == SHEAR_NOW
    fs = stress[0] - stress[2] * n_phi + 2 * 2.0e6 * math.sqrt(n_phi)
    assert abs(fs) < 1e-9 * abs(s1)
    ds = stress - before
    mean = ds[:3].sum() / 3.0
    de_el = (ds[:3] - mean) / (2 * g) + mean / (3 * k)
    dp = de[:3] - de_el
    assert abs(dp[1]) < 1e-12
    ratio = -dp.sum() / (dp[0] - dp[2])
    print(f"psi={dilation}: -de_v^p/(de_1^p - de_3^p) = {ratio:.6f} vs sin(psi) "
          f"{math.sin(math.radians(dilation)):.6f}")
    assert ratio == pytest.approx(math.sin(math.radians(dilation)), abs=1e-9)
    assert sigma_p == pytest.approx(k * dp.sum(), rel=1e-9, abs=1e-6)


def test_tension_return():
    """One, two or three principal stresses above the cut-off are brought to it; the others
    move by the elastic coupling (lambda = K - 2G/3) of the plastic extension, and sigma_p is
    K times the plastic volume change."""
    params, p = material(WEAK)
    k, g = params.bulk, params.shear
    a1, a2 = k + 4 * g / 3, k - 2 * g / 3
    t = 0.5e6
    # uniaxial pull: only s3 exceeds the cut-off
    stress = np.zeros(6)
    bits, sigma_p = mohr_coulomb_update(p, stress, (0.0, 0.0, 2e-4, 0.0, 0.0, 0.0))
    d3 = (a1 * 2e-4 - t) / a1
    assert bits == TENSION_NOW
    assert stress[2] == pytest.approx(t, rel=1e-12)
    assert stress[0] == pytest.approx(a2 * 2e-4 - a2 * d3, rel=1e-12)
    assert sigma_p == pytest.approx(k * d3, rel=1e-12)
    # hydrostatic pull: the apex, all three at the cut-off
    stress = np.zeros(6)
    bits, sigma_p = mohr_coulomb_update(p, stress, (1e-3, 1e-3, 1e-3, 0.0, 0.0, 0.0))
    assert bits == TENSION_NOW
    assert np.allclose(stress[:3], t, rtol=1e-12) and np.all(stress[3:] == 0.0)
    assert sigma_p == pytest.approx(3 * k * 1e-3 - t, rel=1e-12)
    # biaxial pull: s2 and s3 at the cut-off, s1 below it
    stress = np.zeros(6)
    mohr_coulomb_update(p, stress, (-2e-4, 1e-3, 1e-3, 0.0, 0.0, 0.0))
    lam = np.sort(stress[:3])
    assert lam[1:] == pytest.approx([t, t], rel=1e-12) and lam[0] < t


# --- through the cycle -------------------------------------------------------------------------
def cube_test(spec, confining: float, axial_rate: float, steps: int):
    """Unit cube on rollers at x = 0, y = 0, z = 0, pressure ``confining`` on x = 1 and y = 1
    (and the cube pre-stressed to it), the top driven at ``axial_rate`` (m/step, mass-scaled,
    damped). Returns per-step mean axial stress, axial strain and volumetric strain."""
    b = DeformableBody(box([0, 0, 0], [1, 1, 1]), spec, size=0.5, damping=0.8,
                       mass_scaling=True)
    x0 = b.nodes0
    for axis in range(3):
        b.fix(np.isclose(x0[:, axis], 0.0), dofs=(axis,))
    b.fix(np.isclose(x0[:, 2], 1.0), dofs=(2,), velocity=axial_rate)
    b.stress[:, :3] = -confining
    b.applied = b.traction(1, [-confining, 0, 0]) + b.traction(3, [0, -confining, 0])
    szz, ezz, ev = [], [], []
    for _ in range(steps // 50):
        b.step(50)
        szz.append(np.sum(b.stress[:, 2] * b.vol) / b.vol.sum())
        ezz.append(b.displacement[np.isclose(x0[:, 2], 1.0), 2].mean())
        ev.append(b.vol.sum() - 1.0)
    return b, np.array(szz), np.array(ezz), np.array(ev)


@pytest.mark.parametrize(("confining", "dilation"), [(0.0, 5.0), (2.0e6, 5.0), (2.0e6, 0.0)])
def test_compression_strength_and_dilatancy(confining, dilation):
    """Peak axial stress = sigma_3 N_phi + 2 c sqrt(N_phi); during steady plastic flow the
    volume changes as de_v / de_axial = 1 - N_psi (zero for psi = 0)."""
    spec = {**WEAK, "dilation": dilation}
    b, szz, ezz, ev = cube_test(spec, confining, -2.0e-6, 4000)
    n_phi = n_of(35.0)
    strength = confining * n_phi + 2 * 2.0e6 * math.sqrt(n_phi)
    err = abs(-szz[-1] / strength - 1.0)
    flow = slice(len(szz) - 20, len(szz))  # last 1000 steps, well past yield (at < 1500)
    rate = np.polyfit(ezz[flow], ev[flow], 1)[0]
    want = 1.0 - n_of(dilation)
    print(f"sigma3={confining:.0e} psi={dilation}: strength error {err:.1e}, "
          f"dv/de_axial {rate:.5f} vs {want:.5f}")
    assert err < 1e-2
    assert np.all(b.plastic & (SHEAR_NOW | SHEAR_PAST))
    assert rate == pytest.approx(want, abs=5e-3)


def test_tension_cut_off():
    """Pulled, unconfined: the axial stress plateaus at the tensile strength."""
    b, szz, _, _ = cube_test(WEAK, 0.0, 1.0e-6, 1500)
    err = abs(szz[-1] / 0.5e6 - 1.0)
    print(f"tension plateau error {err:.1e}")
    assert err < 1e-2
    assert np.all(b.plastic & TENSION_NOW)


def test_tension_yield_books_plastic_and_elastic_work():
    """A Mohr-Coulomb cube (nu = 0, 750 zones; at size 0.5, 162 zones, the elastic + kinetic
    energy is 1.0 % short of the closed form, over the bound) stretched by its top gridpoints at 0.01 m/s to
    5 times its tension limit's strain T/E: the grid's accumulators (the energy budget's
    columns) against the closed forms of a uniaxial bar at the cut-off T. Put in by the
    prescribed velocity ``T (d - d_y/2)``; held elastically ``T^2 V / 2E`` (with the little
    kinetic energy of the undamped stretch); dissipated ``T (d - d_y)``, ``d_y = T L / E``."""
    E, T, V = 1.0e8, 1.0e4, 0.01
    b = DeformableBody(box([0, 0, 0], [1, 1, 1]), dict(
        model="mohr_coulomb", density=2000.0, young=E, poisson=0.0, cohesion=1.0e7,
        friction=30.0, tension=T, dilation=0.0), size=0.35)
    z = b.nodes0[:, 2]
    b.fix(z < 1e-9, (2,), 0.0)
    b.fix(z > 1 - 1e-9, (2,), V)
    b.vel[z > 1 - 1e-9, 2] = V
    dt = 0.5 * b.timestep()
    n = int(0.05 / dt)
    b.step(n, dt)
    d = V * n * dt
    w = b.work
    kinetic = b.kinetic_as_integrated()
    elastic = w[GW_ZONE] - w[GW_PLASTIC]
    # measured: boundary +6.0e-4, plastic +3.5e-4, elastic + kinetic +2.7e-3
    assert w[GW_BOUNDARY] == pytest.approx(T * (d - 0.5 * T / E), rel=3e-3)
    assert w[GW_PLASTIC] == pytest.approx(T * (d - T / E), rel=3e-3)
    assert elastic + kinetic == pytest.approx(T * T / (2.0 * E), rel=3e-3)
    assert elastic == pytest.approx(b.strain_energy(), rel=0.03)  # less the kinetic: -2.0 %
    # no contacts: the grid's balance is the leap-frog's, to round-off
    assert abs(kinetic + w[GW_ZONE] - w[GW_BOUNDARY]) < 1e-12 * w[GW_BOUNDARY]
