"""Cube stack benchmark: N = n x n x n unit cubes on a fixed floor under gravity, every cube
in face contact from step 0, stepped on one core (``MPI.COMM_SELF``, no output files).

    .venv/bin/python bench/cube_stack.py [n=10] [steps=500] [--algorithm fast|cundall]
                                         [--repeat R]

Each run sets the stack up, takes 20 untimed warm-up steps and times ``steps`` steps. Prints,
per run: the cubes, contacts and sub-contacts and the algorithm; the set-up seconds; the wall
and CPU seconds of the timed steps; block-steps/s (wall), block-steps/CPU-s and
sub-contact-steps/s; and the per-phase timers of the stepper. With ``--repeat R`` (R > 1) the
same run is made R times and the best, median and worst block-steps/CPU-s are printed last:
on a shared host the wall clock counts the other tenants' turns, so compare CPU rates and
medians. To compare two trees, alternate runs with ``PYTHONPATH=that/tree``.

The issue's floor is 2e5 block-steps/s, its target 1e6. The current figures, with their host,
are in docs/validation.md (Benchmarks); every measurement so far, with its date, host, command
and the tree it was compared against, is in bench/results/cube_stack.csv. Not a test: timings
on shared machines are noisy.
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
