"""Pile benchmark: N random convex polyhedra (like configs/default.yaml) dropped into a box and
settling under gravity. Prints block-steps/s, contacts and the per-phase timers on one core.

    .venv/bin/python bench/pile.py [count=300] [steps=2000] [--algorithm fast|cundall]
        [--settle 10000]

The box floor is sized for about four layers of blocks, so contacts form, break and re-form
while the pile falls and settles (unlike the cube stack, which sits in contact from step 0).
``--settle`` steps run untimed first (the blocks start apart, up to one block size above each
other, and need ~10^4 steps to land), so the timed steps see a pile in contact. Not a test:
timings on shared machines are noisy.
"""

from __future__ import annotations

import argparse
import math
import time

from mpi4py import MPI

from pdem.config import parse_scene
from pdem.simulation import Simulation

SIZE = (0.45, 0.6)  # block diameters, m (configs/default.yaml)


def scene_text(count: int, algorithm: str, seed: int = 7) -> str:
    # lattice sites of SIZE[1], a square footprint holding about 4 layers, drop region above
    side = max(2, math.ceil(math.sqrt(count / 4.0)))
    half = 0.5 * side * SIZE[1] + 0.1
    layers = math.ceil(count / side**2)
    top = 0.1 + layers * SIZE[1] + 0.01
    wall = 0.5
    height = top
    box = "{{name: {}, material: rock, fixed: true, box: {{min: [{}, {}, {}], max: [{}, {}, {}]}}}}"
    out = half + wall
    walls = "\n".join("  - " + box.format(*w) for w in [
        ("floor", -out, -out, -0.5, out, out, 0.0),
        ("wall-x0", -out, -out, 0.0, -half, out, height),
        ("wall-x1", half, -out, 0.0, out, out, height),
        ("wall-y0", -half, -out, 0.0, half, -half, height),
        ("wall-y1", -half, half, 0.0, half, out, height)])
    r0 = -half + 0.1 - 1e-9
    r1 = half - 0.1 + 1e-9
    return f"""
name: pile-{count}
gravity: [0.0, 0.0, -9.81]
materials: {{rock: {{density: 2600.0}}}}
joints: {{default: {{kn: 1.0e8, ks: 5.0e7, friction: 30.0}}}}
contact: {{algorithm: {algorithm}}}
blocks:
{walls}
  - name: rock
    random:
      count: {count}
      region: {{min: [{r0}, {r0}, 0.1], max: [{r1}, {r1}, {top}]}}
      size: [{SIZE[0]}, {SIZE[1]}]
      vertices: 10
      seed: {seed}
    material: rock
solve: {{steps: 1, damping: local}}
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("count", type=int, nargs="?", default=300)
    ap.add_argument("steps", type=int, nargs="?", default=2000)
    ap.add_argument("--algorithm", default="fast")
    ap.add_argument("--settle", type=int, default=10000)
    args = ap.parse_args()
    t0 = time.perf_counter()
    solver = Simulation(parse_scene(scene_text(args.count, args.algorithm)), MPI.COMM_SELF,
                    output=False)
    t_setup = time.perf_counter() - t0
    solver.run(steps=20 + args.settle)  # warm-up (compilation is cached after the first run)
    solver.state.timers.reset()
    c0 = solver.contacts.n
    t0 = time.perf_counter()
    solver.run(steps=args.steps)
    el = time.perf_counter() - t0
    nb = args.count
    print(f"pile of {nb} random polyhedra, algorithm={args.algorithm}, dt={solver.dt:.3g} s")
    print(f"set-up {t_setup:.2f} s; {args.steps} steps in {el:.3f} s "
          f"(model time {args.steps * solver.dt:.3g} s)")
    print(f"contacts {c0} -> {solver.contacts.n}, {solver.contacts.n_sub} sub-contacts")
    print(f"block-steps/s      {nb * args.steps / el:12.4g}")
    print(solver.state.timers.report())


if __name__ == "__main__":
    main()
