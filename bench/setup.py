"""Set-up benchmark: time and peak memory to build a model of N cubes and take its first step.

The model is the cube stack of bench/cube_stack.py (pdem.cases.stacks): n x n x n unit cubes
(one ``array:`` entry) on a fixed floor, N = n^3. Each size runs in a fresh process (its own
peak memory); the numba kernels are loaded once on a small model first, so the figures are
the set-up itself, not the kernels' load from the cache (about 0.5 s more on a cold process).

    .venv/bin/python bench/setup.py                 # N = 8,000 and 64,000 on 1 rank
    .venv/bin/python bench/setup.py --ranks 2       # the same under mpiexec -n 2
    .venv/bin/python bench/setup.py --n 20 40 100   # N = 8e3, 6.4e4 and 1e6 (memory: ~GB)

Prints per phase the seconds (slowest rank) and the memory per rank (MB, the largest over the
ranks): resident (RSS: its peak, from getrusage, and after set-up) and proportional (PSS:
shared pages split among the processes sharing them; the peak sampled by a thread every 10 ms,
longer for a large process, so a short spike can be missed). Ranks on one node share the libraries' pages
(numba's LLVM is ~66 MB of every rank's RSS): the node holds the sum of the ranks' PSS, so PSS
is a rank's share of the node's memory, and RSS counts the shared pages once per rank. Run it
against another tree with PYTHONPATH=that/tree to compare before and after a change. Issue
11's target: 64,000 blocks to the first step within 10 s on 2 ranks, <= 400 MB per rank.
Not a test: timings on shared machines are noisy.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

from pdem.memory import proportional_mb, resident_mb

STEPS = 20  # steps timed after set-up (block-steps/s of the whole run)
PHASES = ("parse", "preflight", "expand_blocks", "block_store", "resolve", "check_derived",
          "overlaps", "start", "first_step")


def _timed(times, key, fn):
    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            times[key] = times.get(key, 0.0) + time.perf_counter() - t0
    return wrapper


class PeakSampler:
    """The largest PSS seen, sampled by a thread (the kernels release the GIL: the thread runs
    during them too) every ``period`` seconds, or 4x as long as the last sample took: reading
    a large process's ``smaps_rollup`` walks its page tables and holds its memory map, which
    would slow the set-up's page faults (10^6 blocks: seconds)."""

    def __init__(self, period: float = 0.01):
        self.peak = proportional_mb()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(period,), daemon=True)
        self._thread.start()

    def _run(self, period: float) -> None:
        wait = period
        while not self._stop.wait(wait):
            t0 = time.perf_counter()
            self.peak = max(self.peak, proportional_mb())
            wait = max(period, 4.0 * (time.perf_counter() - t0))

    def stop(self) -> float:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, proportional_mb())
        return self.peak


def scene_bytes(state) -> int:
    """Bytes of what a rank keeps for every scene block (counted by ``nbytes``): the scene
    store's per-block fields (pdem.state.RUN_CATALOGUE), the spec columns and the names."""
    import numpy as np

    kept = sum(a.nbytes for a in vars(state.glob).values() if isinstance(a, np.ndarray))
    return kept + state.specs.nbytes


def child(n: int) -> None:
    """Build the n^3 model on MPI.COMM_WORLD, step once; print one JSON line (rank 0)."""
    from mpi4py import MPI

    import pdem.state as st
    from pdem.cases.stacks import cube_stack_scene
    from pdem.config import parse_scene
    from pdem.simulation import Simulation
    from pdem.stepper import Stepper

    comm = MPI.COMM_WORLD
    # load the kernels (numba cache) on a small model: not the set-up's cost
    Simulation(parse_scene(cube_stack_scene(2, "fast")), comm, output=False).run(steps=1)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    times: dict[str, float] = {}
    # the phases of ModelState.create and Simulation, timed where pdem.state calls them
    for name in ("preflight", "expand_blocks", "block_store", "resolve", "check_derived"):
        setattr(st, name, _timed(times, name, getattr(st, name)))
    orig_overlaps, orig_start = st.ModelState.check_initial_overlaps, Stepper.start
    st.ModelState.check_initial_overlaps = _timed(times, "overlaps", orig_overlaps)
    Stepper.start = _timed(times, "start", orig_start)
    comm.Barrier()
    sampler = PeakSampler()
    t0 = time.perf_counter()
    text = cube_stack_scene(n, "fast")
    if os.environ.get("PDEM_BENCH_MEMORY"):  # --memory: the pre-flight's limit per rank
        text += f"limits: {{max_memory_per_rank: {os.environ['PDEM_BENCH_MEMORY']}}}\n"
    scene = parse_scene(text)
    times["parse"] = time.perf_counter() - t0
    sim = Simulation(scene, comm, output=False)
    t1 = time.perf_counter()
    sim.run(steps=1)
    times["first_step"] = time.perf_counter() - t1
    times["total"] = time.perf_counter() - t0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    now = resident_mb()  # what the run keeps once set up
    comm.Barrier()  # every rank set up: the shared pages are shared
    pss_now = proportional_mb()
    pss_peak = sampler.stop()
    sim.run(steps=1)  # the second step leaves the start's one-off work behind
    t2 = time.perf_counter()
    sim.run(steps=STEPS)
    rate = (sim.state.glob.n - 1) * STEPS / (time.perf_counter() - t2)
    rows = comm.gather((times, rss, rss0, sim.state.glob.n - 1, now, rate, pss_now, pss_peak,
                        scene_bytes(sim.state) / sim.state.glob.n), root=0)
    if comm.rank == 0:
        out = {k: max(r[0].get(k, 0.0) for r in rows) for k in (*PHASES, "total")}
        out.update(n=n, cubes=rows[0][3], ranks=comm.size, peak_mb=max(r[1] for r in rows),
                   base_mb=max(r[2] for r in rows), steady_mb=max(r[4] for r in rows),
                   rate=min(r[5] for r in rows), pss_mb=max(r[6] for r in rows),
                   pss_peak_mb=max(r[7] for r in rows), scene_b=max(r[8] for r in rows))
        print("RESULT " + json.dumps(out), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[20, 40],
                    help="cubes per side (N = n^3); default 20 40")
    ap.add_argument("--ranks", type=int, default=1, help="MPI ranks (mpiexec), default 1")
    ap.add_argument("--memory", help="limits.max_memory_per_rank for the pre-flight (e.g. 10GiB; "
                    "its estimate is conservative: it assumes a denser packing than the stack's)")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        child(args.child)
        return
    if args.memory:
        os.environ["PDEM_BENCH_MEMORY"] = args.memory
    py = sys.executable
    mpiexec = Path(py).with_name("mpiexec")
    results = []
    for n in args.n:
        cmd = [py, __file__, "--child", str(n)]
        if args.ranks > 1:
            cmd = [str(mpiexec), "-n", str(args.ranks), *cmd]
        proc = subprocess.run(cmd, capture_output=True, text=True, env=os.environ)
        line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
        if proc.returncode or not line:
            print(f"n={n}: failed (exit {proc.returncode})\n{proc.stderr[-2000:]}")
            continue
        results.append(json.loads(line[0][7:]))
    if not results:
        return
    print(f"set-up to the first step, cube stack, {args.ranks} rank(s); seconds (slowest rank), "
          "MB per rank: resident (peak, after loading the kernels: base, after set-up) and "
          "proportional (PSS: shared pages split among the ranks)")
    head = f"{'phase':>14}" + "".join(f"{r['cubes']:>12,}" for r in results)
    print(head)
    for k in (*PHASES, "total"):
        print(f"{k:>14}" + "".join(f"{r[k]:>12.2f}" for r in results))
    print(f"{'peak MB':>14}" + "".join(f"{r['peak_mb']:>12.0f}" for r in results))
    print(f"{'base MB':>14}" + "".join(f"{r['base_mb']:>12.0f}" for r in results))
    print(f"{'KB per block':>14}" + "".join(
        f"{1024.0 * (r['peak_mb'] - r['base_mb']) / r['cubes']:>12.1f}" for r in results))
    print(f"{'after set-up MB':>14}" + "".join(f"{r['steady_mb']:>12.0f}" for r in results))
    print(f"{'scene B/block':>14}" + "".join(f"{r.get('scene_b', 0.0):>12.1f}" for r in results)
          + "   (kept on every rank for every scene block: catalogue, spec columns, names)")
    print(f"{'PSS peak MB':>14}" + "".join(f"{r['pss_peak_mb']:>12.0f}" for r in results))
    print(f"{'PSS after MB':>14}" + "".join(f"{r['pss_mb']:>12.0f}" for r in results))
    print(f"{'block-steps/s':>14}" + "".join(f"{r['rate']:>12.3g}" for r in results)
          + f"   (per rank: / {args.ranks}; {STEPS} steps after the first two)")


if __name__ == "__main__":
    main()
