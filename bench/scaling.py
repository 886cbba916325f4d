"""Strong and weak scaling of the cube stack (bench/cube_stack.py) on 1, 2, 4, 8, 16 ranks, and
a model of the decomposition on 16 to 4096 ranks.

    .venv/bin/python bench/scaling.py [--n 22] [--steps 200] [--warmup 20] [--ranks 1 2 4 8 16]
                                      [--weak] [--oversubscribe] [--dims x|auto|rcb]
                                      [--model-only] [--repeat R]

Rank counts: by default 1 2 4 8 16, of which those above the cores this machine lets the
ranks use (``os.cpu_count()`` and the affinity mask MPICH's ranks inherit) are dropped, and the
script says so; ``--oversubscribe`` keeps them, and ``--ranks`` runs the counts given. A row
with more ranks than cores is marked ``oversubscribed``: the ranks then share cores (and step
in Python with sleeping waits, docs/parallel.md, More ranks than cores), so it does not
measure scaling, only that the run works.

Strong scaling (default): the same n^3 stack on every rank count. Weak scaling (``--weak``):
n^3 cubes per rank, the stack ``n P x n x n`` along x (``--dims x``) or n times the rank grid
(``auto``, ``rcb``), so the stack grows with the rank count; efficiency t_1 / t_P.

Measured part: the script launches itself under ``mpiexec -n P`` for each count (n^3
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

Model part (no MPI run): for 16, 64, 256, 1024 and 4096 ranks (and the measured counts, as a
check), strong (the n^3 stack and 10^6 cubes, n = 100) and weak (n^3 cubes a rank), the rank
grid ``choose_dims`` would pick and, from the geometry of the bricks, how many blocks each rank
would own, how many ghosts it would hold (the rule of pdem.parallel.migrate: a block whose box
``centroid +- (radius + ctol/2)`` reaches into the rank's interest box -- the box around its
owned free blocks, padded the same way, grown by the margin), and the halo bytes per step
(17 float64 per ghosted free block in a rigid scene, pdem.model.fields.halo_fields), for the
10^4-cube stack and a 10^6-cube one (n = 100). The cube lattice is a tensor product, so every
count factorises into per-axis counts and 4096 ranks x 4.4 x 10^7 blocks is instant. The
model's ``load eff.`` is mean / max owned blocks: the efficiency the load alone allows.

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
DEFAULT_RANKS = [1, 2, 4, 8, 16]
MODEL_RANKS = [16, 64, 256, 1024, 4096]

# float64 per ghosted free block per step (the declared halo fields of a scene without
# solve.inactive)
ROW_BYTES = row_width(halo_fields(False, zoned=False)) * 8
CUBE_RADIUS = math.sqrt(3.0) / 2.0  # unit cube: centroid to vertex
CTOL = 0.02  # ctol "auto" = 2 % of the smallest block's equivalent size (1 m)
GRAVITY = np.array([0.0, 0.0, -9.81])


# --------------------------------------------------------------------------- measured runs
def cores() -> int:
    """The cores the ranks may use here: os.cpu_count(), or fewer if the affinity mask
    (which mpiexec's ranks inherit, MPICH binding none by default) allows fewer."""
    n = os.cpu_count() or 1
    try:
        n = min(n, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        pass
    return n


def weak_grid(size: int, dims: str) -> list[int]:
    """The stack's size in units of n for weak scaling on ``size`` ranks: ``[size, 1, 1]``
    with ``--dims x``, else MPI's balanced factors, largest on x, smallest on z (gravity:
    choose_dims then gives the same grid, n^3 cubes a brick)."""
    if dims == "x":
        return [size, 1, 1]
    from mpi4py import MPI

    return sorted(MPI.Compute_dims(size, [0, 0, 0]), reverse=True)


def stack_scene(counts) -> str:
    """The cube stack of ``counts`` = [nx, ny, nz] cubes on its floor (cube_stack_scene's
    scene, not cubic)."""
    n = counts[0]
    text = cube_stack_scene(n, "fast")
    nx, ny, nz = map(int, counts)
    for old, new in ((f"count: [{n}, {n}, {n}]", f"count: [{nx}, {ny}, {nz}]"),
                     (f"max: [{n + 1}, {n + 1}, 0]", f"max: [{nx + 1}, {ny + 1}, 0]")):
        assert old in text, old
        text = text.replace(old, new)
    return text


def worker(args) -> None:
    """One MPI job: build, warm up, time; rank 0 prints one JSON line."""
    from mpi4py import MPI

    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    text = (stack_scene([args.n * g for g in weak_grid(comm.size, args.dims)]) if args.weak
            else cube_stack_scene(args.n, "fast"))
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
           "--warmup", str(args.warmup), "--dims", args.dims] + (["--weak"] if args.weak else [])
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        sys.exit(f"mpiexec -n {size} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n"
                 f"{proc.stderr[-3000:]}")
    out = json.loads(lines[-1][len("RESULT "):])
    out["wall"] = time.perf_counter() - t0
    out["oversubscribed"] = size > cores()
    return out


def measured(args) -> list[dict]:
    runs = []
    for size in args.ranks:
        what = (f"{args.n}^3 cubes a rank ({'x'.join(str(args.n * g) for g in weak_grid(size, args.dims))})"
                if args.weak else f"{args.n}^3 cubes")
        print(f"-- mpiexec -n {size}: {what}, {args.warmup} + {args.steps} steps"
              f"{' (oversubscribed)' if size > cores() else ''} ...", flush=True)
        runs.append(launch(size, args))
    t1 = next((r["elapsed"] for r in runs if r["size"] == 1), None)
    kind = "weak" if args.weak else "strong"
    print(f"\n{kind} scaling, cube stack "
          + (f"{args.n}^3 cubes a rank" if args.weak else f"{args.n}^3 = {runs[0]['free']} cubes")
          + f" (+ floor), dims {'[size, 1, 1]' if args.dims == 'x' else args.dims}; cores here: "
          f"{cores()} (os.cpu_count() {os.cpu_count()})")
    print(f"{'ranks':>5} {'cubes':>8} {'grid':>9} {'set-up s':>9} {'steps/s':>9} "
          f"{'block-steps/s':>14} {'efficiency':>10}  {'owned':>15} {'ghosts':>13} "
          f"{'halo B/step/rank (sent)':>24}  note")
    for r in runs:
        rate = r["steps"] / r["elapsed"]
        if not t1:
            eff = f"{'-':>10}"
        elif args.weak:  # the same work a rank: t_1 / t_P
            eff = f"{t1 / r['elapsed']:10.2f}"
        else:
            eff = f"{t1 / (r['size'] * r['elapsed']):10.2f}"
        rep = r["report"]
        note = (f"oversubscribed ({r['size']} ranks on {cores()} cores): not a scaling figure"
                if r["oversubscribed"] else "")
        print(f"{r['size']:5d} {r['free']:8d} {'x'.join(map(str, r['dims'])):>9} {r['setup']:9.1f} "
              f"{rate:9.1f} {rate * r['free']:14.4g} {eff}  {str(rep['owned']):>15} "
              f"{str(rep['ghosts']):>13} {str(rep['halo_bytes']):>24}  {note}")
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


def model(n, size: int):
    """Owned blocks, ghosts, neighbours and halo bytes per rank of the cube stack of ``n``
    (an int: n^3; or [nx, ny, nz])."""
    from pdem.parallel.decomposition import choose_dims

    ns = [n] * 3 if np.isscalar(n) else [int(v) for v in n]
    pad = 0.5 * CTOL
    lo = np.array([-1.0, -1.0, -1.0]) - pad  # the floor [-1, nx+1] x [-1, ny+1] x [-1, 0]
    hi = np.array([ns[0] + 1.0, ns[1] + 1.0, float(ns[2])]) + pad
    dims = choose_dims(size, hi - lo, GRAVITY)
    margin = 1.0 + CTOL  # "auto" = the cell size = the mean envelope of a cube
    reach = CUBE_RADIUS + pad
    per_axis = [axis_counts(np.arange(ns[k]) + 0.5, np.linspace(lo[k], hi[k], dims[k] + 1),
                            reach, margin) for k in range(3)]
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
              for k, c in enumerate((ns[0] / 2.0, ns[1] / 2.0, -0.5))), tuple(dims))
    has_box = owned > 0
    fixed_ghosts = (has_box & (np.arange(len(owned)) != floor_owner)).astype(int)
    return {"dims": dims, "owned": owned, "ghosts": ghosts + fixed_ghosts, "free_ghosts": ghosts,
            "neighbours": nb, "recv": ghosts * ROW_BYTES, "sent": sent * ROW_BYTES}


def print_model(cases, title="strong"):
    print(f"\nmodel of the decomposition, {title} (no run): owned blocks, ghosts (free + the "
          "floor), neighbours and halo bytes per step per rank; mean / max over ranks")
    print(f"{'blocks':>9} {'ranks':>5} {'grid':>8} {'owned mean/max':>17} {'empty':>5} "
          f"{'load eff.':>9} {'ghosts mean/max':>17} {'ghost/owned':>11} {'nbrs max':>8} "
          f"{'halo KB/step recv mean/max':>27} {'sent max':>9}")
    for n, size in cases:
        m = model(n, size)
        o, g = m["owned"], m["ghosts"]
        print(f"{int(np.prod([n] * 3 if np.isscalar(n) else n)):9d} {size:5d} "
              f"{'x'.join(map(str, m['dims'])):>8} "
              f"{o.mean():8.0f}/{o.max():<8d} {int((o == 0).sum()):5d} "
              f"{o.mean() / max(o.max(), 1):9.2f} "
              f"{g.mean():8.0f}/{g.max():<8d} {g.sum() / max(o.sum(), 1):11.2f} "
              f"{m['neighbours'].max():8d} "
              f"{m['recv'].mean() / 1e3:13.1f}/{m['recv'].max() / 1e3:<13.1f} "
              f"{m['sent'].max() / 1e3:9.1f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=22, help="cubes per edge of the stack (22: 10648)")
    ap.add_argument("--steps", type=int, default=200, help="timed steps")
    ap.add_argument("--warmup", type=int, default=20, help="untimed steps first")
    ap.add_argument("--ranks", type=int, nargs="+", default=None,
                    help="rank counts to run (default 1 2 4 8 16, those above the cores here "
                         "dropped unless --oversubscribe)")
    ap.add_argument("--oversubscribe", action="store_true",
                    help="keep the default rank counts above the cores here (rows marked)")
    ap.add_argument("--weak", action="store_true",
                    help="weak scaling: n^3 cubes a rank, the stack grows with the rank count")
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
    if args.ranks is None:
        args.ranks = list(DEFAULT_RANKS)
        if not args.oversubscribe and not args.model_only:
            over = [r for r in args.ranks if r > cores()]
            args.ranks = [r for r in args.ranks if r <= cores()]
            if over:
                print(f"rank counts {' '.join(map(str, over))} left out: {cores()} cores here "
                      "(--oversubscribe or --ranks runs them, marked as oversubscribed)")
    if args.repeat > 1 and not args.model_only:
        repeated(args)
        return
    if not args.model_only:
        measured(args)
    cases = ([(args.n, s) for s in sorted(set(args.ranks) | set(MODEL_RANKS))]
             + [(100, s) for s in MODEL_RANKS])
    print_model(cases, "strong")
    weak = [([args.n * g for g in weak_grid(s, "auto")], s)
            for s in sorted(set(args.ranks) | set(MODEL_RANKS))]
    print_model(weak, f"weak ({args.n}^3 cubes a rank, the stack n x the rank grid)")


if __name__ == "__main__":
    main()
