"""Load balance: the uniform rank grid against the weighted RCB (``parallel.balance``) on a
skewed scene, the corner pile (pdem.cases.corner_pile: random polyhedra crowded in one corner of
a wide floor, thrown towards the opposite one, spreading and settling).

    python bench/balance.py [--count 400] [--steps 3000] [--ranks 2] [--rebalance 1.2]

Launches itself under ``mpiexec -n RANKS`` once per decomposition and prints, at six points of
the run, the blocks each rank owns, its work (the blocks' weights: 1 + their contacts,
pdem.parallel.decomposition.block_work) and the imbalance max / mean of each; then the wall
time, the rebuilds and rebalances, each rank's compute time (the CPU time of its timed phases
that are not messages: the busiest rank is the critical path) and whether the two runs ended in bitwise
the same state (they must: the decomposition changes the speed only). On an oversubscribed
machine the wall times say little; the imbalance and the busiest rank are the figures.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
import types

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLES = 6
COMPUTE = ("motion", "forces", "search", "contacts")  # the timed phases that are not messages


def worker(args) -> None:
    from mpi4py import MPI

    from pdem import timers
    from pdem.cases.corner_pile import corner_pile_scene
    from pdem.config import parse_scene
    from pdem.parallel.decomposition import block_work
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    # the phase timers count this process's CPU time, not the wall clock: on a shared,
    # oversubscribed machine the time a rank is descheduled says nothing of its work
    timers.time = types.SimpleNamespace(perf_counter=time.process_time)
    scene = parse_scene(corner_pile_scene(args.count, args.steps, args.balance, args.rebalance))
    t0 = time.perf_counter()
    sim = Simulation(scene, comm, output=False)
    setup = time.perf_counter() - t0
    s = sim.state
    s.timers.reset()
    rows = []
    elapsed = 0.0
    for k in range(SAMPLES + 1):
        if k:
            comm.Barrier()
            t0 = time.perf_counter()
            sim.run(steps=args.steps // SAMPLES)
            comm.Barrier()
            elapsed += time.perf_counter() - t0
        rep = s.load_report()
        work = comm.allgather(int(block_work(s.blocks, s.n_owned, s.contacts).sum()))
        rows.append({"step": s.step, "owned": rep["owned"], "work": work,
                     "contacts": rep["contacts"], "ghosts": rep["ghosts"]})
    n = s.n_owned
    gids = np.concatenate(comm.allgather(s.blocks.gid[:n]))
    state = np.concatenate(comm.allgather(np.hstack([s.blocks.x[:n], s.blocks.v[:n]])))
    digest = hashlib.sha256(state[np.argsort(gids)].tobytes()).hexdigest()[:16]
    rebalanced = getattr(s.decomp, "n_balanced", 0)
    # each rank's own work (not waiting for the others): the critical path is the busiest rank
    busy = comm.allgather(sum(s.timers.total.get(k, 0.0) for k in COMPUTE))
    if comm.rank == 0:
        print("RESULT " + json.dumps({
            "balance": args.balance, "decomp": s.decomp.describe(), "blocks": s.glob.n,
            "setup": setup, "elapsed": elapsed, "rows": rows, "rebuilds": s.n_rebuilds,
            "rebalanced": rebalanced, "digest": digest, "busy": busy}), flush=True)


def launch(balance: str, args) -> dict:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PMI_", "PMIX_", "MPI", "HYDRA"))}
    env.update(OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    mpiexec = os.path.join(os.path.dirname(sys.executable), "mpiexec")
    cmd = [mpiexec, "-n", str(args.ranks), sys.executable, os.path.abspath(__file__), "--worker",
           "--balance", balance, "--count", str(args.count), "--steps", str(args.steps),
           "--rebalance", str(args.rebalance)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        sys.exit(f"mpiexec -n {args.ranks} ({balance}) failed ({proc.returncode}):\n"
                 f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def imbalance(values) -> float:
    v = np.asarray(values, float)
    return float(v.max() / v.mean()) if v.mean() > 0 else 1.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=400)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--rebalance", type=float, default=1.2)
    ap.add_argument("--balance", default="rcb")
    ap.add_argument("--worker", action="store_true")
    args = ap.parse_args()
    if args.worker:
        worker(args)
        return
    runs = []
    for balance in ("uniform", "rcb"):
        print(f"-- mpiexec -n {args.ranks}: corner pile of {args.count} blocks, {args.steps} "
              f"steps, balance {balance} ...", flush=True)
        runs.append(launch(balance, args))
    print(f"\ncorner pile, {runs[0]['blocks']} blocks, {args.ranks} ranks, parallel.rebalance "
          f"{args.rebalance}; cores here: {os.cpu_count()}")
    print(f"{'balance':>8} {'step':>6} {'owned blocks':>22} {'imb':>6} {'work':>24} {'imb':>6}")
    for r in runs:
        for row in r["rows"]:
            print(f"{r['balance']:>8} {row['step']:6d} {str(row['owned']):>22} "
                  f"{imbalance(row['owned']):6.2f} {str(row['work']):>24} "
                  f"{imbalance(row['work']):6.2f}")
    print()
    for r in runs:
        mean_imb = np.mean([imbalance(row["work"]) for row in r["rows"][1:]])
        print(f"{r['balance']:>8}: {r['decomp']}; set-up {r['setup']:.1f} s, run "
              f"{r['elapsed']:.1f} s, rebuilds {r['rebuilds']}, rebalanced {r['rebalanced']}, "
              f"mean work imbalance {mean_imb:.2f}, final state {r['digest']}")
        print(f"{'':>8}  compute CPU time per rank (motion, forces, search, contacts) "
              f"{[round(b, 1) for b in r['busy']]} s: busiest {max(r['busy']):.1f} s")
    same = len({r["digest"] for r in runs}) == 1
    print(f"final states bitwise identical: {same}")
    if not same:
        sys.exit(1)


if __name__ == "__main__":
    main()
