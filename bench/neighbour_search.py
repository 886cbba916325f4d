"""Cell-space neighbour search scaling: ``CellSpace.candidates`` on random block envelopes.

    .venv/bin/python bench/neighbour_search.py [--sizes 1000 10000 100000] [--reps 5]

N blocks of random size (0.5-1.5 m, padded envelopes) scattered at random in a box holding
them at about a third solid fraction (so each has a handful of neighbours, like a loose pile),
cell size = mean envelope extent (the solver's ``cell_size: auto``). For each N: the time of a
full search (every block active: map all blocks, then search from all) and of a partial one
(1% of the blocks active, as between remaps), per search and per block. Blocks are numbered
in random order (every cell visit is a cache miss) and, second line, in spatial order (cells
swept in x, y, z order, as blocks generated on a lattice are): a linear search shows a flat
time per block; what grows in random order is memory latency, not work. A partial search still
maps every block (the cell space is rebuilt per search), so its cost per active block grows
with N / active. Not a test: timings on shared machines are noisy.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pdem.contact.cellspace import CellSpace


def envelopes(n: int, rng: np.random.Generator, spatial: bool):
    size = rng.uniform(0.5, 1.5, (n, 3))
    box = (n * float(np.mean(size.prod(axis=1))) / 0.35) ** (1.0 / 3.0)
    centre = rng.uniform(0.0, box, (n, 3))
    if spatial:
        cell = np.floor(centre / 1.0).astype(np.int64)
        centre = centre[np.lexsort((cell[:, 2], cell[:, 1], cell[:, 0]))]
    return centre - 0.5 * size, centre + 0.5 * size


def best_of(cells: CellSpace, lo, hi, active, reps: int) -> float:
    cells.candidates(lo, hi, active)  # compile / warm the caches
    best = np.inf
    for _ in range(reps):
        t0 = time.perf_counter()
        cells.candidates(lo, hi, active)
        best = min(best, time.perf_counter() - t0)
    return best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10_000, 100_000])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"{'N':>8} {'order':>7} {'pairs':>9} {'pairs/N':>7} {'full search':>12} {'per block':>10} "
          f"{'1% active':>10} {'per active':>10}")
    for n, spatial in [(n, s) for n in args.sizes for s in (False, True)]:
        lo, hi = envelopes(n, rng, spatial)
        cells = CellSpace(lo, hi, float(np.mean((hi - lo).max(axis=1))))
        everyone = np.ones(n, np.uint8)
        some = np.zeros(n, np.uint8)
        some[rng.choice(n, max(1, n // 100), replace=False)] = 1
        pi, _ = cells.candidates(lo, hi, everyone)
        t_full = best_of(cells, lo, hi, everyone, args.reps)
        t_some = best_of(cells, lo, hi, some, args.reps)
        order = "spatial" if spatial else "random"
        print(f"{n:8d} {order:>7} {len(pi):9d} {len(pi) / n:7.2f} {t_full * 1e3:10.2f}ms "
              f"{t_full / n * 1e9:8.0f}ns {t_some * 1e3:8.2f}ms "
              f"{t_some / some.sum() * 1e6:8.2f}us")


if __name__ == "__main__":
    main()
