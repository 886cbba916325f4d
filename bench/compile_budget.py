"""Cold start: what compiling pdem's kernels costs a run with an empty cache, kernel by kernel.

    .venv/bin/python bench/compile_budget.py [--scene configs/incline.yaml] [--steps 10]
                                             [--ranks 1 2] [--top 15]

Each measurement runs ``--steps`` steps of ``--scene`` in a fresh process with a fresh, empty
kernel cache (``NUMBA_CACHE_DIR`` in a temporary folder), under ``mpiexec -n R`` for each
``--ranks`` R, and prints:

- the wall seconds to the end of the run and to the end of the set-up, the CPU seconds of all
  ranks together and each rank's peak resident memory;
- how many kernels each rank compiled (with pdem.jit's compile lock one rank of a node
  compiles a kernel and the others load it; a rank that compiled nothing waited and loaded);
- for the rank that compiled most: each kernel family's compile seconds, exclusive of the
  kernels it called (compiled in its own entry), and the peak memory when it was done, the
  largest first. The families sum to the compile time; what is left of the wall is set-up,
  stepping and loading.

numba's compile events (``numba:compile``) fire only for a compile, never for a load from the
cache, so a warm run lists nothing. Not a test: compile seconds on a shared machine vary with
its load; compare CPU seconds, measured in one session.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def worker(scene_path: str, steps: int) -> None:
    """One rank: run the scene, recording each compile's exclusive seconds and the peak
    memory after it; print one RESULT line."""
    import numba.core.event as ev
    from mpi4py import MPI

    class Compiles(ev.Listener):
        def __init__(self):
            self.open = []  # [name, start, seconds of nested compiles]
            self.done = []  # (name, exclusive seconds, peak MB after)

        def on_start(self, event):
            fn = event.data["dispatcher"].py_func
            self.open.append([f"{fn.__module__}.{fn.__qualname__}", time.perf_counter(), 0.0])

        def on_end(self, event):
            if not self.open:
                return
            name, t0, nested = self.open.pop()
            took = time.perf_counter() - t0
            if self.open:
                self.open[-1][2] += took
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            self.done.append((name, took - nested, peak))

    seen = Compiles()
    ev.register("numba:compile", seen)
    t0 = time.perf_counter()
    from pdem.config import load_scene
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    sim = Simulation(load_scene(scene_path), comm, output=False)
    setup = time.perf_counter() - t0
    sim.run(steps=steps)
    wall = time.perf_counter() - t0
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print("RESULT " + json.dumps({
        "rank": comm.rank, "setup": setup, "wall": wall, "cpu": usage.ru_utime + usage.ru_stime,
        "peak": usage.ru_maxrss / 1024, "compiles": seen.done}), flush=True)


def measure(scene: str, steps: int, ranks: int) -> list[dict]:
    """A cold run on ``ranks`` ranks: every rank's RESULT."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PMI_", "PMIX_", "MPI", "HYDRA"))}
    with tempfile.TemporaryDirectory(prefix="pdem-cold-") as cache:
        env.update(NUMBA_CACHE_DIR=cache, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1",
                   PYTHONPATH=ROOT)
        mpiexec = os.path.join(os.path.dirname(sys.executable), "mpiexec")
        cmd = [mpiexec, "-n", str(ranks), sys.executable, os.path.abspath(__file__),
               "--worker", "--scene", scene, "--steps", str(steps)]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
        wall = time.perf_counter() - t0
    rows = [json.loads(ln[len("RESULT "):]) for ln in proc.stdout.splitlines()
            if ln.startswith("RESULT ")]
    if proc.returncode != 0 or len(rows) != ranks:
        sys.exit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n"
                 f"{proc.stderr[-3000:]}")
    for row in rows:
        row["launch_wall"] = wall
    return sorted(rows, key=lambda r: r["rank"])


def families(compiles: list) -> list[tuple[str, float, float, int]]:
    """Exclusive seconds, peak MB and count per kernel (numba's own helpers under one name)."""
    out: dict[str, list] = {}
    for name, seconds, peak in compiles:
        key = name if name.startswith("pdem.") else "numba's array helpers"
        row = out.setdefault(key, [0.0, 0.0, 0])
        row[0] += seconds
        row[1] = max(row[1], peak)
        row[2] += 1
    return sorted(((k, *v) for k, v in out.items()), key=lambda r: -r[1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="configs/incline.yaml")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--worker", action="store_true")
    args = ap.parse_args()
    scene = os.path.join(ROOT, args.scene) if not os.path.isabs(args.scene) else args.scene
    if args.worker:
        worker(scene, args.steps)
        return
    print(f"cold start of {args.scene}, {args.steps} steps, empty kernel cache; "
          f"cores here: {os.cpu_count()}")
    for ranks in args.ranks:
        rows = measure(scene, args.steps, ranks)
        total = sum(sum(c[1] for c in r["compiles"]) for r in rows)
        print(f"\n-- mpiexec -n {ranks}: {rows[0]['launch_wall']:.1f} s wall to the end "
              f"(set-up {max(r['setup'] for r in rows):.1f} s), "
              f"{sum(r['cpu'] for r in rows):.1f} CPU s over the ranks, "
              f"compiling {total:.1f} s in all")
        for r in rows:
            print(f"   rank {r['rank']}: compiled {len(r['compiles']):3d} kernels "
                  f"({sum(c[1] for c in r['compiles']):.1f} s), peak {r['peak']:.0f} MB")
        busiest = max(rows, key=lambda r: len(r["compiles"]))
        print(f"   {'seconds':>8} {'peak MB':>8} {'count':>5}  kernel (rank {busiest['rank']})")
        for name, seconds, peak, count in families(busiest["compiles"])[:args.top]:
            print(f"   {seconds:8.2f} {peak:8.0f} {count:5d}  {name}")


if __name__ == "__main__":
    main()
