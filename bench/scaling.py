"""Strong scaling of the cube stack (bench/cube_stack.py) on 1 and 2 ranks, and a model of the
decomposition on 64 and 512 ranks.

    .venv/bin/python bench/scaling.py [--n 22] [--steps 200] [--warmup 20] [--ranks 1 2]
                                      [--dims x|auto|rcb] [--model-only] [--repeat R]

Measured part: the script launches itself under ``mpiexec -n 1`` and ``mpiexec -n 2`` (n^3
cubes, default 22^3 = 10648, split along x with ``parallel.dims [size, 1, 1]``, ``auto`` (the
uniform grid choose_dims picks) or ``rcb`` (``parallel.balance: rcb``, bench/balance.py)),
times ``--steps`` steps after ``--warmup`` steps, and prints block-steps/s, the strong-scaling
efficiency t1 / (p t_p), the halo bytes each rank sends per step (``load_report``) and the
per-phase timers of every rank. Ranks step in the compiled loop (``fused``) with the halo and
the reduction called from it (pdem.parallel.native); ``PDEM_MPI_NATIVE=0`` in the environment
measures the Python path. On a 2-core machine the 2-rank figures are the real thing; on
an oversubscribed one they are not. ``--repeat R`` runs the rank counts R times, alternating,
and prints each round's rates and efficiency and their median: one 200-step window on a
shared machine swings by tens of percent (docs/parallel.md, Scaling).

Model part (no MPI run): for 64 and 512 ranks (and the measured counts, as a check), the rank
grid ``choose_dims`` would pick and, from the geometry of the bricks, how many blocks each rank
would own, how many ghosts it would hold (the rule of pdem.parallel.migrate: a block whose box
``centroid +- (radius + ctol/2)`` reaches into the rank's interest box -- the box around its
owned free blocks, padded the same way, grown by the margin), and the halo bytes per step
(17 float64 per ghosted free block in a rigid scene, pdem.model.fields.halo_fields), for the
10^4-cube stack and a 10^6-cube one (n = 100). The cube lattice is a tensor product, so every
count factorises into per-axis counts and 512 ranks x 10^6 blocks is instant.

Not a test: timings on shared machines are noisy.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

from pdem.cases.stacks import cube_stack_scene
from pdem.model.fields import halo_fields, row_width

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# float64 per ghosted free block per step (the declared halo fields of a scene without
# solve.inactive)
ROW_BYTES = row_width(halo_fields(False, zoned=False)) * 8
CUBE_RADIUS = math.sqrt(3.0) / 2.0  # unit cube: centroid to vertex
CTOL = 0.02  # ctol "auto" = 2 % of the smallest block's equivalent size (1 m)
GRAVITY = np.array([0.0, 0.0, -9.81])


# --------------------------------------------------------------------------- measured runs
def worker(args) -> None:
    """One MPI job: build, warm up, time; rank 0 prints one JSON line."""
    from mpi4py import MPI

    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    text = cube_stack_scene(args.n, "fast")
    par = {"x": f"dims: [{comm.size}, 1, 1]", "auto": "dims: auto, balance: uniform",
           "rcb": "balance: rcb"}[args.dims]
    text += f"parallel: {{{par}}}\n"
    t0 = time.perf_counter()
    solver = Simulation(parse_scene(text), comm, output=False)
    comm.Barrier()
    setup = time.perf_counter() - t0
    solver.run(steps=args.warmup)
    solver.state.timers.reset()
    comm.Barrier()
    t0 = time.perf_counter()
    solver.run(steps=args.steps)
    comm.Barrier()
    elapsed = time.perf_counter() - t0
    report = solver.state.load_report()
    phases = comm.gather(solver.state.timers.report(), root=0)
    dims = solver.state.decomp.dims
    if comm.rank == 0:
        print("RESULT " + json.dumps({
            "size": comm.size, "blocks": solver.state.glob.n,
            "dims": dims.tolist() if dims is not None else ["rcb"],
            "free": int((solver.state.glob.fixed == 0).sum()), "setup": setup, "elapsed": elapsed,
            "steps": args.steps, "report": report, "phases": phases}), flush=True)


def launch(size: int, args) -> dict:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PMI_", "PMIX_", "MPI", "HYDRA"))}
    env.update(OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    cmd = [os.path.join(ROOT, ".venv", "bin", "mpiexec"), "-n", str(size), sys.executable,
           os.path.abspath(__file__), "--worker", "--n", str(args.n), "--steps", str(args.steps),
           "--warmup", str(args.warmup), "--dims", args.dims]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        sys.exit(f"mpiexec -n {size} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n"
                 f"{proc.stderr[-3000:]}")
    out = json.loads(lines[-1][len("RESULT "):])
    out["wall"] = time.perf_counter() - t0
    return out


def measured(args) -> list[dict]:
    runs = []
    for size in args.ranks:
        print(f"-- mpiexec -n {size}: {args.n}^3 cubes, {args.warmup} + {args.steps} steps ...",
              flush=True)
        runs.append(launch(size, args))
    t1 = next((r["elapsed"] for r in runs if r["size"] == 1), None)
    print(f"\ncube stack {args.n}^3 = {runs[0]['free']} cubes (+ floor), dims "
          f"{'[size, 1, 1]' if args.dims == 'x' else args.dims}; cores here: {os.cpu_count()}")
    print(f"{'ranks':>5} {'grid':>9} {'set-up s':>9} {'steps/s':>9} {'block-steps/s':>14} "
          f"{'efficiency':>10}  {'owned':>15} {'ghosts':>13} {'halo B/step/rank (sent)':>24}")
    for r in runs:
        rate = r["steps"] / r["elapsed"]
        eff = f"{t1 / (r['size'] * r['elapsed']):10.2f}" if t1 else f"{'-':>10}"
        rep = r["report"]
        print(f"{r['size']:5d} {'x'.join(map(str, r['dims'])):>9} {r['setup']:9.1f} {rate:9.1f} "
              f"{rate * r['free']:14.4g} {eff}  {str(rep['owned']):>15} {str(rep['ghosts']):>13} "
              f"{str(rep['halo_bytes']):>24}")
    for r in runs:
        for rank, ph in enumerate(r["phases"]):
            print(f"  {r['size']} ranks, rank {rank}: {ph}")
    return runs


def repeated(args) -> None:
    """``--repeat``: the rank counts alternated ``args.repeat`` times, one line a round, then
    the medians."""
    rates = {size: [] for size in args.ranks}
    effs = []
    for k in range(args.repeat):
        runs = {size: launch(size, args) for size in args.ranks}
        line = []
        for size, r in runs.items():
            rates[size].append(r["steps"] * r["free"] / r["elapsed"])
            line.append(f"{size} rank{'s' if size > 1 else ''} {rates[size][-1]:.3g}")
        if 1 in runs:
            t1 = runs[1]["elapsed"]
            eff = [t1 / (size * r["elapsed"]) for size, r in runs.items() if size > 1]
            effs.append(eff[-1] if eff else 1.0)
            line.append(f"efficiency {effs[-1]:.2f}")
        print(f"round {k + 1}: " + ", ".join(line) + " (block-steps/s)", flush=True)
    med = ", ".join(f"{size} rank{'s' if size > 1 else ''} {float(np.median(v)):.3g}"
                    for size, v in rates.items())
    print(f"median of {args.repeat} rounds: {med} block-steps/s"
          + (f"; efficiency {float(np.median(effs)):.2f} (min {min(effs):.2f}, max "
             f"{max(effs):.2f})" if effs else ""))


# --------------------------------------------------------------------------- model
def axis_counts(coords, edges, reach, margin):
    """Per axis: ``owned[a]`` coords in brick a (clamped as owner_of), ``has[a]`` whether brick a
    owns any, and ``M[a, b]``: how many coords owned by brick a reach into brick b's interest
    interval (the interval around b's owned coords +- reach, grown by margin)."""
    d = len(edges) - 1
    idx = np.searchsorted(edges[1:-1], coords, side="right")
    owned = np.bincount(idx, minlength=d)
    M = np.zeros((d, d), np.int64)
    for b in range(d):
        mine = coords[idx == b]
        if len(mine) == 0:
            continue
        lo, hi = mine.min() - reach - margin, mine.max() + reach + margin
        reaches = (coords + reach >= lo) & (coords - reach <= hi)
        M[:, b] = np.bincount(idx[reaches], minlength=d)
    return owned, owned > 0, M


def model(n: int, size: int):
    """Owned blocks, ghosts, neighbours and halo bytes per rank of the n^3 cube stack."""
    from pdem.parallel.decomposition import choose_dims

    pad = 0.5 * CTOL
    lo = np.array([-1.0, -1.0, -1.0]) - pad  # the floor [-1, n+1]^2 x [-1, 0]
    hi = np.array([n + 1.0, n + 1.0, float(n)]) + pad
    dims = choose_dims(size, hi - lo, GRAVITY)
    margin = 1.0 + CTOL  # "auto" = the cell size = the mean envelope of a cube
    reach = CUBE_RADIUS + pad
    coords = np.arange(n) + 0.5
    per_axis = [axis_counts(coords, np.linspace(lo[k], hi[k], dims[k] + 1), reach, margin)
                for k in range(3)]
    (ox, hx, Mx), (oy, hy, My), (oz, hz, Mz) = per_axis
    owned = np.einsum("a,b,c->abc", ox, oy, oz).ravel()  # row-major rank order
    # received by rank r = sum over owners s != r of (s's blocks reaching r's interest box)
    recv_all = np.einsum("a,b,c->abc", Mx.sum(0), My.sum(0), Mz.sum(0)).ravel()
    diag = np.einsum("a,b,c->abc", np.diag(Mx), np.diag(My), np.diag(Mz)).ravel()
    ghosts = recv_all - diag  # free ghosts; only ranks with an interest box have any
    sent = np.einsum("a,b,c->abc", Mx.sum(1), My.sum(1), Mz.sum(1)).ravel() - diag
    # neighbours: ranks s != r that send to r (M[s, r] > 0 on every axis)
    nb = np.einsum("a,b,c->abc", (Mx > 0).sum(0), (My > 0).sum(0), (Mz > 0).sum(0)).ravel()
    nb = nb - np.einsum("a,b,c->abc", np.diag(Mx) > 0, np.diag(My) > 0, np.diag(Mz) > 0).ravel()
    floor_owner = np.ravel_multi_index(
        tuple(int(np.searchsorted(np.linspace(lo[k], hi[k], dims[k] + 1)[1:-1], c, "right"))
              for k, c in enumerate((n / 2.0, n / 2.0, -0.5))), tuple(dims))
    has_box = owned > 0
    fixed_ghosts = (has_box & (np.arange(len(owned)) != floor_owner)).astype(int)
    return {"dims": dims, "owned": owned, "ghosts": ghosts + fixed_ghosts, "free_ghosts": ghosts,
            "neighbours": nb, "recv": ghosts * ROW_BYTES, "sent": sent * ROW_BYTES}


def print_model(cases):
    print("\nmodel of the decomposition (no run): owned blocks, ghosts (free + the floor), "
          "neighbours and halo bytes per step per rank; mean / max over ranks")
    print(f"{'blocks':>9} {'ranks':>5} {'grid':>8} {'owned mean/max':>17} {'empty':>5} "
          f"{'ghosts mean/max':>17} {'ghost/owned':>11} {'nbrs max':>8} "
          f"{'halo KB/step recv mean/max':>27} {'sent max':>9}")
    for n, size in cases:
        m = model(n, size)
        o, g = m["owned"], m["ghosts"]
        print(f"{n ** 3:9d} {size:5d} {'x'.join(map(str, m['dims'])):>8} "
              f"{o.mean():8.0f}/{o.max():<8d} {int((o == 0).sum()):5d} "
              f"{g.mean():8.0f}/{g.max():<8d} {g.sum() / max(o.sum(), 1):11.2f} "
              f"{m['neighbours'].max():8d} "
              f"{m['recv'].mean() / 1e3:13.1f}/{m['recv'].max() / 1e3:<13.1f} "
              f"{m['sent'].max() / 1e3:9.1f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=22, help="cubes per edge of the stack (22: 10648)")
    ap.add_argument("--steps", type=int, default=200, help="timed steps")
    ap.add_argument("--warmup", type=int, default=20, help="untimed steps first")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2], help="rank counts to run")
    ap.add_argument("--dims", choices=["x", "auto", "rcb"], default="x",
                    help="x: parallel.dims [size, 1, 1]; auto: choose_dims; rcb: balance rcb")
    ap.add_argument("--model-only", action="store_true", help="skip the MPI runs")
    ap.add_argument("--repeat", type=int, default=1,
                    help="run the rank counts this many times, alternating; print the medians")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args)
        return
    if args.repeat > 1 and not args.model_only:
        repeated(args)
        return
    if not args.model_only:
        measured(args)
    cases = [(args.n, s) for s in sorted(set(args.ranks) | {64, 512})] + [(100, 64), (100, 512)]
    print_model(cases)


if __name__ == "__main__":
    main()
