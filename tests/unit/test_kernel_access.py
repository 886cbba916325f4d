"""Each kernel states what it reads and writes of the stores (``@access`` above it,
pdem.jit.ACCESS, by declared field name): every name it declares is a block, contact or
sub-contact field (pdem.model.fields), and run on a real scene, called as the stepper calls it,
it changes no field it does not declare as written (bitwise: a field is changed when a byte of
it is). A kernel's result that the caller puts in the store in place of a field (the
re-detected sub-contact columns) counts as a write of that field.

Every declared kernel has its run here: declaring one more means adding its call below."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pdem.simulation  # noqa: F401  (every kernel the runs use, so ACCESS holds them all)
from pdem.cases import make_simulation
from pdem.cases.stacks import cube_stack_scene
from pdem.contact.detect import refresh_contacts
from pdem.contact.forces import book_stored_energy, contact_forces
from pdem.contact.rigid import WORK_GEOMETRY, Bodies
from pdem.contact.staleness import stale_contacts
from pdem.contact.update import begin_update, end_update
from pdem.dynamics import motion
from pdem.dynamics.inactive import update_inactive
from pdem.dynamics.kinematics import rotation_matrices
from pdem.jit import ACCESS
from pdem.model.contacts import Subs, sub_columns
from pdem.model.fields import BLOCK, CONTACT, SUB, SUB_GRID, SUB_HIST, kernel_record

FIELDS = {f.name for f in BLOCK + CONTACT + SUB + (SUB_HIST, SUB_GRID)}


@pytest.fixture(scope="module")
def sim():
    """A 2³ cube stack a few steps after its start, sliding and turning a little (the cubes
    given a sideways velocity and a spin), so its contacts carry overlaps and shear."""
    sim = make_simulation(cube_stack_scene(2, "fast"))
    b, n = sim.blocks, sim.n_owned
    free = b.fixed[:n] == 0
    b.v[:n][free, 0] += 0.01 * (np.arange(n)[free] % 2)
    b.L[:n][free, 2] += 1.0
    for _ in range(5):
        sim.advance()
    return sim


def fields(sim) -> dict[str, np.ndarray]:
    """Every field array of the scene's stores, by name."""
    c = sim.contacts
    return {f.name: getattr(sim.blocks, f.name) for f in BLOCK} | c.arrays | c.sub


def args(sim):
    """What most calls take: the state, the blocks, the owned rows, the contacts and the joint
    tables."""
    s = sim.state
    return s, s.blocks, s.n_owned, s.contacts, s.joints.kernel_args


def all_contacts(sim):
    return np.ones(sim.contacts.n, np.uint8)


# Each run prepares its kernel's call (outside of what is compared) and returns it.

def run_integrate(sim):
    s, b, n, _, _ = args(sim)
    rec = kernel_record(motion.Motion, b, n)
    return lambda: motion.integrate(rec, s.gravity, s.dt, s.damping_args(), s.scalar_inertia,
                                    motion.new_stats())


def run_stagger_start(sim):
    s, b, n, _, _ = args(sim)
    rec = kernel_record(motion.Motion, b, n)
    return lambda: motion.stagger_start(rec, s.gravity, s.dt, s.scalar_inertia)


def run_motion_bookkeeping(sim):
    _, b, n, _, _ = args(sim)
    return lambda: motion.motion_bookkeeping(
        b.dx[:n], b.dtheta[:n], b.radius[:n], b.fixed[:n], b.u_acc[:n], b.u_geo[:n],
        b.u_mig[:n], b.v[:n], b.x[:n], math.inf, math.inf)


def run_update_inactive(sim):
    """Every free block at rest for long enough (one step): held at once."""
    s, b, n, _, _ = args(sim)
    rec = kernel_record(motion.Motion, b, n)
    return lambda: update_inactive(rec, s.gravity, b.radius[:n], b.calm[:n], b.still[:n],
                                   math.inf, 1, math.inf, 1.0)


def run_contact_forces(sim):
    s, b, _, c, joints = args(sim)
    return lambda: contact_forces(s.dt, kernel_record(Bodies, b), c.pairs(), c.subs(), joints,
                                  b.still)


def run_book_stored_energy(sim):
    _, b, _, c, joints = args(sim)
    return lambda: book_stored_energy(kernel_record(Bodies, b), c.pairs(), c.subs(), joints,
                                      all_contacts(sim), WORK_GEOMETRY)


def run_stale_contacts(sim):
    s, b, _, c, _ = args(sim)
    todo = np.empty(c.n, np.uint8)
    return lambda: stale_contacts(b.x, b.q, b.R, b.radius, c.ia, c.ib, c.rel_x, c.rel_q, c.gap,
                                  c.warm, c.sc_start, c.sc_un, s.resolved.refresh_tolerance,
                                  c.moved, todo)


def run_begin_update(sim):
    _, b, _, c, joints = args(sim)
    c.moved[:] = 1.0  # (zeroed by the update)
    up = sim.stepper.geometry_update()
    return lambda: begin_update(b.x, b.q, b.R, up, c.pairs(), c.subs(), joints, c.moved,
                                c.rel_x, c.rel_q, all_contacts(sim))


def run_refresh_contacts(sim):
    _, b, _, c, _ = args(sim)
    up = sim.stepper.geometry_update()
    return lambda: refresh_contacts(b.x, b.R, up.shapes, up.planes, c.sc_start, c.subs(),
                                    all_contacts(sim), up.ctol, up.touch_frac, up.alg, up.trim,
                                    up.in_place)


def run_end_update(sim):
    """After the update's first two calls, as the stepper makes them."""
    _, b, _, c, joints = args(sim)
    up = sim.stepper.geometry_update()
    todo = all_contacts(sim)
    before, new = begin_update(b.x, b.q, b.R, up, c.pairs(), c.subs(), joints, c.moved,
                               c.rel_x, c.rel_q, todo)
    keep, start, *columns = refresh_contacts(b.x, b.R, up.shapes, up.planes, c.sc_start,
                                             c.subs(), todo, up.ctol, up.touch_frac, up.alg,
                                             up.trim, up.in_place)
    return lambda: end_update(b.x, b.R, up, c.pairs()._replace(sc_start=start), Subs(*columns),
                              joints, kernel_record(Bodies, b), todo, keep, new, before, True)


def run_rotation_matrices(sim):
    b = sim.blocks
    b.R[:] = 0.0  # (made again from the orientations)
    return lambda: rotation_matrices(b.q, b.R)


RUNS = {
    "pdem.dynamics.motion.integrate": run_integrate,
    "pdem.dynamics.motion.stagger_start": run_stagger_start,
    "pdem.dynamics.motion.motion_bookkeeping": run_motion_bookkeeping,
    "pdem.dynamics.inactive.update_inactive": run_update_inactive,
    "pdem.dynamics.kinematics.rotation_matrices": run_rotation_matrices,
    "pdem.contact.forces.contact_forces": run_contact_forces,
    "pdem.contact.forces.book_stored_energy": run_book_stored_energy,
    "pdem.contact.staleness.stale_contacts": run_stale_contacts,
    "pdem.contact.update.begin_update": run_begin_update,
    "pdem.contact.detect.refresh_contacts": run_refresh_contacts,
    "pdem.contact.update.end_update": run_end_update,
}


def test_every_declared_kernel_is_run_here():
    assert set(ACCESS) == set(RUNS)


@pytest.mark.parametrize("name", sorted(ACCESS))
def test_declared_names_are_fields(name):
    reads, writes = ACCESS[name]
    assert not set(reads) - FIELDS, f"{name} reads undeclared fields"
    assert not set(writes) - FIELDS, f"{name} writes undeclared fields"
    assert len(set(reads)) == len(reads) and len(set(writes)) == len(writes)


def changed(before: dict, after: dict) -> set[str]:
    """The names whose arrays differ in a byte (or in shape or dtype)."""
    return {k for k, a in before.items()
            if a.shape != after[k].shape or a.dtype != after[k].dtype
            or a.tobytes() != np.ascontiguousarray(after[k]).tobytes()}


@pytest.mark.parametrize("name", sorted(RUNS))
def test_a_kernel_changes_only_the_fields_it_declares(sim, name):
    live = fields(sim)
    kept = {k: a.copy() for k, a in live.items()}  # the scene as it was, put back after
    try:
        call = RUNS[name](sim)
        before = {k: a.copy() for k, a in fields(sim).items()}
        result = call()
        written = changed(before, fields(sim))
        if name.endswith(".refresh_contacts"):  # the new sub-contact columns, for the store's
            _, _, *columns = result
            new = sub_columns(Subs(*columns))
            written |= changed({k: before[k] for k in new}, new)
        undeclared = written - set(ACCESS[name].writes)
        assert not undeclared, f"{name} changes {sorted(undeclared)}, not declared as written"
        assert written, f"{name} changed nothing here: the scene does not test it"
    finally:
        for k, a in fields(sim).items():
            np.copyto(a, kept[k])
