"""The cube stack of the benchmarks (bench/cube_stack.py, bench/scaling.py): n x n x n unit
cubes on a fixed floor under the default gravity, every cube in face contact from step 0."""

from __future__ import annotations


def cube_stack_scene(n: int, algorithm: str, damping: str = "local") -> str:
    """The n^3 cube stack on the floor ``[-1, n+1]^2 x [-1, 0]``; one step (callers set the
    number of steps with ``run(steps=...)``)."""
    return f"""
name: cube-stack-{n}
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30.0}}}}
contact: {{algorithm: {algorithm}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [{n + 1}, {n + 1}, 0]}}, material: rock, fixed: true}}
  - name: cube
    array: {{box: {{min: [0, 0, 0], max: [1, 1, 1]}}, count: [{n}, {n}, {n}], spacing: [1, 1, 1]}}
    material: rock
solve: {{steps: 1, damping: {damping}}}
"""
