"""Cube stack benchmark: N = n x n x n unit cubes on a fixed floor under gravity, every cube
in face contact from step 0. Prints block-steps/s and sub-contact-steps/s on one core.

    .venv/bin/python bench/cube_stack.py [n=10] [steps=500] [--algorithm fast|cundall]
                                         [--repeat R]

Issue floor 2e5 block-steps/s, target 1e6. Not a test: timings on shared machines are noisy.
Measured (2026-11-23, 2 shared cores under load, alternating with the tree before):
``PYTHONPATH=. .venv/bin/python bench/cube_stack.py 20 300`` 4.0e5 -> 4.3e5 block-steps/s
(1.07-1.09x on CPU time); the step is contact forces ~57%, contact updates ~40%, motion ~5%
(docs/validation.md, Benchmarks). 2026-11-25, the contact update 1.4x cheaper per contact
(same bits): 3.7-3.8e5 -> 4.2-4.3e5 block-steps/s on CPU time (machine under load 3-4);
with contacts re-detected by the motion of B relative to A (pdem.contact.staleness) too:
7.0-7.1e5 against 3.9-4.1e5 for the tree before both (quiet machine, alternating, 2026-11-25).
Later: the force loop's roots near 1 by series (docs/validation.md): defaults (n=10)
9.4-9.9e5 against 8.6-9.3e5, 20 300: 8.9-9.3e5 against 8.5-8.9e5 (alternating, 2026-11-25).
2026-11-27, the staleness marks reused, short runs copied by row, separated sub-contacts
skipping their law: CPU time of 500 steps 0.517 s (median 0.548) against 0.560 (0.599), 12 runs
each alternating; best 9.1e5 block-steps/CPU-s on that host (docs/validation.md).
Later that day, the periodic contact updates inside the compiled loop (pdem.contact.update):
0.476 s (median 0.523) against 0.487 (0.541), 24 runs each alternating; best 1.05e6
block-steps/CPU-s, the target, in the best runs of this host, not in every run.
"""

from __future__ import annotations

import argparse
import statistics
import time

from mpi4py import MPI

from pdem.cases.stacks import cube_stack_scene
from pdem.config import parse_scene
from pdem.simulation import Simulation


def one_run(args):
    """Set up the stack and time ``args.steps`` steps after a 20-step warm-up: (set-up s, wall
    s, CPU s, the solver)."""
    t0 = time.perf_counter()
    solver = Simulation(parse_scene(cube_stack_scene(args.n, args.algorithm)), MPI.COMM_SELF,
                        output=False)
    t_setup = time.perf_counter() - t0
    solver.run(steps=20)  # warm-up (compilation is cached after the first run)
    solver.state.timers.reset()
    t0, c0 = time.perf_counter(), time.process_time()
    solver.run(steps=args.steps)
    return t_setup, time.perf_counter() - t0, time.process_time() - c0, solver


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("n", type=int, nargs="?", default=10)
    ap.add_argument("steps", type=int, nargs="?", default=500)
    ap.add_argument("--algorithm", default="fast")
    ap.add_argument("--repeat", type=int, default=1,
                    help="the same run this many times: prints each, then the best and median")
    args = ap.parse_args()
    rates = []
    for _ in range(args.repeat):
        t_setup, el, cpu, solver = one_run(args)
        nb = solver.blocks.n - 1
        nsub = solver.contacts.n_sub
        print(f"cube stack {args.n}^3 = {nb} cubes, {solver.contacts.n} contacts, {nsub} "
              f"sub-contacts, algorithm={args.algorithm}")
        print(f"set-up {t_setup:.2f} s; {args.steps} steps in {el:.3f} s ({cpu:.3f} s CPU)")
        print(f"block-steps/s      {nb * args.steps / el:12.4g}")
        # on a shared host the wall clock counts the other tenants' turns too
        print(f"block-steps/CPU-s  {nb * args.steps / cpu:12.4g}")
        print(f"sub-contact-steps/s {nsub * args.steps / el:12.4g}")
        print(solver.state.timers.report())
        rates.append(nb * args.steps / cpu)
    if args.repeat > 1:
        # the same work each time: the spread is the host's (shared cores, frequency)
        print(f"block-steps/CPU-s over {args.repeat} runs: best {max(rates):.4g}, median "
              f"{statistics.median(rates):.4g}, worst {min(rates):.4g}")


if __name__ == "__main__":
    main()
