"""Small scenes: steps/s with the compiled loop (``solve.fused``, pdem.cycle) on and off.

    .venv/bin/python bench/fused_loop.py [steps=200000]

A 1-block scene (a cube resting on a fixed floor) and a 10-block scene (a column of ten
cubes on a floor, local damping), one core, no output files, rigid and with the cubes zoned
at 0.5 (162 zones each: the grids step inside the loop, pdem.cycle.fused_grid_steps). Issue
10's floor: 2e5 steps/s for the rigid ones with the loop on. Also prints the result is bitwise
the same either way. Not a test: timings on shared machines are noisy; compare the two
columns of one run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pdem.cases import make_simulation


def column_scene(n: int, fused: bool, zoned: bool = False) -> str:
    cube = "material: soft, zones: {size: 0.5}" if zoned else "material: rock"
    blocks = "\n".join(
        f"  - {{name: c{k}, box: {{min: [-0.5, -0.5, {k}.0], max: [0.5, 0.5, {k + 1}.0]}}, "
        f"{cube}}}" for k in range(n))
    return f"""
name: column{n}
gravity: [0, 0, -9.81]
materials: {{rock: {{density: 2650}}, soft: {{density: 2650, young: 1.0e9, poisson: 0.25}}}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
{blocks}
solve: {{steps: 1000000000, damping: local, fused: {str(fused).lower()}}}
"""


def measure(n_blocks: int, fused: bool, steps: int, zoned: bool = False):
    sim = make_simulation(column_scene(n_blocks, fused, zoned))
    sim.run(steps=2000)  # warm-up: compilation (cached on disk after the first run), settling
    t0 = time.perf_counter()
    sim.run(steps=steps)
    el = time.perf_counter() - t0
    b = sim.blocks
    return steps / el, (b.x.copy(), b.q.copy(), b.v.copy(), b.w.copy())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("steps", type=int, nargs="?", default=200_000)
    args = ap.parse_args()
    print(f"{'scene':10s} {'per step (Python)':>20s} {'fused':>14s} {'speed-up':>9s}  bitwise")
    for zoned in (False, True):
        for n in (1, 10):
            slow_steps = max(1000, args.steps // 20)  # the per-step path is ~20x slower
            # a zoned cube's step is ~100x a rigid one's
            fast_steps = max(1000, args.steps // 20) if zoned else args.steps
            rate_off, _ = measure(n, False, slow_steps, zoned)
            rate_on, _ = measure(n, True, fast_steps, zoned)
            # the same steps both ways must give the same state
            _, a = measure(n, False, slow_steps, zoned)
            _, c = measure(n, True, slow_steps, zoned)
            same = all(np.array_equal(x, y) for x, y in zip(a, c, strict=True))
            label = f"{n:2d} {'zoned' if zoned else 'rigid'}"
            print(f"{label:10s}  {rate_off:14.4g} st/s {rate_on:10.4g} st/s "
                  f"{rate_on / rate_off:8.1f}x  {same}", flush=True)


if __name__ == "__main__":
    main()
