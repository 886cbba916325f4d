"""A separated sub-contact that stays separated skips its joint update (pdem.contact.forces):
each law's ``stays_open`` may say so only when the update would return zero forces and the
same state, to the bit, whatever the shear force and displacements; and the force loop with
the skip gives the same bits as the full update."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from pdem.cases.stacks import cube_stack_scene
from pdem.config import parse_scene
from pdem.contact.forces import contact_forces
from pdem.contact.laws import FAILED, OPEN, SLIPPING, coulomb
from pdem.contact.laws import continuously_yielding as cy
from pdem.simulation import Simulation

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

# overlaps and dilations about the sign change (and exactly at it, both zeros), areas with 0
small = st.one_of(st.sampled_from([0.0, -0.0, 1e-300, -1e-300]),
                  st.floats(-1e-3, 1e-3, allow_nan=False))
areas = st.one_of(st.sampled_from([0.0, -1e-18, 1e-18]), st.floats(0.0, 2.0))
states = st.sampled_from([0, OPEN, FAILED, OPEN | FAILED, SLIPPING, OPEN | SLIPPING,
                          OPEN | FAILED | SLIPPING])
shear = st.floats(-1e6, 1e6, allow_nan=False)
disp = st.floats(-1e-3, 1e-3, allow_nan=False)

COULOMB = [coulomb.Params(kn=1e10, ks=5e9, friction=30.0),
           coulomb.Params(kn=1e10, ks=5e9, friction=35.0, tension=1e5),
           coulomb.Params(kn=1e10, ks=5e9, friction=35.0, cohesion=2e5),
           coulomb.Params(kn=1e10, ks=5e9, friction=35.0, tension=1e5, cohesion=2e5,
                          dilation=5.0)]
LAWS = {
    "coulomb": (coulomb.update, coulomb.stays_open, coulomb.table(COULOMB)),
    "coulomb friction": (coulomb.friction_update, coulomb.friction_stays_open,
                         coulomb.friction_table(COULOMB[:1])),
    "continuously yielding": (cy.update, cy.stays_open, cy.table([
        cy.Params(kn=1e10, ks=5e9, normal_exponent=0.3, shear_exponent=0.2, roughness=1e-3,
                  initial_friction=40.0),
        cy.Params(kn=1e10, ks=5e9)])),
}


def bits(x: float) -> bytes:
    return np.float64(x).tobytes()


@pytest.mark.parametrize("name", LAWS)
@settings(max_examples=400, deadline=None)
@given(data=st.data(), un=small, dil=small, area=areas, state=states, f=st.tuples(shear, shear,
       shear), d=st.tuples(disp, disp, disp), u=st.tuples(disp, disp, disp),
       r=st.sampled_from([0.0, -0.0, 0.3]))
def test_stays_open_only_when_the_update_returns_zero_forces_and_the_same_state(
        name, data, un, dil, area, state, f, d, u, r):
    update, stays_open, table = LAWS[name]
    j = data.draw(st.integers(0, len(table[0]) - 1))
    dil = abs(dil)  # dilation is never negative
    hist = np.array([[1e-4, r, 0.6, 0.0, 0.8]])[:, :5 if name.startswith("continuously")
                                                 else 0].copy()
    if not stays_open(table, j, 0, hist, un, dil, area, state):
        return
    before = hist.copy()
    fn, dil1, st1, fx, fy, fz = update(table, j, 0, hist, un, dil, *f, *d, area, *u, state)
    assert [bits(v) for v in (fn, dil1, fx, fy, fz)] == [bits(v) for v in
                                                        (0.0, dil, 0.0, 0.0, 0.0)]
    assert st1 == state
    assert hist.tobytes() == before.tobytes()


@pytest.mark.parametrize("name", LAWS)
def test_stays_open_says_so_for_a_plainly_separated_joint(name):
    """Not a predicate that is never true: a joint opened a step ago and still 1 mm apart."""
    update, stays_open, table = LAWS[name]
    hist = np.zeros((1, 5 if name.startswith("continuously") else 0))
    _, _, state, *_ = update(table, 0, 0, hist, -1e-3, 0.0, 1.0, 2.0, 3.0, 1e-6, 0.0, 0.0, 0.5,
                             0.0, 0.0, 0.0, 0)
    assert state & OPEN
    assert stays_open(table, 0, 0, hist, -1e-3, 0.0, 0.5, state)
    assert not stays_open(table, 0, 0, hist, 1e-6, 0.0, 0.5, state)  # closed again
    assert not stays_open(table, 0, 0, hist, -1e-3, 0.0, 0.5, state & ~OPEN)  # opens now


def test_force_loop_skip_gives_the_full_updates_bits():
    """The 4³ stack after settling: a fifth or more of its sub-contacts are separated. Clearing
    their OPEN bit makes the loop run the law for them (a state that has just opened); the
    forces, moments, energies and every sub-contact column must come out the same bits as
    with the skip."""
    sim = Simulation(parse_scene(cube_stack_scene(4, "fast")), MPI.COMM_SELF, output=False)
    sim.run(steps=300)
    c, b, s = sim.contacts, sim.blocks, sim.state
    sub = c.sub
    # separated by far more than a step's motion, carrying no shear force: stay so this step
    apart = ((sub["sc_state"] & OPEN) != 0) & (sub["sc_un"] + sub["sc_dil"] < -1e-7) \
        & (sub["sc_fs"] == 0.0).all(1)
    assert apart.mean() > 0.2

    def step(clear_open):
        subs = type(c.subs())(*[a.copy() for a in c.subs()])
        if clear_open:
            subs.state[apart] &= ~np.uint8(OPEN)
        pairs = type(c.pairs())(*[a.copy() if isinstance(a, np.ndarray) else a
                                  for a in c.pairs()])
        body = sim.stepper.bodies()
        body = type(body)(*[a.copy() for a in body])
        body.force[:] = 0.0
        body.moment[:] = 0.0
        contact_forces(s.dt, body, pairs, subs, s.joints.kernel_args, b.still)
        return body, subs, pairs

    skipped, full = step(False), step(True)
    for got, want in zip(skipped, full, strict=True):
        for name, x, y in zip(got._fields, got, want, strict=True):
            assert np.array_equal(x, y) and x.tobytes() == y.tobytes(), name
    assert math.isfinite(float(np.abs(skipped[0].force).sum()))
