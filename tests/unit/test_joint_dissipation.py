"""A joint's dissipation in one step, as the force loop books it (pdem.contact.laws).

The energy budget books, for every sub-contact step in which the joint yields or changes
state, the work done on it (trapezoid) less the change of its stored energy. The Coulomb laws
compute that regrouped (:func:`pdem.contact.laws.coulomb._linear_dissipation`, two divisions
instead of four); a law without a kernel of its own falls back to evaluating its stored energy
before and after. These tests hold the regrouped sum to the plain one, in every state the law
reaches (sticking, slipping, opening, bonded in tension, failing, dilating, without area), and
check what the regrouping is for: an elastic step dissipates nothing to far better than the
plain form's cancellation."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdem.contact.laws import JOINT_LAWS, apply_law, joint_dissipation, law_energy
from pdem.contact.laws.continuously_yielding import Params as CYParams
from pdem.contact.laws.coulomb import Params


@numba.njit
def _step(laws, un0, dil0, g, st0, dun, ds, area):
    """One sub-contact step of the law in slot 0, as contact_forces does it: returns the
    booked dissipation, the plain energy-difference form, and the work and energy scales."""
    hist = np.zeros((1, 5))
    un = un0 - dun
    fn, dil, state, fx, fy, fz = apply_law(laws, 0, 0, 0, hist, un, dil0, g[0], g[1], g[2],
                                          ds[0], ds[1], ds[2], area, ds[0], ds[1], ds[2], st0)
    booked = joint_dissipation(laws, 0, 0, 0, hist, dun, ds[0], ds[1], ds[2], area, un0, dil0,
                               g[0], g[1], g[2], st0, un, dil, fn, fx, fy, fz, state)
    fn0, e0 = law_energy(laws, 0, 0, 0, hist, un0, dil0, g[0], g[1], g[2], area, st0)
    _, e1 = law_energy(laws, 0, 0, 0, hist, un, dil, fx, fy, fz, area, state)
    work = -0.5 * ((fn0 + fn) * dun + (g[0] + fx) * ds[0] + (g[1] + fy) * ds[1]
                   + (g[2] + fz) * ds[2])
    scale = abs(fn0 * dun) + abs(fn * dun) + math.sqrt(g[0]**2 + g[1]**2 + g[2]**2 + fx**2
                                                       + fy**2 + fz**2) \
        * math.sqrt(ds[0]**2 + ds[1]**2 + ds[2]**2) + abs(e0) + abs(e1)
    return booked, work - (e1 - e0), scale, state, dil


def _laws(params):
    law = JOINT_LAWS[params.model].specialised([params])
    return law, (law.table([params]),)


COULOMB = {
    "frictional": Params(kn=1e10, ks=5e9, friction=30.0),
    "bonded": Params(kn=1e10, ks=5e9, friction=35.0, cohesion=2e5, tension=1e5),
    "dilating": Params(kn=1e10, ks=5e9, friction=30.0, dilation=10.0, dilation_limit=0.01),
}


def test_frictional_joint_compiles_its_own_dissipation():
    law, _ = _laws(COULOMB["frictional"])
    assert law.dissipation is not None and law.energy is not None
    assert JOINT_LAWS["continuously_yielding"].dissipation is None  # the fallback


@pytest.mark.parametrize("name", sorted(COULOMB))
@settings(max_examples=150, deadline=None)
@given(un0=st.floats(-2e-5, 2e-5), dun=st.floats(-2e-6, 2e-6),
       g=st.tuples(*[st.floats(-3e5, 3e5)] * 2), ds=st.tuples(*[st.floats(-1e-4, 1e-4)] * 2),
       area=st.sampled_from([0.05, 1.0, 0.0, -1e-18]), failed=st.booleans(),
       dil0=st.sampled_from([0.0, 1e-6]))
def test_booked_dissipation_is_the_energy_difference(name, un0, dun, g, ds, area, failed, dil0):
    params = COULOMB[name]
    law, laws = _laws(params)
    dil0 = dil0 if params.dilation > 0.0 else 0.0
    # the carried shear force and the increment lie in the plane (normal z), as in the loop
    g = np.array([g[0], g[1], 0.0])
    ds = np.array([ds[0], ds[1], 0.0])
    st0 = np.uint8(2 if failed else 0)
    booked, plain, scale, _, _ = _step(laws, un0, dil0, g, st0, dun, ds, area)
    # the two forms are the same sum regrouped: they agree to the rounding of its terms
    assert abs(booked - plain) <= 1e-12 * scale + 1e-300, (booked, plain, scale)


@pytest.mark.parametrize("name", sorted(COULOMB))
def test_elastic_step_dissipates_nothing(name):
    params = COULOMB[name]
    _, laws = _laws(params)
    # a compressed, sticking sub-contact loaded further in both directions: nothing yields
    g = np.array([1e4, -2e4, 0.0])
    ds = np.array([1e-7, 3e-7, 0.0])
    booked, plain, scale, state, _ = _step(laws, 1e-5, 0.0, g, np.uint8(0), 2e-7, ds, 1.0)
    assert state == 0
    assert abs(booked) <= 1e-15 * scale  # the springs' own rounding
    assert abs(plain) <= 1e-12 * scale  # the plain form, for comparison: its cancellation


def test_slip_dissipates_friction_times_slip():
    # a frictional joint at its limit slips by ds less the elastic part: the booked
    # dissipation is tan(phi) fn |slip| (fn constant over the step), positive
    params = COULOMB["frictional"]
    _, laws = _laws(params)
    kn, ks, area = params.kn, params.ks, 1.0
    un0 = 1e-5
    fn = kn * area * un0
    limit = math.tan(math.radians(params.friction)) * fn
    g = np.array([limit, 0.0, 0.0])  # at the limit already
    ds = np.array([-4e-6, 0.0, 0.0])  # pushed on in the same direction (force opposes ds)
    booked, _, _, state, _ = _step(laws, un0, 0.0, g, np.uint8(1), 0.0, ds, area)
    assert state & 1  # slipping
    assert booked == pytest.approx(limit * 4e-6, rel=1e-12)
    assert ks > 0


@settings(max_examples=60, deadline=None)
@given(un0=st.floats(1e-6, 2e-5), dun=st.floats(-1e-6, 1e-6),
       g=st.tuples(*[st.floats(-3e5, 3e5)] * 2), ds=st.tuples(*[st.floats(-1e-4, 1e-4)] * 2))
def test_law_without_a_kernel_books_its_energy_difference(un0, dun, g, ds):
    # continuously yielding has no dissipation kernel: the fallback is the plain form itself
    _, laws = _laws(CYParams(kn=1e10, ks=5e9, friction=30.0))
    g = np.array([g[0], g[1], 0.0])
    ds = np.array([ds[0], ds[1], 0.0])
    booked, plain, _, _, _ = _step(laws, un0, 0.0, g, np.uint8(0), dun, ds, 1.0)
    assert booked == plain
