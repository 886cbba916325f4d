"""A skewed scene for the load balance (bench/balance.py, tests/mpi/test_balance_mpi.py): random
polyhedra crowded in one corner of a wide fixed floor and thrown towards the opposite corner,
so that they first crowd the corner and then spread and settle. A uniform rank grid leaves most
ranks with little to do; ``parallel.balance: rcb`` follows the blocks."""

from __future__ import annotations


def corner_pile_scene(count: int = 400, steps: int = 3000, balance: str = "rcb",
                      rebalance: float | None = 1.2, seed: int = 4, margin: float = 0.2,
                      velocity=(2.0, 1.0, -0.5)) -> str:
    """``count`` random polyhedra (0.35-0.45 m, on layers of 6 x 6 lattice sites 0.5 m apart)
    in the corner ``[-3.9, -0.9]^2`` of the floor ``[-4, 4]^2``, the lowest 5 cm above it,
    thrown at ``velocity``; local damping, ``steps`` steps, a snapshot every quarter."""
    height = 0.5 * -(-count // 36)
    par = f"balance: {balance}, rebalance: {'null' if rebalance is None else rebalance}"
    v = ", ".join(repr(float(c)) for c in velocity)
    return f"""
name: corner-pile
materials: {{rock: {{density: 2600.0}}}}
joints: {{default: {{kn: 3.0e7, ks: 1.5e7, friction: 20.0}}}}
blocks:
  - {{name: floor, box: {{min: [-4, -4, -0.5], max: [4, 4, 0]}}, material: rock, fixed: true}}
  - name: rock
    random: {{count: {count}, region: {{min: [-3.9, -3.9, 0.05], max: [-0.9, -0.9, {height + 0.05}]}},
              size: [0.35, 0.45], vertices: 10, seed: {seed}}}
    material: rock
    velocity: [{v}]
parallel: {{{par}, margin: {margin}}}
solve: {{steps: {steps}, damping: {{mode: local, alpha: 0.8}}}}
output: {{every_steps: {max(1, steps // 4)}}}
"""
