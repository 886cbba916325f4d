"""Kernel records are filled by field name from the declarations (pdem.model.fields): every
field of a block-side record is a declared block field (its own name or its declared
``kernel`` name), and the record holds the store's own arrays (views of its rows), so a
kernel writes into the store."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.cases import make_simulation
from pdem.contact.rigid import Bodies
from pdem.cycle import motion_record
from pdem.dynamics.motion import Motion
from pdem.model.fields import BLOCK_BY_NAME, KERNEL_FIELDS, kernel_record

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
