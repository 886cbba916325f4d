"""Inactive blocks (solve.inactive) give bitwise the 1-rank run on several ranks: a stack
spanning the rank split settles and is held, then a dropped cube lands on it and wakes its
neighbours across the split (their hold state and held joint forces travel with the halo).

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_inactive_mpi.py``.
"""

from __future__ import annotations

import pytest
from support import TWO_RANKS_ONLY, slabs_match_one_rank

pytestmark = [pytest.mark.mpi(min_size=2), TWO_RANKS_ONLY, pytest.mark.timeout(300, method="thread")]

SCENE = """
materials: {rock: {density: 2500.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-1, -1, -1], max: [5, 3, 0]}, material: rock, fixed: true}
  - name: cube
    array: {box: {min: [0, 0, 0], max: [1, 1, 1]}, count: [4, 2, 2], spacing: [1, 1, 1]}
    material: rock
  - {name: drop, box: {min: [1.5, 0.0, 2.03], max: [2.5, 1.0, 3.03]}, material: rock}
solve: {steps: 4000, damping: local, inactive: {speed: 1.0e-4, steps: 100, force: 0.01}}
"""


def test_held_stack_woken_across_the_split_matches_one_rank(tmp_path):
    slabs_match_one_rank(tmp_path, SCENE, "held", 250)


# the same with a zoned cube standing on the stack (the dropped cube lands on it): rigid
# blocks held and woken across the split, the zoned one never held (its grid steps on), bitwise
# the 1-rank run
ZONED = SCENE.replace(
    "materials: {rock: {density: 2500.0}}",
    "materials: {rock: {density: 2500.0}, soft: {density: 2500.0, young: 1.0e9, poisson: 0.25}}"
).replace(
    "  - {name: drop,",
    "  - {name: z, box: {min: [1.5, 0.0, 2.0], max: [2.5, 1.0, 3.0]}, material: soft, "
    "zones: {size: 0.5}}\n  - {name: drop,"
).replace("min: [1.5, 0.0, 2.03], max: [2.5, 1.0, 3.03]", "min: [1.5, 0.0, 3.03], max: [2.5, 1.0, 4.03]"
          ).replace("steps: 4000", "steps: 1500")


def test_held_stack_beside_a_zoned_block_matches_one_rank(tmp_path):
    slabs_match_one_rank(tmp_path, ZONED, "zoned-held", 250)
