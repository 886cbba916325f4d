"""Kernel records are filled by field name from the declarations (pdem.model.fields): every
field of a block-side record is a declared block field, every field of a contact-side record
(Pairs, Subs, Planes) a declared contact or sub-contact field or the contacts' CSR start (its
own name or its declared ``kernel`` name), and the record holds the store's own arrays (views
of its rows), so a kernel writes into the store."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.cases import make_simulation
from pdem.contact.detect import Planes
from pdem.contact.rigid import Bodies
from pdem.cycle import motion_record
from pdem.dynamics.motion import Motion
from pdem.model.contacts import PAIR_COLUMNS, PLANE_COLUMNS, SUB_COLUMNS, Pairs, Subs
from pdem.model.fields import (
    BLOCK_BY_NAME,
    CONTACT,
    CONTACT_KERNEL_FIELDS,
    KERNEL_FIELDS,
    SUB,
    SUB_GRID,
    SUB_HIST,
    kernel_record,
)

SCENE = """
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, 0.0], max: [0.5, 0.5, 1.0]}, material: rock,
     force: [1.0, 2.0, 3.0]}
solve: {steps: 3}
"""


@pytest.mark.parametrize("record", [Motion, Bodies])
def test_every_record_field_is_a_declared_block_field(record):
    for name in record._fields:
        assert name in KERNEL_FIELDS, f"{record.__name__}.{name} is not a declared block field"
        assert KERNEL_FIELDS[name] in BLOCK_BY_NAME


def test_records_hold_the_stores_arrays():
    sim = make_simulation(SCENE)
    b = sim.blocks
    m = motion_record(b, 2)
    for name in Motion._fields:
        field = getattr(b, KERNEL_FIELDS[name])
        assert np.shares_memory(getattr(m, name), field)
        assert np.array_equal(getattr(m, name), field[:2])
    assert np.array_equal(m.applied[1], [1.0, 2.0, 3.0])  # applied_force, by its kernel name
    bodies = kernel_record(Bodies, b)
    assert all(getattr(bodies, k) is getattr(b, KERNEL_FIELDS[k]) for k in Bodies._fields)
    held = kernel_record(Motion, b, 2, fixed=b.still)
    assert np.shares_memory(held.fixed, b.still)


CONTACT_FIELDS = {f.name for f in CONTACT + SUB + (SUB_HIST, SUB_GRID)}


def test_the_contact_kernel_names_are_distinct():
    fields = CONTACT + SUB + (SUB_HIST, SUB_GRID)
    names = [f.name for f in fields] + [f.kernel for f in fields if f.kernel]
    assert len(names) == len(set(names))


@pytest.mark.parametrize("record, columns", [(Pairs, PAIR_COLUMNS), (Subs, SUB_COLUMNS),
                                             (Planes, PLANE_COLUMNS)])
def test_every_contact_record_field_is_a_declared_field(record, columns):
    assert len(columns) == len(record._fields)
    for name, column in zip(record._fields, columns, strict=True):
        if name == "sc_start":  # the CSR start: the store's own
            assert column == "sc_start"
            continue
        assert name in CONTACT_KERNEL_FIELDS, f"{record.__name__}.{name} is not a declared field"
        assert column == CONTACT_KERNEL_FIELDS[name] in CONTACT_FIELDS


def test_every_sub_contact_field_is_in_the_sub_contact_record():
    """A contact geometry update (pdem.contact.detect.refresh_contacts) makes the sub-contacts
    afresh from the :data:`Subs` columns: a sub-contact field outside them would be dropped by
    the first update (the zoned blocks' ``sc_grid`` is carried beside it,
    pdem.deformable.subcontacts.carry_grid_columns)."""
    assert set(SUB_COLUMNS) == {f.name for f in SUB + (SUB_HIST,)}


def test_contact_records_hold_the_stores_arrays():
    sim = make_simulation(SCENE)
    c = sim.contacts
    assert c.n and c.n_sub
    for record, columns in ((c.pairs(), PAIR_COLUMNS), (c.subs(), SUB_COLUMNS),
                            (c.planes(), PLANE_COLUMNS)):
        for value, column in zip(record, columns, strict=True):
            assert value is getattr(c, column)
    assert c.subs().un is c.sub["sc_un"] and c.planes().gap is c.arrays["gap"]
    assert c.pairs().sc_start is c.sc_start
